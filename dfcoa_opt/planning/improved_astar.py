"""Improved A* of paper 000 (section 4.1, eq 12-13) and the A* comparison.

Eq 13 (paper 000, citing its ref. [31])::

    f(n) = g(n) + h(n)
           + beta / const_1 * sum_{i=0}^{M} 1 / sqrt((Y_tar - Y_pos)^2 + (x_tar - x_pos)^2)
           - alpha h(n) / const_2 * (R - r) / R

Our reading (docs/methods/astar.md, "Paper ambiguities"): ``(x_pos, Y_pos)``
is the node, ``(x_tar, Y_tar)_i`` the centres of the M occupied cells within
``window`` of it (a disc), distances in m, each term weighted by the cell area
(1 m^2 at the paper's 1 cell/m, where this is eq 13 exactly; the weight keeps
the sum from growing with the square of the resolution); ``R`` is the
start-goal and ``r`` the node-goal Euclidean distance. o(n) is a node term of f only: g stays the
travelled length, so the returned cost is a true path length. The search never
reopens closed nodes (the flowchart: "selects all nodes that are not in the
closed set"), so with beta > 0 or alpha > 0 the path is no longer guaranteed
shortest. The flowchart's "optimizes the current node with the target node" is
``goal_shortcut`` (join the goal by line of sight; on by default), and "optimizing
the path length based on connecting the nearest nodes" is the line-of-sight
shortening of :mod:`dfcoa_opt.planning.postprocess`.

:func:`compare_planners` times traditional vs improved A* on given maps and on
seeded random maps (:func:`random_map`) and :func:`comparison_markdown` prints
the relative change beside the paper's claims.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.core.params import param
from dfcoa_opt.planning import postprocess
from dfcoa_opt.planning.astar import AStarParams, obstacle_term, plan, search
from dfcoa_opt.planning.registry import register_planner
from dfcoa_opt.world.grid import OccupancyGrid

#: Paper 000 claims for improved vs traditional A* (abstract, contribution 2).
PAPER_CLAIMS = {"time": -0.27, "nodes": -0.35}


@dataclass(frozen=True)
class ImprovedAStarParams(AStarParams):
    """Options of the ``improved_astar`` planner (eq 13); also every ``astar`` option."""

    alpha: float = param(0.5, doc="alpha of eq 13: weight of the heuristic reduction "
                                  "-alpha h (R - r) / (const_2 R).", ge=0.0)
    beta: float = param(1.0, doc="beta of eq 13: weight of the obstacle term "
                                 "beta / const_1 sum a / d_i (d_i in m, a = cell area in m^2, "
                                 "so o(n) is in m).", ge=0.0)
    const1: float = param(1.0, doc="const_1 of eq 13 (normalises beta).", gt=0.0)
    const2: float = param(1.0, doc="const_2 of eq 13 (normalises alpha).", gt=0.0)
    window: float = param(1.5, doc="Radius of the disc around a node whose occupied cells "
                                   "enter the obstacle sum of eq 13 (M = their number).",
                          unit="m", ge=0.0)
    goal_shortcut: bool = param(True, doc="Fig. 7 node optimisation (\"optimizes the current "
                                          "node with the target node\"): join the goal by line "
                                          "of sight from the closest node expanded so far. On "
                                          "by default, the flowchart's full reading; false "
                                          "leaves eq 13 alone.")

    def search_options(self, resolution: float) -> dict[str, Any]:
        """Keyword arguments of :func:`~dfcoa_opt.planning.astar.search` (cell units).

        With ``a = 1 / resolution^2`` and ``d_m = d_cells / resolution``,
        ``o(n)`` in cells (= resolution * o in m) is ``beta / const1 * sum 1 / d_cells``:
        the obstacle gain does not depend on the resolution.
        """
        return {"heuristic": self.heuristic, "corner_cutting": self.corner_cutting,
                "h_gain": self.alpha / self.const2, "o_gain": self.beta / self.const1,
                "window": self.window * resolution, "goal_shortcut": self.goal_shortcut,
                "method": self.method}


@register_planner("improved_astar", params=ImprovedAStarParams)
def improved_astar_planner(grid: OccupancyGrid, start: NDArray[np.float64],
                           goal: NDArray[np.float64], waypoints: Any,
                           options: ImprovedAStarParams | None = None) -> NDArray[np.float64]:
    """Improved A* (eq 13) leader planner: ``(P, 2)`` path in m, empty when unreachable."""
    return plan(grid, start, goal, options if options is not None else ImprovedAStarParams()).path


# ------------------------------------------------------------------ comparison
@dataclass(frozen=True)
class Task:
    """One planning problem: a map and a start/goal pair in m."""

    name: str
    grid: OccupancyGrid
    start: tuple[float, float]
    goal: tuple[float, float]


def random_map(rng: np.random.Generator, shape: tuple[int, int] = (64, 64),
               density: float = 0.2, kind: Literal["blocks", "cells"] = "blocks",
               max_block: int = 8) -> NDArray[np.bool_]:
    """A random ``(H, W)`` occupancy array (True = blocked).

    Args:
        rng: Random generator (the only source of randomness).
        shape: ``(rows, cols)``.
        density: Target fraction of blocked cells in [0, 1).
        kind: ``"cells"``: each cell blocked with probability ``density``;
            ``"blocks"``: axis-aligned rectangles with sides 1..``max_block`` cells
            added until the blocked fraction reaches ``density``.
        max_block: Largest rectangle side in cells (``"blocks"`` only).
    """
    if not 0.0 <= density < 1.0:
        raise ValueError("density must be in [0, 1)")
    n_rows, n_cols = shape
    if kind == "cells":
        return rng.random(shape) < density
    occ = np.zeros(shape, dtype=bool)
    target = density * occ.size
    while occ.sum() < target:
        h, w = rng.integers(1, max_block + 1, size=2)
        r, c = rng.integers(0, n_rows), rng.integers(0, n_cols)
        occ[r:r + h, c:c + w] = True
    return occ


def random_tasks(rng: np.random.Generator, n: int = 50, shape: tuple[int, int] = (64, 64),
                 density: float = 0.2, kind: Literal["blocks", "cells"] = "blocks",
                 resolution: float = 1.0) -> list[Task]:
    """``n`` solvable tasks on random maps, start near one corner and goal near the opposite.

    Start and goal are drawn in the bottom-left / top-right eighths of the map
    until traditional A* connects them (4 tries, then a new map).
    """
    tasks: list[Task] = []
    n_rows, n_cols = shape
    while len(tasks) < n:
        grid = OccupancyGrid(random_map(rng, shape, density, kind), resolution)
        for _ in range(4):
            s = (int(rng.integers(0, n_rows // 8 + 1)), int(rng.integers(0, n_cols // 8 + 1)))
            g = (int(rng.integers(n_rows - 1 - n_rows // 8, n_rows)),
                 int(rng.integers(n_cols - 1 - n_cols // 8, n_cols)))
            if search(grid.occupied, s, g).found:
                start, goal = ((float(v) for v in grid.cell_centers()[rc]) for rc in (s, g))
                tasks.append(Task(f"random_{kind}_{len(tasks):02d}", grid, tuple(start),
                                  tuple(goal)))
                break
    return tasks


#: Name of the improved planner without the node optimisation in :func:`default_planners`.
EQ13_ONLY = "improved_astar (eq 13 only)"


def default_planners(inflate: float = 0.0) -> dict[str, AStarParams]:
    """Traditional A*, improved A* (defaults: eq 13 and the node optimisation), eq 13 alone.

    All with obstacle inflation ``inflate`` m and line-of-sight shortening.
    """
    return {"astar": AStarParams(inflate=inflate),
            "improved_astar": ImprovedAStarParams(inflate=inflate),
            EQ13_ONLY: ImprovedAStarParams(inflate=inflate, goal_shortcut=False)}


def compare_planners(tasks: Iterable[Task], planners: Mapping[str, AStarParams] | None = None,
                     repeats: int = 5) -> list[dict[str, Any]]:
    """Plan every task with every planner; one row per (task, planner).

    Args:
        tasks: Problems (see :func:`random_tasks`).
        planners: Name -> options; default :func:`default_planners` (no inflation).
            ``ImprovedAStarParams`` options run eq 13.
        repeats: Timed runs per row (after one warm-up); the median is reported.

    Returns:
        Rows with ``map``, ``planner``, ``time_ms`` (median whole plan, including
        inflation and post-processing, with the map's eq 13 obstacle term already
        kept by :func:`~dfcoa_opt.planning.astar.plan`), ``prep_ms`` (computing that
        term once for the map, :func:`~dfcoa_opt.planning.astar.obstacle_term`; 0 for
        a planner without it), ``search_ms`` (median search only),
        ``nodes`` (expanded), ``length_m`` (final path), ``raw_length_m``
        (search path), ``min_clearance_m`` (sampled every quarter cell against the
        un-inflated map) and ``found``.
    """
    planners = dict(planners) if planners is not None else default_planners()
    rows = []
    for task in tasks:
        for name, params in planners.items():
            plan(task.grid, task.start, task.goal, params)  # warm-up (numba, distance field)
            runs = [plan(task.grid, task.start, task.goal, params) for _ in range(repeats)]
            res = runs[-1]
            rows.append({
                "map": task.name, "planner": name,
                "time_ms": 1e3 * float(np.median([r.time for r in runs])),
                "prep_ms": _prep_ms(task, params),
                "search_ms": 1e3 * float(np.median([r.search.time for r in runs])),
                "nodes": res.expanded, "found": res.found,
                "length_m": res.length,
                "raw_length_m": postprocess.path_length(res.raw_path) if res.found else math.inf,
                "min_clearance_m": postprocess.min_clearance(task.grid, res.path),
            })
    return rows


def _prep_ms(task: Task, params: AStarParams) -> float:
    """Time (ms) to compute the eq 13 obstacle term once for the task's searched grid."""
    options = params.search_options(task.grid.resolution)
    if options.get("o_gain", 0.0) <= 0.0 or options.get("window", 0.0) < 1.0:
        return 0.0
    ends = (np.asarray(task.start, dtype=float), np.asarray(task.goal, dtype=float))
    occ = postprocess.planning_grid(task.grid, params.inflate, ends)
    t0 = time.perf_counter()
    obstacle_term(occ, options["window"])
    return 1e3 * (time.perf_counter() - t0)


def _relative(rows: Sequence[Mapping[str, Any]], key: str, planner: str,
              base: str) -> tuple[float, float, float]:
    """Means of ``key`` for ``planner`` and ``base`` over maps both solved, and their ratio - 1."""
    by = {(r["map"], r["planner"]): r for r in rows}
    maps = sorted({r["map"] for r in rows if (r["map"], base) in by and (r["map"], planner) in by
                   and by[r["map"], base]["found"] and by[r["map"], planner]["found"]})
    if not maps:
        return math.nan, math.nan, math.nan
    a = np.array([by[m, planner][key] for m in maps], dtype=float)
    b = np.array([by[m, base][key] for m in maps], dtype=float)
    change = a.mean() / b.mean() - 1.0 if b.mean() != 0 else math.nan
    return float(a.mean()), float(b.mean()), float(change)


def comparison_markdown(rows: Sequence[Mapping[str, Any]], base: str = "astar") -> str:
    """Markdown table: per-planner means over maps and the change vs ``base`` beside the paper.

    The change is ``mean(planner) / mean(base) - 1`` over the maps where both
    found a path. The paper's claims (-27 % time, -35 % nodes) are printed in
    their own column; positive changes mean the planner is slower / expands more.
    Planners with eq 13's obstacle term get a "map preparation" row: computing
    that term once per map, which the planning time leaves out (``plan`` keeps it).
    """
    planners = list(dict.fromkeys(r["planner"] for r in rows))
    n_maps = len({r["map"] for r in rows})
    maps = f"{n_maps} map" + ("" if n_maps == 1 else "s")
    lines = [f"Traditional vs improved A* on {maps} (means over maps; change = ratio of "
             f"the means - 1 vs `{base}`).", "",
             "| planner | metric | mean | change vs " + base + " | paper (improved vs A*) |",
             "|---|---|---|---|---|"]
    claims = {"time_ms": PAPER_CLAIMS["time"], "nodes": PAPER_CLAIMS["nodes"]}
    for p in planners:
        for key, label in (("time_ms", "planning time (ms)"),
                           ("prep_ms", "map preparation (ms, once per map)"),
                           ("search_ms", "search time (ms)"),
                           ("nodes", "nodes expanded"), ("length_m", "path length (m)"),
                           ("min_clearance_m", "min clearance (m)")):
            if key == "prep_ms" and not any(r.get(key) for r in rows if r["planner"] == p):
                continue  # a planner without the eq 13 obstacle term prepares nothing
            mean, base_mean, change = _relative(rows, key, p, base)
            paper = f"{claims[key]:+.0%}" if key in claims and p != base else ""
            ch = "" if p == base or base_mean == 0 else f"{change:+.1%}"
            lines.append(f"| {p} | {label} | {mean:.4g} | {ch} | {paper} |")
    solved = {p: sum(1 for r in rows if r["planner"] == p and r["found"]) for p in planners}
    lines += ["", "Solved: " + ", ".join(f"{p} {k}/{n_maps}" for p, k in solved.items()) + "."]
    return "\n".join(lines)
