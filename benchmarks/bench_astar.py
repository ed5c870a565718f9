"""Benchmark: grid A* (dfcoa_opt.planning.astar) against a plain-Python heapq A*.

Run ``python -m benchmarks.bench_astar``. Each row times one call with
``time.perf_counter`` after a warm-up call (numba compilation excluded), ours
and the reference in interleaved repetitions (:mod:`benchmarks.timing`). The
reference is the textbook A* below (heapq, dict g-values, same moves, same
octile heuristic, no corner cutting), measured in the same run on the same
problem; both must return the same (optimal) cost, which is checked. The
compiled peer pyastar2d (C++, ``bench`` extra) is timed on the same grids when
it is installed; it solves an easier problem (diagonal steps cost 1, corners
are cut), so its rows compare speed, not optimality.

Problems:
- the paper-000 Scenario 1 map (``scenarios/**/dfcoa_s1.toml``) rasterised at
  1 cell/m (35 x 35 cells), start (7, 7) m -> goal (12, 29) m;
- a 1024 x 1024 grid, each cell blocked with probability 0.2 (seed 0), from the
  bottom-left to the top-right corner (the 2 x 2 corner blocks are cleared);
- improved vs traditional A* per expanded node and per search on the DFCOA S1
  and S2 maps at 10 cells/m (:func:`per_node_rows`).

:func:`jps_rows` times jump point search (``method="jps"``) on the first two
problems against pyastar2d and against our A*, after checking that it returns
A*'s cost.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np

from benchmarks.timing import interleave, print_rows, row
from dfcoa_opt.planning import postprocess
from dfcoa_opt.planning.astar import AStarParams, obstacle_term, plan, search
from dfcoa_opt.planning.improved_astar import ImprovedAStarParams, Task
from dfcoa_opt.world.grid import OccupancyGrid

SQRT2 = math.sqrt(2.0)
ROOT = Path(__file__).resolve().parents[1]


#: The compiled peer of row (b) (speed only; see :func:`pyastar2d_calls`).
PEER = "pyastar2d 1.1 C++ A* (diagonal steps cost 1, cuts corners)"


def heapq_astar(occ: list[list[bool]], start: tuple[int, int],
                goal: tuple[int, int]) -> tuple[float, int]:
    """Reference: plain-Python A* (heapq); returns (cost in cells, nodes expanded)."""
    n_rows, n_cols = len(occ), len(occ[0])
    gr, gc = goal

    def h(r: int, c: int) -> float:
        dr, dc = abs(r - gr), abs(c - gc)
        return max(dr, dc) + (SQRT2 - 1.0) * min(dr, dc)

    moves = [(1, 0, 1.0), (-1, 0, 1.0), (0, 1, 1.0), (0, -1, 1.0),
             (1, 1, SQRT2), (1, -1, SQRT2), (-1, 1, SQRT2), (-1, -1, SQRT2)]
    g = {start: 0.0}
    closed: set[tuple[int, int]] = set()
    heap = [(h(*start), 0.0, start)]
    while heap:
        _, _, u = heapq.heappop(heap)
        if u in closed:
            continue
        closed.add(u)
        if u == goal:
            return g[u], len(closed)
        r, c = u
        for dr, dc, w in moves:
            vr, vc = r + dr, c + dc
            if not (0 <= vr < n_rows and 0 <= vc < n_cols) or occ[vr][vc]:
                continue
            if dr and dc and (occ[r][vc] or occ[vr][c]):
                continue
            v = (vr, vc)
            ng = g[u] + w
            if v not in closed and ng < g.get(v, math.inf):
                g[v] = ng
                heapq.heappush(heap, (ng + h(vr, vc), -ng, v))
    return math.inf, len(closed)


def s1_grid() -> OccupancyGrid:
    """The dfcoa_s1 scenario's obstacles at 1 cell/m (35 x 35 cells)."""
    from dfcoa_opt.scenario.loader import scenario_from_dict
    from dfcoa_opt.scenario.overrides import read_toml

    path = sorted((ROOT / "scenarios").rglob("dfcoa_s1.toml"))[0]
    data = read_toml(path)
    data["world"]["resolution"] = 1
    leader = {k: v for k, v in data["leader"].items() if k != "planner_options"}
    data["leader"] = {**leader, "planner": "straight"}  # only the map is needed
    return scenario_from_dict(data, str(path), path.parent).world.grid


def random_grid(n: int = 1024, density: float = 0.2, seed: int = 0) -> np.ndarray:
    """``(n, n)`` cells blocked with probability ``density``; corner 2 x 2 blocks cleared."""
    occ = np.random.default_rng(seed).random((n, n)) < density
    occ[:2, :2] = occ[-2:, -2:] = False
    return occ


def _check(ours: float, ref: float, what: str) -> None:
    if abs(ours - ref) > 1e-6:
        raise AssertionError(f"{what}: cost {ours} differs from the reference {ref}")


def pyastar2d_call(occ: np.ndarray, start: tuple[int, int],
                   goal: tuple[int, int]) -> Callable[[int], object] | None:
    """pyastar2d's C++ A* on the same grid as ``fn(k)``; None if it is not installed.

    pyastar2d (``bench`` extra) is a speed peer only: a move costs the weight
    of the cell entered, so diagonal steps cost 1, not sqrt(2), and it cuts
    corners -- not the same shortest-path problem as ours.
    """
    try:
        import pyastar2d
    except ImportError:
        print("pyastar2d is not installed: its peer rows are left out (pip install pyastar2d)")
        return None
    weights = np.where(occ, np.inf, 1.0).astype(np.float32)
    if pyastar2d.astar_path(weights, start, goal, allow_diagonal=True) is None:
        raise RuntimeError("pyastar2d found no path where ours did")
    return lambda k: pyastar2d.astar_path(weights, start, goal, allow_diagonal=True)


def per_node_rows() -> list[dict]:
    """Improved vs traditional A* on the DFCOA S1 and S2 maps: per node and per search.

    At the maps' own 10 cells/m with their 1.2 m inflation, start and goal: the
    searched grid, the eq 13 options and the map's obstacle term
    (:func:`obstacle_term`, once per map, as :func:`plan` keeps it) are prepared
    outside the timing. Two rows per map:

    - eq 13 alone (no node optimisation), times divided by each search's nodes
      expanded, so the ratio compares the cost of one expansion (issue 21:
      >= 1/1.2);
    - the default improved A* (eq 13 and the node optimisation, the paper's
      full reading) against traditional A*, whole search (the paper's "time").
    """
    from dfcoa_opt.bench.recipes.astar import dfcoa_tasks

    tasks, inflate = dfcoa_tasks(ROOT / "scenarios")
    return [r for task in tasks for r in _improved_rows(task, inflate)]


def _improved_rows(task: Task, inflate: float) -> list[dict]:
    """The two rows of :func:`per_node_rows` for one map."""
    start, goal = np.asarray(task.start), np.asarray(task.goal)
    occ = postprocess.planning_grid(task.grid, inflate, (start, goal))
    s_rc = tuple(int(v) for v in task.grid.world_to_cell(start))
    g_rc = tuple(int(v) for v in task.grid.world_to_cell(goal))
    opts = {}
    for name, shortcut in (("eq13", False), ("full", True)):
        params = ImprovedAStarParams(inflate=inflate, goal_shortcut=shortcut)
        opts[name] = params.search_options(task.grid.resolution)
        opts[name]["obstacle_field"] = obstacle_term(occ, opts[name]["window"])
    nodes = {k: search(occ, s_rc, g_rc, **o).expanded for k, o in opts.items()}
    nodes["trad"] = search(occ, s_rc, g_rc).expanded
    t = interleave({"eq13": (lambda k: search(occ, s_rc, g_rc, **opts["eq13"]), 40),
                    "full": (lambda k: search(occ, s_rc, g_rc, **opts["full"]), 40),
                    "trad": (lambda k: search(occ, s_rc, g_rc), 40)})
    per_node = {k: [a / nodes[k] for a in v] for k, v in t.items()}
    trad = f"traditional A* ({nodes['trad']} nodes)"
    return [row(f"improved A* search per node, eq 13 alone, {task.name} map at 10 cells/m "
                f"({nodes['eq13']} nodes)", per_node["eq13"],
                f"{trad} search per node, same task", per_node["trad"]),
            row(f"improved A* whole search, eq 13 + node optimisation (default), {task.name} "
                f"map at 10 cells/m ({nodes['full']} nodes)", t["full"],
                f"{trad} whole search, same task", t["trad"])]


def run() -> list[dict]:
    """Time the searches; returns one dict per configuration."""
    rows = []
    ref_name = "plain-Python heapq A* (same moves and heuristic)"

    grid = s1_grid()
    occ = grid.occupied
    s_rc = tuple(int(v) for v in grid.world_to_cell(np.array([7.0, 7.0])))
    g_rc = tuple(int(v) for v in grid.world_to_cell(np.array([12.0, 29.0])))
    occ_list = occ.tolist()
    _check(search(occ, s_rc, g_rc).cost, heapq_astar(occ_list, s_rc, g_rc)[0], "35x35")
    peer = pyastar2d_call(occ, s_rc, g_rc)
    calls = {"search": (lambda k: search(occ, s_rc, g_rc), 200),
             "heapq": (lambda k: heapq_astar(occ_list, s_rc, g_rc), 40),
             "plan": (lambda k: plan(grid, (7.0, 7.0), (12.0, 29.0), AStarParams()), 200),
             "improved": (lambda k: plan(grid, (7.0, 7.0), (12.0, 29.0),
                                         ImprovedAStarParams()), 200)}
    if peer is not None:
        calls["peer"] = (peer, 200)
    t = interleave(calls)
    rows.append(row("A* search 35x35 (dfcoa_s1 at 1 cell/m)", t["search"], ref_name, t["heapq"]))
    if peer is not None:
        rows.append(row("A* search 35x35 (dfcoa_s1 at 1 cell/m)", t["search"], PEER, t["peer"]))
    rows.append(row("A* plan 35x35 (inflate 0.5 m, search, shortening, metres)", t["plan"],
                    ref_name, t["heapq"]))
    rows.append(row("improved A* plan 35x35 (defaults: eq 13 + node optimisation)", t["improved"],
                    "traditional A* plan, same map", t["plan"]))
    rows += per_node_rows()

    big = random_grid()
    corner = (big.shape[0] - 1, big.shape[1] - 1)
    ours = search(big, (0, 0), corner)
    ref_cost, ref_nodes = heapq_astar(big.tolist(), (0, 0), corner)
    _check(ours.cost, ref_cost, "1024x1024")
    big_list = big.tolist()
    what = (f"A* search 1024x1024, 20% random cells, corner to corner "
            f"({ours.expanded} nodes; reference {ref_nodes})")
    peer = pyastar2d_call(big, (0, 0), corner)
    calls = {"search": (lambda k: search(big, (0, 0), corner), 3)}
    if peer is not None:
        calls["peer"] = (peer, 3)
    t = interleave(calls)
    ref = interleave({"heapq": (lambda k: heapq_astar(big_list, (0, 0), corner), 1),
                      "search": (lambda k: search(big, (0, 0), corner), 1)})
    rows.append(row(what, ref["search"], ref_name, ref["heapq"]))
    if peer is not None:
        rows.append(row(what, t["search"], PEER, t["peer"]))
    return rows + jps_rows()


def jps_rows() -> list[dict]:
    """Jump point search (``search(..., method="jps")``) on the same two problems.

    Each problem is checked first: JPS must return A*'s (optimal) cost. Then
    JPS, our A* and pyastar2d are timed in interleaved repetitions
    (:func:`~benchmarks.timing.interleave`).
    """
    rows = []
    grid = s1_grid()
    s1 = (grid.occupied, tuple(int(v) for v in grid.world_to_cell(np.array([7.0, 7.0]))),
          tuple(int(v) for v in grid.world_to_cell(np.array([12.0, 29.0]))))
    big = random_grid()
    problems = [("35x35 (dfcoa_s1 at 1 cell/m)", s1, 200),
                ("1024x1024, 20% random cells, corner to corner", (big, (0, 0), (1023, 1023)), 3)]
    for name, (occ, start, goal), samples in problems:
        jps = search(occ, start, goal, method="jps")
        ref = search(occ, start, goal)
        _check(jps.cost, ref.cost, f"JPS {name}")
        what = f"JPS search {name} ({jps.expanded} jump points; A* {ref.expanded} nodes)"
        calls = {"jps": (lambda k, o=occ, s=start, g=goal: search(o, s, g, method="jps"), samples),
                 "astar": (lambda k, o=occ, s=start, g=goal: search(o, s, g), samples)}
        peer = pyastar2d_call(occ, start, goal)
        if peer is not None:
            calls["peer"] = (peer, samples)
        t = interleave(calls)
        if peer is not None:
            rows.append(row(what, t["jps"], PEER, t["peer"]))
        rows.append(row(what, t["jps"], "our A* search (same problem, same cost)", t["astar"]))
    return rows


if __name__ == "__main__":
    print_rows(run())
