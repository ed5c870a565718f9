"""Traditional A* on an 8-connected occupancy grid (paper 000, eq 12 with o(n) = 0).

The search is one numba kernel (:mod:`dfcoa_opt.planning.astar_kernel`) with
an array-based, indexed 4-ary min-heap (decrease-key; each node is in the heap
at most once). The same kernel runs
the improved A* of eq 13 (:mod:`dfcoa_opt.planning.improved_astar`) when its
extra terms are non-zero, so both planners share every line of the search.

Moves: 4 straight moves cost 1 cell, 4 diagonal moves cost sqrt(2) cells. Without
corner cutting (default; the MovingAI benchmark rule) a diagonal move needs both
orthogonal side cells free; with ``corner_cutting`` one free side cell is enough
(it never squeezes between two blocked cells). Heuristics (in cells): octile
``max + (sqrt(2) - 1) min`` of ``|d row|, |d col|`` (the exact cost on an empty
grid) or Euclidean. Both are consistent, so the first time the goal is popped
its g is optimal and closed nodes are never reopened. Among equal f, deeper
nodes (larger g) go first: successors whose f equals the current minimum are
expanded from a LIFO stack without touching the heap, and heap keys are
``f - 1e-9 g``. This changes neither optimality nor the cost, only the number
of nodes expanded (fewer on open maps) and the speed.

``method="jps"`` runs jump point search instead
(:mod:`dfcoa_opt.planning.jps_kernel`): the same optimal cost on the same moves
without corner cutting, fewer nodes expanded (jump points), not valid with
corner cutting or eq 13's terms (``search`` refuses them).

:func:`plan` wraps the search for world coordinates: obstacle inflation, the
search, line-of-sight shortening, optional smoothing, conversion to metres.
"""

from __future__ import annotations

import hashlib
import math
import time
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dfcoa_opt.core.errors import ScenarioError
from dfcoa_opt.core.params import param
from dfcoa_opt.planning import postprocess
from dfcoa_opt.planning.astar_kernel import astar_kernel, workspace
from dfcoa_opt.planning.jps_kernel import jps_kernel
from dfcoa_opt.planning.registry import register_planner
from dfcoa_opt.world.grid import OccupancyGrid

_NO_FIELD = np.zeros((1, 1), dtype=np.float64)
#: Obstacle terms kept by :func:`plan` per (grid bytes, shape, window): a map planned on
#: again costs one hash instead of one FFT.
_FIELDS: OrderedDict[tuple[bytes, tuple[int, ...], float], NDArray[np.float64]] = OrderedDict()
_FIELDS_KEPT = 8


@dataclass(frozen=True)
class AStarParams:
    """Options of the ``astar`` planner (``[leader.planner_options]``)."""

    heuristic: Literal["octile", "euclidean"] = param(
        "octile", doc="Heuristic h(n): octile (exact on an empty 8-connected grid) or "
                      "Euclidean; both are admissible and give optimal paths.")
    corner_cutting: bool = param(False, doc="Allow a diagonal move when one of its two side "
                                            "cells is blocked (default: both must be free).")
    inflate: float = param(0.5, doc="Grow obstacles by this radius before planning (room for "
                                    "the virtual leader's formation); cells near the start and "
                                    "goal that only inflation blocks are released.", unit="m",
                           ge=0.0)
    shorten: bool = param(True, doc="Remove redundant nodes by exact line-of-sight checks.")
    smooth: bool = param(False, doc="Round the shortened path's corners where free (Chaikin).")
    smooth_iterations: int = param(3, doc="Chaikin rounds when smooth is true.", ge=1, le=8)
    method: Literal["astar", "jps"] = param(
        "astar", doc="Search: plain A* or jump point search (same optimal cost, fewer nodes "
                     "expanded; only without corner cutting and eq 13 terms).")

    def search_options(self, resolution: float) -> dict[str, Any]:
        """Keyword arguments of :func:`search` for this planner (no eq 13 terms)."""
        return {"heuristic": self.heuristic, "corner_cutting": self.corner_cutting,
                "method": self.method}

    def check(self, src: str, key: str) -> None:
        """``method = "jps"`` only with the options it is optimal for (see :func:`search`)."""
        if self.method == "jps":
            o = self.search_options(1.0)
            bad = jps_conflicts(o["corner_cutting"], o.get("h_gain", 0.0), o.get("o_gain", 0.0),
                                o.get("goal_shortcut", False))
            if bad:
                raise ScenarioError(src, f"{key}.method" if key else "method",
                                    f"'jps' cannot be combined with {', '.join(bad)}")


@dataclass(frozen=True)
class SearchResult:
    """Outcome of one grid search (cell units).

    Attributes:
        cells: ``(P, 2)`` path cells ``(row, col)`` from start to goal; empty when
            not found. Consecutive cells are 8-neighbours unless the improved
            search's goal shortcut joined the last one by line of sight.
        cost: g(goal) in cells (straight 1, diagonal sqrt 2); ``inf`` when not found.
        expanded: Nodes expanded (closed); jump points for ``method="jps"``.
        time: Wall time of the search in s.
    """

    cells: NDArray[np.int64]
    cost: float
    expanded: int
    time: float

    @property
    def found(self) -> bool:
        """Whether a path was found."""
        return len(self.cells) > 0


@dataclass(frozen=True)
class AStarResult:
    """Outcome of :func:`plan` (world units).

    Attributes:
        search: The grid search (cells, cost in cells, nodes expanded, search time).
        raw_path: ``(P, 2)`` m, the search's cell centres, preceded by the exact
            start and followed by the exact goal (when they are not the centres).
        path: ``(Q, 2)`` m, after shortening / smoothing (what the leader follows).
        time: Wall time of the whole plan (inflation, search, post-processing) in s.
        occupied: The grid actually searched (after inflation and release).
    """

    search: SearchResult
    raw_path: NDArray[np.float64]
    path: NDArray[np.float64]
    time: float
    occupied: NDArray[np.bool_] = field(repr=False)

    @property
    def found(self) -> bool:
        """Whether a path was found."""
        return self.search.found

    @property
    def cells(self) -> NDArray[np.int64]:
        """Search path cells ``(P, 2)`` (row, col)."""
        return self.search.cells

    @property
    def expanded(self) -> int:
        """Nodes expanded by the search."""
        return self.search.expanded

    @property
    def length(self) -> float:
        """Length of :attr:`path` in m (``inf`` when not found)."""
        return postprocess.path_length(self.path) if self.found else math.inf


def obstacle_term(occupied: ArrayLike, window: float) -> NDArray[np.float64]:
    """Eq 13's obstacle sum of every cell, in cells^-1: ``sum 1 / d_i`` over occupied cells.

    ``d_i`` is the distance (cells) from the cell's centre to the centre of
    occupied cell ``i``, summed over ``0 < d_i <= window``. The sum depends only
    on the map and the window, so it is the correlation of the occupancy grid
    with the kernel ``1 / d`` on the disc of radius ``window``, computed once per
    map by FFT (``scipy.signal.fftconvolve``) instead of once per node. The
    FFT's rounding (~1e-13) is cleared below 1e-9; a non-zero sum is at least
    ``1 / window``.

    Args:
        occupied: ``(H, W)`` bool, True = blocked.
        window: Radius of the disc in cells; below 1 no other cell is inside.

    Returns:
        ``(H, W)`` float array.
    """
    occ = np.asarray(occupied, dtype=bool)
    if window < 1.0:
        return np.zeros(occ.shape)
    w = int(min(math.floor(window), max(occ.shape)))  # a wider disc adds no cell
    dr, dc = np.mgrid[-w:w + 1, -w:w + 1]
    d = np.hypot(dr, dc)
    kernel = np.where((d > 0) & (d <= window), 1.0 / np.where(d > 0, d, 1.0), 0.0)
    from scipy.signal import fftconvolve  # here: scipy.signal costs ~0.5 s to import

    field = fftconvolve(occ.astype(float), kernel, mode="same")
    field[field < 1e-9] = 0.0
    return field


def _cached_obstacle_term(occ: NDArray[np.bool_], window: float) -> NDArray[np.float64]:
    """:func:`obstacle_term`, kept for the next :func:`plan` on the same map and window."""
    key = (hashlib.blake2b(occ.tobytes(), digest_size=16).digest(), occ.shape, float(window))
    field = _FIELDS.get(key)
    if field is None:
        field = obstacle_term(occ, window)
        _FIELDS[key] = field
        if len(_FIELDS) > _FIELDS_KEPT:
            _FIELDS.popitem(last=False)
    else:
        _FIELDS.move_to_end(key)
    return field


def jps_conflicts(corner_cutting: bool, h_gain: float, o_gain: float,
                  goal_shortcut: bool) -> list[str]:
    """The :func:`search` options that rule out ``method="jps"`` (empty when none).

    JPS prunes by the symmetry of uniform-cost 8-connected moves without corner
    cutting; corner cutting changes the moves, and eq 13's terms change the
    priority per cell, so its pruning would no longer be optimal for them.
    """
    return [name for name, on in (("corner_cutting", corner_cutting), ("h_gain", h_gain != 0.0),
                                  ("o_gain", o_gain != 0.0), ("goal_shortcut", goal_shortcut))
            if on]


def search(occupied: ArrayLike, start: ArrayLike, goal: ArrayLike, *, method: str = "astar",
           heuristic: str = "octile", corner_cutting: bool = False, h_gain: float = 0.0,
           o_gain: float = 0.0, window: float = 0.0, goal_shortcut: bool = False,
           obstacle_field: NDArray[np.float64] | None = None) -> SearchResult:
    """A* on a bool grid in cell units (eq 12; eq 13 when the gains are non-zero).

    Args:
        occupied: ``(H, W)`` bool, True = blocked; ``occupied[row, col]``.
        start: Start cell ``(row, col)``.
        goal: Goal cell ``(row, col)``.
        method: ``"astar"`` (every cell a node) or ``"jps"`` (jump point search,
            :mod:`~dfcoa_opt.planning.jps_kernel`: the same optimal cost, and a
            path of 8-neighbour cells, but ``expanded`` counts jump points).
            JPS needs the uniform-cost rules: no corner cutting and no eq 13 terms.
        heuristic: ``"octile"`` or ``"euclidean"`` (cells).
        corner_cutting: See the module docstring.
        h_gain: alpha / const_2 of eq 13 (dimensionless); 0 = traditional.
        o_gain: Weight of the obstacle term: o(n) = o_gain * sum 1 / d_i in cells,
            d_i in cells (``beta / const_1`` with the area weighting of
            :class:`~dfcoa_opt.planning.improved_astar.ImprovedAStarParams`);
            0 = traditional.
        window: Radius (cells) of the disc of obstacle cells summed in eq 13.
        goal_shortcut: Join the goal by line of sight from the closest node so far.
        obstacle_field: ``obstacle_term(occupied, window)`` when the caller has it
            (:func:`plan` keeps it per map); computed here when None. Either way
            a node's obstacle sum is one read.

    Returns:
        The path cells, g(goal) in cells, nodes expanded and the search time.
        An unreachable goal, or a start/goal that is blocked or outside the
        grid, gives an empty path and ``cost = inf``.

    Raises:
        ValueError: Unknown heuristic or method, or ``method="jps"`` with corner
            cutting or an eq 13 term.
    """
    t0 = time.perf_counter()
    if heuristic not in ("octile", "euclidean"):
        raise ValueError(f"heuristic must be 'octile' or 'euclidean', got {heuristic!r}")
    if method not in ("astar", "jps"):
        raise ValueError(f"method must be 'astar' or 'jps', got {method!r}")
    if method == "jps":
        bad = jps_conflicts(corner_cutting, h_gain, o_gain, goal_shortcut)
        if bad:
            raise ValueError("method 'jps' is optimal only for uniform move costs without "
                             f"corner cutting; it cannot be combined with {', '.join(bad)}")
    occ = np.ascontiguousarray(occupied, dtype=bool)
    sr, sc = (int(v) for v in np.asarray(start).reshape(2))
    gr, gc = (int(v) for v in np.asarray(goal).reshape(2))
    n_rows, n_cols = occ.shape
    inside = all(0 <= r < n_rows and 0 <= c < n_cols for r, c in ((sr, sc), (gr, gc)))
    if not inside or occ[sr, sc] or occ[gr, gc]:
        return SearchResult(np.zeros((0, 2), np.int64), math.inf, 0, time.perf_counter() - t0)
    obst = _NO_FIELD
    if o_gain > 0.0 and window >= 1.0:
        obst = obstacle_term(occ, window) if obstacle_field is None else obstacle_field
        if obst.shape != occ.shape:
            raise ValueError(f"obstacle_field has shape {obst.shape}, the grid {occ.shape}")
    else:
        o_gain = 0.0
    wp = n_cols + 2
    st = np.ones((n_rows + 2, wp), np.uint8)
    st[1:-1, 1:-1] = occ
    if method == "jps":
        cells, cost, expanded = jps_kernel(
            st.reshape(-1), wp, (sr + 1) * wp + sc + 1, (gr + 1) * wp + gc + 1,
            0 if heuristic == "octile" else 1)
        return SearchResult(cells, float(cost), int(expanded), time.perf_counter() - t0)
    cells, cost, expanded = astar_kernel(
        st.reshape(-1), wp, (sr + 1) * wp + sc + 1, (gr + 1) * wp + gc + 1,
        0 if heuristic == "octile" else 1, bool(corner_cutting), float(h_gain),
        math.hypot(sr - gr, sc - gc), float(o_gain), obst, bool(goal_shortcut),
        *workspace(st.size))
    return SearchResult(cells, float(cost), int(expanded), time.perf_counter() - t0)


def plan(grid: OccupancyGrid, start: ArrayLike, goal: ArrayLike,
         params: AStarParams | None = None) -> AStarResult:
    """Plan from ``start`` to ``goal`` (world m) with A* or improved A* and post-process.

    Steps: inflate obstacles by ``params.inflate``
    (:func:`~dfcoa_opt.planning.postprocess.planning_grid`, which releases the
    surroundings of a start or goal that only inflation blocks); search
    (:func:`search` with the options of ``params``, so an
    :class:`~dfcoa_opt.planning.improved_astar.ImprovedAStarParams` runs eq 13);
    shorten by line of sight; smooth; convert to m. The path
    starts at ``start`` and ends at ``goal`` exactly: they are joined to the
    centres of their own cells (a hop inside one free cell).

    Args:
        grid: The map.
        start: ``(x, y)`` m.
        goal: ``(x, y)`` m.
        params: Planner options; default :class:`AStarParams()`.
    """
    t0 = time.perf_counter()
    params = params if params is not None else AStarParams()
    start = np.asarray(start, dtype=float).reshape(2)
    goal = np.asarray(goal, dtype=float).reshape(2)
    occ = postprocess.planning_grid(grid, params.inflate, (start, goal))
    s_rc = tuple(int(v) for v in grid.world_to_cell(start))
    g_rc = tuple(int(v) for v in grid.world_to_cell(goal))
    options = params.search_options(grid.resolution)
    if options.get("o_gain", 0.0) > 0.0 and options.get("window", 0.0) >= 1.0:
        options["obstacle_field"] = _cached_obstacle_term(occ, options["window"])
    res = search(occ, s_rc, g_rc, **options)
    if not res.found:
        empty = np.zeros((0, 2))
        return AStarResult(res, empty, empty, time.perf_counter() - t0, occ)
    h, ox, oy = grid.cell_size, grid.origin[0], grid.origin[1]

    def to_world(xy_cells: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.column_stack((ox + xy_cells[:, 0] * h, oy + xy_cells[:, 1] * h))

    def with_ends(path: NDArray[np.float64]) -> NDArray[np.float64]:
        # the hop from the exact start (goal) to its cell centre stays inside that cell
        head = [] if tuple(path[0]) == tuple(start) else [start]
        tail = [] if tuple(path[-1]) == tuple(goal) else [goal]
        return np.vstack([*head, path, *tail])

    centres = res.cells[:, ::-1] + 0.5  # (x, y) in cell coordinates
    raw = with_ends(to_world(centres))
    kept = res.cells
    if params.shorten:
        kept = postprocess.shorten(occ, res.cells, params.corner_cutting)
    pts = kept[:, ::-1] + 0.5
    if params.smooth:
        pts = postprocess.smooth(occ, pts, params.smooth_iterations)
    path = with_ends(to_world(pts))
    return AStarResult(res, raw, path, time.perf_counter() - t0, occ)


@register_planner("astar", params=AStarParams)
def astar_planner(grid: OccupancyGrid, start: NDArray[np.float64], goal: NDArray[np.float64],
                  waypoints: Any, options: AStarParams | None = None) -> NDArray[np.float64]:
    """Traditional A* leader planner: ``(P, 2)`` path in m, empty when unreachable."""
    return plan(grid, start, goal, options).path
