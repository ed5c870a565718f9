"""Leader planner ``clearance_astar``: a shortest path that keeps room for the formation.

A* on the 8-connected grid (no corner cutting) where a move costs its length
times ``1 + weight * (p(u) + p(v)) / 2``; ``p`` is 0 for a cell at least
``clearance`` m from every occupied cell and grows linearly to 1 at ``inflate``
m, closer than which a cell is blocked. The path therefore runs down the
middle of passages narrower than twice ``clearance`` and keeps ``clearance``
from obstacles where the map allows, while still passing where only one robot
fits. (Improved A*'s eq 13 term only orders the search and plain A* hugs the
corners: both bring a formation's wings onto the walls.) The octile heuristic
stays admissible, as every move costs at least its length, so the path is the
cheapest one.

With ``shorten``, a vertex is dropped when the straight segment that replaces
it keeps at least the clearance the path had over the stretch it replaces
(capped at ``clearance``): shortcuts never bring the path closer to obstacles.
Used by the generated worlds of ``scenarios/heldout/`` (docs/heldout.md).
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.core.params import param
from dfcoa_opt.planning.astar_kernel import trace_path
from dfcoa_opt.planning.postprocess import planning_grid
from dfcoa_opt.planning.registry import register_planner
from dfcoa_opt.world.grid import OccupancyGrid

SQRT2 = math.sqrt(2.0)


@dataclass(frozen=True)
class ClearanceParams:
    """Options of the ``clearance_astar`` planner (``[leader.planner_options]``)."""

    inflate: float = param(0.3, doc="Cells closer than this to an obstacle are blocked (a "
                                    "robot radius and a margin); near the start and goal "
                                    "they are released.", unit="m", ge=0.0)
    clearance: float = param(1.5, doc="Cells this far from every obstacle cost their length; "
                                      "closer ones cost more (half the formation's width and "
                                      "a margin).", unit="m", gt=0.0)
    weight: float = param(4.0, doc="Extra cost, in lengths, of a move between cells at the "
                                   "inflate limit.", ge=0.0)
    shorten: bool = param(True, doc="Drop vertices where the straight segment keeps the "
                                    "clearance of the stretch it replaces.")

    def check(self, src: str, key: str) -> None:
        """``clearance`` beyond ``inflate``."""
        if self.clearance <= self.inflate:
            from dfcoa_opt.core.errors import ScenarioError

            raise ScenarioError(src, f"{key}.clearance", f"({self.clearance:g} m) must exceed "
                                                         f"inflate ({self.inflate:g} m)")


@numba.njit(cache=True)
def _search(blocked, penalty, weight, sr, sc, gr, gc):  # pragma: no cover - numba
    """Weighted A* from (sr, sc) to (gr, gc); the path cells ``(P, 2)`` (empty: none)."""
    h, w = blocked.shape
    g = np.full(h * w, np.inf)
    parent = np.full(h * w, -1, np.int64)
    closed = np.zeros(h * w, np.bool_)
    s, t = sr * w + sc, gr * w + gc
    g[s] = 0.0
    heap = [(0.0, s)]
    drs = (1, -1, 0, 0, 1, 1, -1, -1)
    dcs = (0, 0, 1, -1, 1, -1, 1, -1)
    while heap:
        _, u = heapq.heappop(heap)
        if closed[u]:
            continue
        closed[u] = True
        if u == t:
            break
        ur, uc = u // w, u % w
        for k in range(8):
            vr, vc = ur + drs[k], uc + dcs[k]
            if vr < 0 or vr >= h or vc < 0 or vc >= w or blocked[vr, vc]:
                continue
            step = 1.0
            if k >= 4:
                if blocked[ur + drs[k], uc] or blocked[ur, uc + dcs[k]]:
                    continue
                step = SQRT2
            v = vr * w + vc
            if closed[v]:
                continue
            ng = g[u] + step * (1.0 + weight * 0.5 * (penalty[ur, uc] + penalty[vr, vc]))
            if ng < g[v]:
                g[v] = ng
                parent[v] = u
                dr, dc = abs(vr - gr), abs(vc - gc)
                hv = (dr + dc) + (SQRT2 - 2.0) * min(dr, dc)
                heapq.heappush(heap, (ng + hv, v))
    if not closed[t]:
        return np.zeros((0, 2), np.int64)
    return trace_path(parent, s, t, w, 0)


@numba.njit(cache=True)
def _segment_clearance(dist, r0, c0, r1, c1):  # pragma: no cover - numba
    """Smallest cell clearance along the segment between two cell centres (quarter-cell steps)."""
    n = max(1, int(math.ceil(4.0 * max(abs(r1 - r0), abs(c1 - c0)))))
    out = np.inf
    for i in range(n + 1):
        r = int(round(r0 + (r1 - r0) * i / n))
        c = int(round(c0 + (c1 - c0) * i / n))
        out = min(out, dist[r, c])
    return out


@numba.njit(cache=True)
def _shorten(dist, cells, cap):  # pragma: no cover - numba
    """Indices of the kept cells: extend from each anchor while the clearance holds."""
    n = cells.shape[0]
    keep = np.empty(n, np.int64)
    keep[0] = 0
    k = 1
    anchor = 0
    while anchor < n - 1:
        need = min(cap, dist[cells[anchor, 0], cells[anchor, 1]])
        j = anchor + 1
        need = min(need, dist[cells[j, 0], cells[j, 1]])
        while j + 1 < n:
            nxt = min(need, dist[cells[j + 1, 0], cells[j + 1, 1]])
            if _segment_clearance(dist, cells[anchor, 0], cells[anchor, 1], cells[j + 1, 0],
                                  cells[j + 1, 1]) < nxt:
                break
            need = nxt
            j += 1
        keep[k] = j
        k += 1
        anchor = j
    return keep[:k]


def clearance_path(grid: OccupancyGrid, start: Any, goal: Any,
                   params: ClearanceParams | None = None) -> NDArray[np.float64]:
    """The ``clearance_astar`` path from ``start`` to ``goal`` (m), ``(P, 2)``; empty when none.

    The path starts at ``start`` and ends at ``goal`` exactly, through the
    centres of the cells in between.
    """
    p = params if params is not None else ClearanceParams()
    start = np.asarray(start, dtype=float).reshape(2)
    goal = np.asarray(goal, dtype=float).reshape(2)
    blocked = planning_grid(grid, p.inflate, (start, goal))
    dist = grid.distance_field
    span = max(p.clearance - p.inflate, 1e-9)
    penalty = np.clip((p.clearance - dist) / span, 0.0, 1.0)
    (sr, sc), (gr, gc) = (tuple(int(v) for v in grid.world_to_cell(q)) for q in (start, goal))
    h, w = blocked.shape
    if not (0 <= sr < h and 0 <= sc < w and 0 <= gr < h and 0 <= gc < w) \
            or blocked[sr, sc] or blocked[gr, gc]:
        return np.zeros((0, 2))
    cells = _search(np.ascontiguousarray(blocked), np.ascontiguousarray(penalty),
                    float(p.weight), sr, sc, gr, gc)
    if len(cells) == 0:
        return np.zeros((0, 2))
    if p.shorten and len(cells) > 2:
        cells = cells[_shorten(np.ascontiguousarray(np.minimum(dist, 1e9)), cells,
                               float(p.clearance))]
    xy = np.column_stack((grid.origin[0] + (cells[:, 1] + 0.5) * grid.cell_size,
                          grid.origin[1] + (cells[:, 0] + 0.5) * grid.cell_size))
    return np.vstack((start, xy[1:-1], goal)) if len(xy) > 1 else np.vstack((start, goal))


@register_planner("clearance_astar", params=ClearanceParams)
def clearance_planner(grid: OccupancyGrid, start: NDArray[np.float64], goal: NDArray[np.float64],
                      waypoints: Any, options: ClearanceParams | None = None
                      ) -> NDArray[np.float64]:
    """Leader planner: :func:`clearance_path` with the scenario's options."""
    return clearance_path(grid, start, goal, options)
