"""World family ``cellular``: BARN-like obstacles grown by a cellular automaton.

As in BARN (Perille et al., 2020): the map is cut into square cells; each cell
of the obstacle band is occupied with the *fill* probability; then *smoothing*
passes of the 4-5 rule turn the noise into blobs and clear isolated cells: a
cell is occupied after a pass when at least 5 of its 8 neighbours were, or
when it was and at least 4 of them were. Cells outside the map count as free.
Cells whose centre lies within the start's or the goal's free disc stay free
throughout. Each world draws its own fill probability and number of passes,
uniformly from the given ranges; the occupied cells become rectangles
(:func:`~dfcoa_opt.world.generate.rects.mask_rectangles`).

Facts of a draw: ``fill`` (the drawn probability), ``smoothing`` (passes),
``initial_fill`` and ``final_fill`` (occupied fraction of the band's cells
that may hold obstacles, before and after smoothing).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.core.params import param
from dfcoa_opt.world.generate import Generated, Layout, check_range, register_family
from dfcoa_opt.world.generate.rects import mask_rectangles


@dataclass(frozen=True)
class CellularParams:
    """Options of the ``cellular`` family (``[world.generate.options]``)."""

    cell: float = param(0.5, doc="Side of one automaton cell.", unit="m", gt=0.0)
    fill: tuple[float, float] = param((0.35, 0.45), doc="Range of the initial fill probability "
                                                       "(BARN's fill percentage); each world "
                                                       "draws one uniformly.", ge=0.0, lt=1.0)
    smoothing: tuple[int, int] = param((1, 3), doc="Range of the number of 4-5 rule passes; "
                                                   "each world draws one uniformly.",
                                       ge=0, le=20)
    band: tuple[float, float] | None = param(
        None, doc="(x0, x1) of the obstacle band; default: between the start's and the goal's "
                  "free discs.", unit="m")

    def check(self, src: str, key: str) -> None:
        """Ranges in order."""
        check_range(self.fill, src, f"{key}.fill")
        check_range(self.smoothing, src, f"{key}.smoothing")
        if self.band is not None:
            check_range(self.band, src, f"{key}.band")


def neighbours(occ: NDArray[np.bool_]) -> NDArray[np.int64]:
    """Occupied neighbours (8-connected) of every cell; outside the grid counts as free."""
    p = np.pad(occ.astype(np.int64), 1)
    h, w = occ.shape
    return sum(p[1 + di:1 + di + h, 1 + dj:1 + dj + w]
               for di in (-1, 0, 1) for dj in (-1, 0, 1) if di or dj)


def smooth(occ: NDArray[np.bool_], keep_free: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """One pass of the 4-5 rule (cells of ``keep_free`` stay free)."""
    n = neighbours(occ)
    return ((n >= 5) | (occ & (n >= 4))) & ~keep_free


@register_family("cellular", params=CellularParams)
def cellular(p: CellularParams, rng: np.random.Generator, layout: Layout) -> Generated:
    """Draw one cellular-automaton world (see the module docstring)."""
    x0, x1, y0, y1 = layout.extent
    cols = max(1, int(np.floor((x1 - x0) / p.cell + 1e-9)))
    rows = max(1, int(np.floor((y1 - y0) / p.cell + 1e-9)))
    xs = x0 + p.cell * np.arange(cols + 1)
    ys = y0 + p.cell * np.arange(rows + 1)
    cx = (xs[:-1] + xs[1:]) / 2
    cy = (ys[:-1] + ys[1:]) / 2
    lo, hi = p.band if p.band is not None else layout.span()
    in_band = np.broadcast_to((cx >= lo) & (cx <= hi), (rows, cols))
    points, radii = layout.keep_points()
    gx, gy = np.meshgrid(cx, cy)
    near = np.zeros((rows, cols), dtype=bool)
    for (px, py), r in zip(points, radii, strict=True):
        near |= np.hypot(gx - px, gy - py) <= r + p.cell * np.sqrt(0.5)
    keep_free = near | ~in_band
    fill = float(rng.uniform(*p.fill))
    passes = int(rng.integers(p.smoothing[0], p.smoothing[1] + 1))
    occ = (rng.random((rows, cols)) < fill) & ~keep_free
    eligible = max(int((~keep_free).sum()), 1)
    initial = float(occ.sum()) / eligible
    for _ in range(passes):
        occ = smooth(occ, keep_free)
    facts = {"fill": fill, "smoothing": passes, "initial_fill": initial,
             "final_fill": float(occ.sum()) / eligible}
    return Generated(shapes=mask_rectangles(occ, xs, ys), facts=facts)
