"""Occupancy grid: construction, inflation, distance field, exact clearance.

Frame: the world origin is the bottom-left corner of cell ``(row 0, col 0)``;
rows grow with +y and columns with +x. ASCII art and images are written top row
first (as on screen) and are flipped on load. Resolution is in cells per metre.
Outside the grid is free space for sensing and collision checks; planners only
search inside it.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from dfcoa_opt.world.shapes import Shape

#: Characters accepted in ASCII maps.
ASCII_OCCUPIED = frozenset("#@TXO1")
ASCII_FREE = frozenset(".0 G")


@dataclass(frozen=True, eq=False)
class OccupancyGrid:
    """A binary occupancy grid.

    Attributes:
        occupied: ``(H, W)`` bool, read-only; ``occupied[row, col]``, row 0 at the bottom.
        resolution: Cells per metre, > 0.
        origin: World ``(x, y)`` of the grid's bottom-left corner, in m.
    """

    occupied: NDArray[np.bool_]
    resolution: float
    origin: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        occ = np.array(self.occupied, dtype=bool)
        if occ.ndim != 2 or occ.size == 0:
            raise ValueError("occupied must be a non-empty 2-D array")
        if not (np.isfinite(self.resolution) and self.resolution > 0):
            raise ValueError("resolution must be a finite number > 0")
        occ.setflags(write=False)
        object.__setattr__(self, "occupied", occ)
        object.__setattr__(self, "origin", (float(self.origin[0]), float(self.origin[1])))
        object.__setattr__(self, "resolution", float(self.resolution))

    # ----------------------------------------------------------------- builders
    @classmethod
    def empty(cls, size: tuple[float, float], resolution: float,
              origin: tuple[float, float] = (0.0, 0.0)) -> OccupancyGrid:
        """A free grid covering ``size = (width, height)`` m."""
        w, h = (max(1, round(s * resolution)) for s in size)
        return cls(np.zeros((h, w), dtype=bool), resolution, origin)

    @classmethod
    def from_ascii(cls, text: str, resolution: float,
                   origin: tuple[float, float] = (0.0, 0.0)) -> OccupancyGrid:
        """Build from ASCII art, top row first.

        ``#@TXO1`` are occupied; ``.``, ``0``, space and ``G`` are free. Blank
        leading/trailing lines are ignored; all rows must have the same length.

        Raises:
            ValueError: On ragged rows or unknown characters (message names the row).
        """
        lines = [ln for ln in text.strip("\n").split("\n")]
        while lines and not lines[-1].strip():
            lines.pop()
        if not lines:
            raise ValueError("map_ascii is empty")
        width = len(lines[0])
        occ = np.zeros((len(lines), width), dtype=bool)
        for r, ln in enumerate(lines):
            if len(ln) != width:
                raise ValueError(f"row {r + 1} has {len(ln)} characters, expected {width}")
            bad = set(ln) - ASCII_OCCUPIED - ASCII_FREE
            if bad:
                raise ValueError(f"row {r + 1} has unknown character(s) {''.join(sorted(bad))!r}")
            occ[r] = [c in ASCII_OCCUPIED for c in ln]
        return cls(occ[::-1], resolution, origin)

    @classmethod
    def from_image(cls, path: str | Path, resolution: float, threshold: float = 0.5,
                   origin: tuple[float, float] = (0.0, 0.0)) -> OccupancyGrid:
        """Build from a PNG: a pixel is occupied when its grey level < ``threshold``.

        Args:
            path: PNG file; one pixel per cell, top row first.
            resolution: Cells (pixels) per metre.
            threshold: Grey level in [0, 1] below which a pixel is occupied.
            origin: World (x, y) of the bottom-left corner, m.
        """
        import matplotlib.image as mpimg

        img = np.asarray(mpimg.imread(str(path)), dtype=float)
        if img.ndim == 3:
            img = img[..., :3].mean(axis=2)
        if img.max() > 1.0:
            img = img / 255.0
        return cls(img[::-1] < threshold, resolution, origin)

    @classmethod
    def from_shapes(cls, size: tuple[float, float], resolution: float, shapes: Iterable[Shape],
                    origin: tuple[float, float] = (0.0, 0.0)) -> OccupancyGrid:
        """Rasterise shapes: a cell is occupied iff its centre lies inside a shape."""
        return cls.empty(size, resolution, origin).with_shapes(shapes)

    def with_shapes(self, shapes: Iterable[Shape]) -> OccupancyGrid:
        """This grid with the given shapes rasterised in (centre-inside rule).

        Each shape tests only the cell centres inside its bounding box (plus a
        cell of margin): the same cells as testing every centre, without the
        cost of the whole grid per shape (a cluttered map has hundreds of discs).
        """
        occ = self.occupied.copy()
        centres = self.cell_centers()
        n_rows, n_cols = occ.shape
        ox, oy = self.origin
        cs = self.cell_size
        for shape in shapes:
            x0, y0, x1, y1 = shape.bounds()
            if not all(math.isfinite(v) for v in (x0, y0, x1, y1)):
                r0, r1, c0, c1 = 0, n_rows, 0, n_cols
            else:  # cells whose centre (origin + (index + 0.5) cs) may lie in [min, max]
                c0 = max(0, math.floor((x0 - ox) / cs - 0.5) - 1)
                c1 = min(n_cols, math.ceil((x1 - ox) / cs - 0.5) + 2)
                r0 = max(0, math.floor((y0 - oy) / cs - 0.5) - 1)
                r1 = min(n_rows, math.ceil((y1 - oy) / cs - 0.5) + 2)
            if r0 >= r1 or c0 >= c1:
                continue
            win = centres[r0:r1, c0:c1]
            occ[r0:r1, c0:c1] |= shape.contains(win.reshape(-1, 2)).reshape(win.shape[:2])
        return OccupancyGrid(occ, self.resolution, self.origin)

    # --------------------------------------------------------------- properties
    @property
    def shape(self) -> tuple[int, int]:
        """``(rows, cols)``."""
        return self.occupied.shape  # type: ignore[return-value]

    @property
    def cell_size(self) -> float:
        """Side of one cell in m."""
        return 1.0 / self.resolution

    @property
    def size(self) -> tuple[float, float]:
        """``(width, height)`` of the grid in m."""
        return self.shape[1] * self.cell_size, self.shape[0] * self.cell_size

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """``(xmin, xmax, ymin, ymax)`` in m (matplotlib ``imshow`` order)."""
        w, h = self.size
        return self.origin[0], self.origin[0] + w, self.origin[1], self.origin[1] + h

    def cell_centers(self) -> NDArray[np.float64]:
        """World coordinates of all cell centres, ``(H, W, 2)`` in m."""
        rows, cols = np.indices(self.shape)
        return np.stack(
            (self.origin[0] + (cols + 0.5) * self.cell_size,
             self.origin[1] + (rows + 0.5) * self.cell_size), axis=-1)

    def world_to_cell(self, points: ArrayLike) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """``(row, col)`` of the cells containing ``points`` ``(..., 2)`` m.

        A point outside the grid gets an index outside it too, clipped to one cell
        beyond the border (-1 or the size), so that far or non-finite points cast
        safely; NaN gets -1.
        """
        p = np.asarray(points, dtype=float)
        h, w = self.shape
        with np.errstate(over="ignore", invalid="ignore"):
            col = np.floor((p[..., 0] - self.origin[0]) * self.resolution)
            row = np.floor((p[..., 1] - self.origin[1]) * self.resolution)
        col = np.nan_to_num(np.clip(col, -1, w), nan=-1).astype(np.intp)
        row = np.nan_to_num(np.clip(row, -1, h), nan=-1).astype(np.intp)
        return row, col

    def in_bounds(self, row: ArrayLike, col: ArrayLike) -> NDArray[np.bool_]:
        """Which ``(row, col)`` indices lie inside the grid."""
        row, col = np.asarray(row), np.asarray(col)
        return (row >= 0) & (row < self.shape[0]) & (col >= 0) & (col < self.shape[1])

    def is_occupied_at(self, points: ArrayLike) -> NDArray[np.bool_]:
        """Whether the cell under each point ``(..., 2)`` m is occupied (outside: False)."""
        row, col = self.world_to_cell(points)
        ok = self.in_bounds(row, col)
        out = np.zeros(row.shape, dtype=bool)
        out[ok] = self.occupied[row[ok], col[ok]]
        return out

    # ------------------------------------------------------------ distance field
    @cached_property
    def distance_field(self) -> NDArray[np.float64]:
        """Euclidean distance (m) from each cell centre to the nearest occupied cell centre.

        Zero on occupied cells, ``inf`` everywhere when nothing is occupied
        (``scipy.ndimage.distance_transform_edt``).
        """
        if not self.occupied.any():
            d = np.full(self.shape, np.inf)
        else:
            from scipy import ndimage  # here: ~0.2 s to import, needed once a grid is built

            d = ndimage.distance_transform_edt(~self.occupied) * self.cell_size
        d.setflags(write=False)
        return d

    def inflate(self, radius: float) -> OccupancyGrid:
        """Grow obstacles by ``radius`` (m).

        A cell becomes occupied when its centre is within ``radius`` of an occupied
        cell centre. (MATLAB's ``inflate`` instead rounds the radius up to whole
        cells; see docs/reproduction.md.)
        """
        if radius < 0 or not np.isfinite(radius):
            raise ValueError("inflation radius must be finite and >= 0")
        return OccupancyGrid(self.occupied | (self.distance_field <= radius), self.resolution,
                             self.origin)

    def clearance(self, points: ArrayLike, cap: float = 10.0) -> NDArray[np.float64]:
        """Exact distance (m) from points to the nearest occupied cell square.

        Zero inside an occupied cell. Distances above ``cap`` are reported as
        ``cap`` (they are only bounded from below there), and an empty grid gives ``cap``.

        Args:
            points: ``(..., 2)`` world points in m.
            cap: Largest distance of interest in m.
        """
        p = np.asarray(points, dtype=float)
        flat = np.ascontiguousarray(p.reshape(-1, 2))
        out = _clearance_kernel(flat, self.occupied, self.distance_field, self.origin[0],
                                self.origin[1], self.cell_size, float(cap))
        return out.reshape(p.shape[:-1])


@numba.njit(cache=True)
def _clearance_kernel(points, occ, dfield, ox, oy, h, cap):  # pragma: no cover - numba
    """Window search bounded by the centre distance field (see ``clearance``)."""
    n_rows, n_cols = occ.shape
    out = np.empty(points.shape[0])
    half_diag = h * np.sqrt(0.5)
    for k in range(points.shape[0]):
        px, py = points[k, 0], points[k, 1]
        c = int(np.floor((px - ox) / h))
        r = int(np.floor((py - oy) / h))
        rc = min(max(r, 0), n_rows - 1)
        cc = min(max(c, 0), n_cols - 1)
        # distance from p to the nearest occupied centre is within dist(p, centre(rc,cc)) + D
        cx = ox + (cc + 0.5) * h
        cy = oy + (rc + 0.5) * h
        d_pc = np.sqrt((px - cx) ** 2 + (py - cy) ** 2)
        bound = dfield[rc, cc] + d_pc  # >= distance to the nearest occupied square
        lower = dfield[rc, cc] - d_pc - half_diag  # <= that distance
        if not np.isfinite(bound) or lower > cap:
            out[k] = cap
            continue
        reach = min(bound, cap)
        r0 = max(int(np.floor((py - reach - oy) / h)), 0)
        r1 = min(int(np.floor((py + reach - oy) / h)), n_rows - 1)
        c0 = max(int(np.floor((px - reach - ox) / h)), 0)
        c1 = min(int(np.floor((px + reach - ox) / h)), n_cols - 1)
        best = np.inf
        for i in range(r0, r1 + 1):
            y0 = oy + i * h
            dy = max(y0 - py, 0.0, py - (y0 + h))
            if dy >= best:
                continue
            for j in range(c0, c1 + 1):
                if occ[i, j]:
                    x0 = ox + j * h
                    dx = max(x0 - px, 0.0, px - (x0 + h))
                    d = np.sqrt(dx * dx + dy * dy)
                    if d < best:
                        best = d
        out[k] = min(best, cap)
    return out
