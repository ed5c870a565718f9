"""Benchmark: grid A* (dfcoa_opt.planning.astar) against a plain-Python heapq A*.

Run ``python -m benchmarks.bench_astar``. Each row times one call with
``time.perf_counter`` after a warm-up call (numba compilation excluded). The
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
  bottom-left to the top-right corner (the 2 x 2 corner blocks are cleared).
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np

from benchmarks.bench_lidar import print_rows, row
from benchmarks.bench_lidar import time_calls as lidar_time_calls
from dfcoa_opt.planning.astar import AStarParams, plan, search
from dfcoa_opt.planning.astar_improved import ImprovedAStarParams
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
    from dfcoa_opt.sim.loader import read_toml, scenario_from_dict

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


def time_calls(fn: Callable[[], object], samples: int) -> np.ndarray:
    """Per-call times in us of ``fn()`` (after one warm-up)."""
    return lidar_time_calls(lambda _k: fn(), samples)


def _check(ours: float, ref: float, what: str) -> None:
    if abs(ours - ref) > 1e-6:
        raise AssertionError(f"{what}: cost {ours} differs from the reference {ref}")


def pyastar2d_calls(occ: np.ndarray, start: tuple[int, int], goal: tuple[int, int],
                    samples: int) -> np.ndarray | None:
    """Times (us) of pyastar2d's C++ A* on the same grid; None if it is not installed.

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
    return time_calls(lambda: pyastar2d.astar_path(weights, start, goal, allow_diagonal=True),
                      samples)


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
    ref = time_calls(lambda: heapq_astar(occ_list, s_rc, g_rc), 200)
    fast = time_calls(lambda: search(occ, s_rc, g_rc), 1000)
    rows.append(row("A* search 35x35 (dfcoa_s1 at 1 cell/m)", fast, ref_name, ref))
    peer = pyastar2d_calls(occ, s_rc, g_rc, 1000)
    if peer is not None:
        rows.append(row("A* search 35x35 (dfcoa_s1 at 1 cell/m)", fast, PEER, peer))
    full = time_calls(lambda: plan(grid, (7.0, 7.0), (12.0, 29.0), AStarParams()), 1000)
    rows.append(row("A* plan 35x35 (inflate 0.5 m, search, shortening, metres)", full,
                    ref_name, ref))
    improved = time_calls(lambda: plan(grid, (7.0, 7.0), (12.0, 29.0), ImprovedAStarParams()),
                          1000)
    rows.append(row("improved A* plan 35x35 (eq 13 defaults)", improved,
                    "traditional A* plan, same map", full))

    big = random_grid()
    corner = (big.shape[0] - 1, big.shape[1] - 1)
    ours = search(big, (0, 0), corner)
    ref_cost, ref_nodes = heapq_astar(big.tolist(), (0, 0), corner)
    _check(ours.cost, ref_cost, "1024x1024")
    big_list = big.tolist()
    ref = time_calls(lambda: heapq_astar(big_list, (0, 0), corner), 3)
    fast = time_calls(lambda: search(big, (0, 0), corner), 15)
    what = (f"A* search 1024x1024, 20% random cells, corner to corner "
            f"({ours.expanded} nodes; reference {ref_nodes})")
    rows.append(row(what, fast, ref_name, ref))
    peer = pyastar2d_calls(big, (0, 0), corner, 15)
    if peer is not None:
        rows.append(row(what, fast, PEER, peer))
    return rows


if __name__ == "__main__":
    print_rows(run())
