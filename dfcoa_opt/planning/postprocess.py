"""Grid-path post-processing: line of sight, node removal, smoothing, clearance.

Conventions are those of :class:`~dfcoa_opt.world.grid.OccupancyGrid`: cell
``(row, col)`` covers ``[col, col + 1) x [row, row + 1)`` in *cell coordinates*
(x = column direction, y = row direction, row 0 at the bottom); a cell centre is
at ``(col + 0.5, row + 0.5)``. World metres are ``origin + cell coordinates /
resolution``.

Line of sight is exact: a segment is free when every cell whose interior it
crosses is free, and where it passes exactly through a cell corner the two side
cells must both be free (no corner cutting, the same rule as the A* search's
diagonal moves; with ``corner_cutting`` one free side cell is enough). Between
cell centres the test is done in integers (no rounding); between arbitrary
points (smoothing) it is the Amanatides-Woo traversal, where crossings closer
than ``1e-12`` cell are treated as corners.

These are the "node optimisation and path shortening" steps of paper 000
section 4.1 (Fig. 7, "optimizing the path length based on connecting the
nearest nodes"): redundant nodes are removed while the straight segment between
the kept nodes stays free.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from dfcoa_opt.world.grid import OccupancyGrid

_CORNER_EPS = 1e-12


@numba.njit(cache=True)
def los_flat(blocked, stride, r0, c0, r1, c1, corner_cutting):  # pragma: no cover - numba
    """Line of sight between cell centres on a flat row-major grid.

    ``blocked[r * stride + c] == 1`` marks a blocked cell (bool or uint8 arrays;
    the A* kernel passes its padded state array, where other values mean free).
    Integer supercover walk: every cell the segment enters is tested, both end
    cells included; at an exact corner crossing both side cells must be free
    (one when ``corner_cutting``). The caller keeps the walk inside the array.
    """
    dx = abs(c1 - c0)
    dy = abs(r1 - r0)
    sx = 1 if c1 > c0 else -1
    sy = 1 if r1 > r0 else -1
    x, y = c0, r0
    if blocked[y * stride + x] == 1:
        return False
    err = dx - dy  # its sign tells which boundary (x or y) the segment crosses next
    n = dx + dy
    while n > 0:
        if err > 0:
            x += sx
            err -= 2 * dy
            n -= 1
        elif err < 0:
            y += sy
            err += 2 * dx
            n -= 1
        else:  # passes exactly through the corner shared by four cells
            a = blocked[y * stride + x + sx] == 1
            b = blocked[(y + sy) * stride + x] == 1
            if corner_cutting:
                if a and b:
                    return False
            elif a or b:
                return False
            x += sx
            y += sy
            err += 2 * (dx - dy)
            n -= 2
        if blocked[y * stride + x] == 1:
            return False
    return True


@numba.njit(cache=True)
def los_cells(occ, r0, c0, r1, c1, corner_cutting):  # pragma: no cover - numba
    """Whether the segment between the centres of ``(r0, c0)`` and ``(r1, c1)`` is free.

    ``occ`` is a C-contiguous ``(H, W)`` bool grid; see :func:`los_flat`.
    """
    return los_flat(occ.reshape(-1), occ.shape[1], r0, c0, r1, c1, corner_cutting)


@numba.njit(cache=True)
def _segment_free(occ, x0, y0, x1, y1):  # pragma: no cover - numba
    """Amanatides-Woo walk of the segment ``(x0, y0) -> (x1, y1)`` in cell coordinates.

    Outside the grid counts as blocked. No corner cutting at corner crossings.
    """
    n_rows, n_cols = occ.shape
    c = int(math.floor(x0))
    r = int(math.floor(y0))
    dx = x1 - x0
    dy = y1 - y0
    sx = 1 if dx > 0 else -1
    sy = 1 if dy > 0 else -1
    inf = np.inf
    tdx = abs(1.0 / dx) if dx != 0 else inf
    tdy = abs(1.0 / dy) if dy != 0 else inf
    if dx > 0:
        tx = (c + 1 - x0) / dx
    elif dx < 0:
        tx = (x0 - c) / -dx
    else:
        tx = inf
    if dy > 0:
        ty = (r + 1 - y0) / dy
    elif dy < 0:
        ty = (y0 - r) / -dy
    else:
        ty = inf
    while True:
        if r < 0 or r >= n_rows or c < 0 or c >= n_cols or occ[r, c]:
            return False
        t = min(tx, ty)
        if t >= 1.0:
            return True
        if abs(tx - ty) <= _CORNER_EPS:
            rr, cc = r + sy, c + sx
            if rr < 0 or rr >= n_rows or cc < 0 or cc >= n_cols or occ[r, cc] or occ[rr, c]:
                return False
            r, c = rr, cc
            tx += tdx
            ty += tdy
        elif tx < ty:
            c += sx
            tx += tdx
        else:
            r += sy
            ty += tdy


@numba.njit(cache=True)
def _shorten_kernel(occ, cells, corner_cutting):  # pragma: no cover - numba
    """Indices of the kept vertices of ``cells`` (greedy: extend while in sight)."""
    n = cells.shape[0]
    keep = np.empty(n, np.int64)
    keep[0] = 0
    k = 1
    anchor = 0
    j = 1
    while j < n:
        # advance while the next vertex is still visible from the anchor
        while j + 1 < n and los_cells(occ, cells[anchor, 0], cells[anchor, 1],
                                      cells[j + 1, 0], cells[j + 1, 1], corner_cutting):
            j += 1
        keep[k] = j
        k += 1
        anchor = j
        j += 1
    return keep[:k]


def line_of_sight(occupied: NDArray[np.bool_], a: ArrayLike, b: ArrayLike,
                  corner_cutting: bool = False) -> bool:
    """Exact line of sight between the centres of cells ``a`` and ``b`` (``(row, col)``).

    Args:
        occupied: ``(H, W)`` bool grid, True = blocked.
        a: Start cell ``(row, col)``; must be inside the grid.
        b: End cell ``(row, col)``; must be inside the grid.
        corner_cutting: Allow passing a corner when one of the two side cells is free.
    """
    a, b = np.asarray(a, dtype=np.int64), np.asarray(b, dtype=np.int64)
    return bool(los_cells(np.ascontiguousarray(occupied, dtype=bool), a[0], a[1], b[0], b[1],
                          corner_cutting))


def segment_free(occupied: NDArray[np.bool_], p: ArrayLike, q: ArrayLike) -> bool:
    """Whether the segment ``p -> q`` (cell coordinates ``(x, y)``) crosses only free cells."""
    p, q = np.asarray(p, dtype=float), np.asarray(q, dtype=float)
    return bool(_segment_free(np.ascontiguousarray(occupied, dtype=bool), p[0], p[1], q[0], q[1]))


def shorten(occupied: NDArray[np.bool_], cells: NDArray[np.int64],
            corner_cutting: bool = False) -> NDArray[np.int64]:
    """Remove redundant path vertices by line of sight (node optimisation).

    Greedy string pulling: from the current anchor, keep extending to the next
    vertex while the segment from the anchor stays in sight; the last visible
    vertex becomes the next anchor. The pass is repeated on its own output until
    no vertex is removed. The result is never longer than the input (triangle
    inequality) and every segment has line of sight.

    Args:
        occupied: ``(H, W)`` bool grid the path was planned on.
        cells: ``(P, 2)`` consecutive path cells ``(row, col)``.
        corner_cutting: Corner rule of :func:`line_of_sight`.

    Returns:
        ``(Q, 2)`` kept cells, Q <= P, same first and last cell.
    """
    cells = np.ascontiguousarray(cells, dtype=np.int64).reshape(-1, 2)
    if len(cells) <= 2:
        return cells.copy()
    occ = np.ascontiguousarray(occupied, dtype=bool)
    while True:
        keep = _shorten_kernel(occ, cells, corner_cutting)
        if len(keep) == len(cells):
            return cells
        cells = np.ascontiguousarray(cells[keep])


def smooth(occupied: NDArray[np.bool_], points: NDArray[np.float64],
           iterations: int = 3) -> NDArray[np.float64]:
    """Chaikin corner cutting that only cuts corners where the cut is free.

    Each iteration replaces every interior vertex ``P_k`` by the two points at a
    quarter of the adjacent segments (``0.75 P_k + 0.25 P_{k-1}`` and
    ``0.75 P_k + 0.25 P_{k+1}``) when the segment joining them is free
    (:func:`segment_free`); otherwise the vertex is kept. Endpoints are kept,
    so the path never gets longer and stays on free cells.

    Args:
        occupied: ``(H, W)`` bool grid.
        points: ``(P, 2)`` polyline in cell coordinates ``(x, y)``.
        iterations: Number of subdivision rounds.
    """
    occ = np.ascontiguousarray(occupied, dtype=bool)
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    for _ in range(iterations):
        if len(pts) < 3:
            break
        out = [pts[0]]
        for k in range(1, len(pts) - 1):
            a = 0.75 * pts[k] + 0.25 * pts[k - 1]
            b = 0.75 * pts[k] + 0.25 * pts[k + 1]
            if _segment_free(occ, a[0], a[1], b[0], b[1]):
                out.extend((a, b))
            else:
                out.append(pts[k])
        out.append(pts[-1])
        pts = np.asarray(out)
    return pts


def planning_grid(grid: OccupancyGrid, inflate: float,
                  keep: Iterable[ArrayLike] = ()) -> NDArray[np.bool_]:
    """The occupancy the planner searches: ``grid`` with obstacles grown by ``inflate`` m.

    A cell is blocked when its centre is within ``inflate`` of an occupied cell
    centre (:meth:`OccupancyGrid.inflate`). For each point of ``keep`` (start,
    goal) whose cell only inflation blocks, the cells within ``inflate`` + one
    cell of it that are free in ``grid`` are freed again, so a leader that starts
    (or ends) closer than ``inflate`` to an obstacle can still leave (reach) it.

    Returns:
        A new ``(H, W)`` bool array.
    """
    occ = np.array(grid.occupied, dtype=bool)
    if inflate <= 0.0:
        return occ
    occ |= grid.distance_field <= inflate
    for point in keep:
        p = np.asarray(point, dtype=float).reshape(2)
        row, col = (int(v) for v in grid.world_to_cell(p))
        if not (0 <= row < occ.shape[0] and 0 <= col < occ.shape[1]) or not occ[row, col]:
            continue
        k = int(math.ceil(min(inflate * grid.resolution, max(occ.shape)))) + 1  # map-bounded
        r0, r1 = max(row - k, 0), min(row + k + 1, occ.shape[0])
        c0, c1 = max(col - k, 0), min(col + k + 1, occ.shape[1])
        rows, cols = np.mgrid[r0:r1, c0:c1]
        x = grid.origin[0] + (cols + 0.5) * grid.cell_size
        y = grid.origin[1] + (rows + 0.5) * grid.cell_size
        near = np.hypot(x - p[0], y - p[1]) <= inflate + grid.cell_size
        occ[r0:r1, c0:c1] &= ~(near & ~grid.occupied[r0:r1, c0:c1])
    return occ


def path_length(path: ArrayLike) -> float:
    """Length of a ``(P, 2)`` polyline (its units)."""
    p = np.asarray(path, dtype=float).reshape(-1, 2)
    return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())


def sample_path(path: ArrayLike, step: float) -> NDArray[np.float64]:
    """Points along a polyline at spacing <= ``step``, every vertex included, ``(S, 2)``."""
    p = np.asarray(path, dtype=float).reshape(-1, 2)
    if len(p) < 2:
        return p.copy()
    out = [p[:1]]
    for a, b in zip(p[:-1], p[1:], strict=True):
        n = max(1, math.ceil(np.hypot(*(b - a)) / step))
        t = np.arange(1, n + 1)[:, None] / n
        out.append(a + t * (b - a))
    return np.vstack(out)


def path_clearance(grid: OccupancyGrid, path: ArrayLike,
                   step: float | None = None) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Clearance along a path: exact distance to the nearest occupied cell square.

    Args:
        grid: The (un-inflated) map.
        path: ``(P, 2)`` world polyline in m.
        step: Sample spacing in m; default a quarter cell. The minimum over
            the samples overestimates the true minimum along the path by at most
            ``step / 2`` (clearance is 1-Lipschitz).

    Returns:
        ``(samples (S, 2) m, clearance (S,) m)``; an empty grid gives ``inf``.
    """
    pts = sample_path(path, step if step is not None else 0.25 * grid.cell_size)
    if not grid.occupied.any():
        return pts, np.full(len(pts), np.inf)
    cap = float(np.hypot(*grid.size)) + float(np.abs(pts).max(initial=0.0)) + 1.0
    return pts, grid.clearance(pts, cap=cap)


def min_clearance(grid: OccupancyGrid, path: ArrayLike, step: float | None = None) -> float:
    """Smallest clearance (m) along ``path`` (see :func:`path_clearance`); inf when empty."""
    if len(np.asarray(path).reshape(-1, 2)) == 0:
        return math.inf
    return float(path_clearance(grid, path, step)[1].min())
