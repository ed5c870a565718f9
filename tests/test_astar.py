"""A* planners: MovingAI oracle, move rules, post-processing, eq 13, registration."""

from __future__ import annotations

import heapq
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from dfcoa_opt.errors import ScenarioError
from dfcoa_opt.planning import postprocess
from dfcoa_opt.planning.astar import AStarParams, obstacle_term, plan, search
from dfcoa_opt.planning.astar_improved import (
    PAPER_CLAIMS,
    ImprovedAStarParams,
    compare_planners,
    comparison_markdown,
    default_planners,
    random_map,
    random_tasks,
)
from dfcoa_opt.planning.registry import get_planner, planner_names
from dfcoa_opt.sim.loader import scenario_from_dict
from dfcoa_opt.world.grid import OccupancyGrid

# A copy of ../shared/data/movingai (MovingAI benchmark, movingai.com), kept in the
# repository so the oracle test runs on every checkout.
MOVINGAI = Path(__file__).resolve().parent / "data" / "movingai"
SQRT2 = math.sqrt(2.0)


# ------------------------------------------------------------------ helpers
def load_movingai_map(path: Path) -> OccupancyGrid:
    """Parse a MovingAI .map: '.' and 'G' passable, anything else blocked; row 0 at the bottom."""
    lines = path.read_text().splitlines()
    height = int(lines[1].split()[1])
    width = int(lines[2].split()[1])
    assert lines[0].strip() == "type octile" and lines[3].strip() == "map"
    rows = lines[4:4 + height]
    assert len(rows) == height and all(len(r) == width for r in rows)
    occ = np.array([[ch not in ".G" for ch in r] for r in rows])
    return OccupancyGrid(occ[::-1], resolution=1.0)


def movingai_problems() -> list[tuple[int, int, int, int, float]]:
    """(start_x, start_y, goal_x, goal_y, optimal length) of arena.map.scen (y from the top)."""
    lines = (MOVINGAI / "arena.map.scen").read_text().splitlines()
    assert lines[0].startswith("version")
    out = []
    for ln in lines[1:]:
        f = ln.split("\t")
        if len(f) >= 9:
            out.append((int(f[4]), int(f[5]), int(f[6]), int(f[7]), float(f[8])))
    return out


def dijkstra_cost(occ: np.ndarray, s: tuple[int, int], g: tuple[int, int],
                  corner_cutting: bool = False) -> float:
    """Independent oracle: scipy Dijkstra on the 8-connected graph."""
    n_rows, n_cols = occ.shape
    idx = np.arange(occ.size).reshape(occ.shape)
    src, dst, w = [], [], []
    for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1), (-1, 1), (-1, -1), (-1, 0), (0, -1)):
        for r in range(n_rows):
            for c in range(n_cols):
                vr, vc = r + dr, c + dc
                if not (0 <= vr < n_rows and 0 <= vc < n_cols) or occ[r, c] or occ[vr, vc]:
                    continue
                if dr and dc:
                    a, b = occ[r, vc], occ[vr, c]
                    if (a and b) if corner_cutting else (a or b):
                        continue
                src.append(idx[r, c])
                dst.append(idx[vr, vc])
                w.append(SQRT2 if dr and dc else 1.0)
    graph = coo_matrix((w, (src, dst)), shape=(occ.size, occ.size)).tocsr()
    return float(dijkstra(graph, indices=idx[s])[idx[g]])


def random_free_pair(rng: np.random.Generator, occ: np.ndarray) -> tuple[tuple, tuple]:
    free = np.argwhere(~occ)
    a, b = rng.choice(len(free), 2, replace=False)
    return tuple(int(v) for v in free[a]), tuple(int(v) for v in free[b])


def assert_valid_moves(occ: np.ndarray, cells: np.ndarray, corner_cutting: bool = False) -> None:
    """Consecutive 8-neighbours on free cells; diagonals obey the corner rule."""
    assert not occ[cells[:, 0], cells[:, 1]].any(), "path crosses a blocked cell"
    steps = np.diff(cells, axis=0)
    assert np.abs(steps).max(initial=0) <= 1 and (np.abs(steps).sum(1) > 0).all()
    for (r, c), (dr, dc) in zip(cells[:-1], steps, strict=True):
        if dr and dc:
            a, b = occ[r, c + dc], occ[r + dr, c]
            assert not (a and b), "squeezes between two blocked cells"
            if not corner_cutting:
                assert not (a or b), "cuts a corner"


def sampled_segment_free(occ: np.ndarray, p: np.ndarray, q: np.ndarray) -> bool:
    """Dense sampling (cell coordinates (x, y)): every sample lies in a free cell."""
    t = np.linspace(0.0, 1.0, 2001)[:, None]
    pts = p + t * (q - p)
    col, row = np.floor(pts[:, 0]).astype(int), np.floor(pts[:, 1]).astype(int)
    return not occ[row, col].any()


def scenario_dict(**leader: object) -> dict:
    """A minimal valid scenario with a wall between start and goal."""
    return {
        "world": {"size": [20.0, 10.0], "resolution": 5,
                  "obstacles": [{"type": "rectangle", "min": [9.0, 0.0], "max": [10.0, 7.0]}]},
        "robots": {"model": "unicycle", "radius": 0.2},
        "team": {"n": 3},
        "formation": {"shape": "line", "spacing": 0.8},
        "leader": {"start": [2.0, 2.0], "goal": [17.0, 2.0], **leader},
    }


# ------------------------------------------------------------------ oracle
@pytest.mark.parametrize("method", ["astar", "jps"])
def test_movingai_arena_all_optimal_lengths(method):
    grid = load_movingai_map(MOVINGAI / "arena.map")
    n_rows = grid.shape[0]
    problems = movingai_problems()
    assert len(problems) == 130
    for sx, sy, gx, gy, length in problems:
        s, g = (n_rows - 1 - sy, sx), (n_rows - 1 - gy, gx)  # MovingAI y counts from the top
        for heuristic in ("octile", "euclidean"):
            res = search(grid.occupied, s, g, heuristic=heuristic, method=method)
            assert res.cost == pytest.approx(length, abs=1e-6), (sx, sy, gx, gy, heuristic)
            assert len(res.cells) and tuple(res.cells[0]) == s and tuple(res.cells[-1]) == g
            assert_valid_moves(grid.occupied, res.cells)
            assert postprocess.path_length(res.cells) == pytest.approx(res.cost, abs=1e-9)
        # the same through the world-coordinate wrapper (1 cell/m: cost in cells = m)
        out = plan(grid, (sx + 0.5, n_rows - sy - 0.5), (gx + 0.5, n_rows - gy - 0.5),
                   AStarParams(inflate=0.0, shorten=False, method=method))
        assert out.search.cost == pytest.approx(length, abs=1e-6)
        assert postprocess.path_length(out.path) == pytest.approx(length, abs=1e-6)


@pytest.mark.parametrize("method", ["astar", "jps"])
def test_random_maps_match_dijkstra_both_heuristics_and_corner_rules(method):
    rng = np.random.default_rng(7)
    for k in range(12):
        occ = random_map(rng, (24, 30), 0.25, "cells" if k % 2 else "blocks")
        s, g = random_free_pair(rng, occ)
        for cut in (False, True) if method == "astar" else (False,):  # JPS: no corner cutting
            ref = dijkstra_cost(occ, s, g, cut)
            for heuristic in ("octile", "euclidean"):
                res = search(occ, s, g, heuristic=heuristic, corner_cutting=cut, method=method)
                if math.isinf(ref):
                    assert not res.found and math.isinf(res.cost)
                    continue
                assert res.cost == pytest.approx(ref, abs=1e-9)
                assert postprocess.path_length(res.cells) == pytest.approx(ref, abs=1e-9)
                assert_valid_moves(occ, res.cells, corner_cutting=cut)


# ------------------------------------------------------------------ move rules
def test_no_corner_cutting_between_diagonal_blocks():
    occ = np.zeros((3, 3), dtype=bool)
    occ[0, 1] = occ[1, 0] = True  # (0,0) touches (1,1) only through a corner
    assert not search(occ, (0, 0), (1, 1)).found
    assert not search(occ, (0, 0), (1, 1), corner_cutting=True).found  # never squeezes
    occ[1, 0] = False  # one side free: only corner cutting allows the diagonal
    assert search(occ, (0, 0), (1, 1)).cost == pytest.approx(2.0)
    assert search(occ, (0, 0), (1, 1), corner_cutting=True).cost == pytest.approx(SQRT2)


def test_unreachable_blocked_or_outside_gives_empty():
    occ = np.zeros((10, 10), dtype=bool)
    occ[:, 5] = True
    for s, g in (((2, 2), (2, 8)), ((0, 5), (2, 8)), ((2, 2), (2, 12)), ((-1, 0), (2, 2))):
        res = search(occ, s, g)
        assert not res.found and res.cells.shape == (0, 2) and math.isinf(res.cost)
    grid = OccupancyGrid(occ, 1.0)
    for name in ("astar", "improved_astar"):
        path = get_planner(name)(grid, np.array([2.5, 2.5]), np.array([8.5, 2.5]), None,
                                 AStarParams(inflate=0.0) if name == "astar" else None)
        assert path.shape == (0, 2)


def test_start_equals_goal_and_endpoints():
    occ = random_map(np.random.default_rng(3), (20, 20), 0.2)
    occ[4, 4:18] = occ[4:16, 17] = False  # a free L from (4, 4) to (15, 17)
    res = search(occ, (4, 4), (4, 4))
    assert res.found and res.cost == 0.0 and res.cells.tolist() == [[4, 4]]
    grid = OccupancyGrid(occ, 2.0, origin=(-1.0, 3.0))
    start, goal = np.array([1.3, 5.2]), np.array([7.6, 10.8])
    out = plan(grid, start, goal, AStarParams(inflate=0.0))
    assert out.found
    np.testing.assert_array_equal(out.path[0], start)
    np.testing.assert_array_equal(out.path[-1], goal)
    rows, cols = grid.world_to_cell(np.vstack((start, goal)))
    assert tuple(out.cells[0]) == (rows[0], cols[0]) and tuple(out.cells[-1]) == (rows[1], cols[1])


# ------------------------------------------------------------------ post-processing
def test_line_of_sight_is_exact_against_sampling():
    rng = np.random.default_rng(11)
    for _ in range(30):
        occ = random_map(rng, (16, 16), 0.15, "cells")
        for _ in range(20):
            a, b = random_free_pair(rng, occ)
            los = postprocess.line_of_sight(occ, a, b)
            assert los == postprocess.line_of_sight(occ, b, a)  # symmetric
            p, q = np.array(a[::-1]) + 0.5, np.array(b[::-1]) + 0.5
            if los:
                assert sampled_segment_free(occ, p, q)
                assert postprocess.segment_free(occ, p, q)
    corner = np.zeros((2, 2), dtype=bool)
    corner[0, 1] = True
    assert not postprocess.line_of_sight(corner, (0, 0), (1, 1))  # through the corner
    assert postprocess.line_of_sight(corner, (0, 0), (1, 1), corner_cutting=True)


@pytest.mark.parametrize("params", [ImprovedAStarParams(inflate=0.0),
                                    ImprovedAStarParams(inflate=0.0, goal_shortcut=False),
                                    ImprovedAStarParams(inflate=0.0, smooth=True)])
def test_improved_paths_are_free_and_shortening_helps(params):
    rng = np.random.default_rng(5)
    for task in random_tasks(rng, 8, (40, 40), 0.2):
        out = plan(task.grid, task.start, task.goal, params)
        occ = out.occupied
        assert out.found
        if not params.goal_shortcut:
            assert_valid_moves(occ, out.cells)
        assert out.length <= postprocess.path_length(out.raw_path) + 1e-9
        xy = (out.path - np.array(task.grid.origin)) * task.grid.resolution
        for p, q in zip(xy[:-1], xy[1:], strict=True):
            assert postprocess.segment_free(occ, p, q)
            assert sampled_segment_free(occ, p, q)
        if not params.smooth:
            kept = postprocess.shorten(occ, out.cells)
            for a, b in zip(kept[:-1], kept[1:], strict=True):
                assert postprocess.line_of_sight(occ, a, b)


def test_clearance_along_path_matches_brute_force():
    task = random_tasks(np.random.default_rng(4), 1, (30, 30), 0.15)[0]
    grid = OccupancyGrid(task.grid.occupied, 4.0, origin=(1.0, -2.0))
    start = np.array(task.start) / 4.0 + (1.0, -2.0)
    goal = np.array(task.goal) / 4.0 + (1.0, -2.0)
    out = plan(grid, start, goal, ImprovedAStarParams(inflate=0.3))
    assert out.found
    pts, clr = postprocess.path_clearance(grid, out.path)
    rows, cols = np.nonzero(grid.occupied)
    lo = np.column_stack((grid.origin[0] + cols / 4.0, grid.origin[1] + rows / 4.0))
    hi = lo + 0.25
    d = np.maximum(np.maximum(lo[None] - pts[:, None], 0.0), pts[:, None] - hi[None])
    brute = np.hypot(d[..., 0], d[..., 1]).min(axis=1)
    np.testing.assert_allclose(clr, brute, atol=1e-12)
    assert postprocess.min_clearance(grid, out.path) == pytest.approx(brute.min())
    assert brute.min() > 0.3 - 0.25  # inflation keeps the path away from the obstacles


# ------------------------------------------------------------------ eq 13
def test_alpha_term_expands_more_nodes_on_an_open_map():
    """Measured truth: reducing h (eq 13, alpha > 0) makes A* less informed, not faster."""
    occ = np.zeros((48, 48), dtype=bool)
    base = search(occ, (2, 3), (45, 40))
    assert base.expanded == 44  # deep tie-breaking walks straight to the goal
    for alpha in (0.25, 0.5, 1.0):
        res = search(occ, (2, 3), (45, 40), h_gain=alpha)
        assert res.expanded > 5 * base.expanded
        assert res.cost == pytest.approx(base.cost)  # still shortest on an empty map


def test_obstacle_term_keeps_raw_path_farther_from_obstacles():
    occ = np.zeros((30, 40), dtype=bool)
    occ[8:22, 18:22] = True  # a block in the middle, start and goal level with its top edge
    grid = OccupancyGrid(occ, 1.0)
    plain = plan(grid, (2.5, 21.5), (37.5, 21.5), AStarParams(inflate=0.0, shorten=False))
    improved = plan(grid, (2.5, 21.5), (37.5, 21.5),
                    ImprovedAStarParams(inflate=0.0, shorten=False, alpha=0.0, beta=4.0))
    mean_clr = [postprocess.path_clearance(grid, r.raw_path)[1].mean() for r in (plain, improved)]
    assert mean_clr[1] > mean_clr[0]
    assert improved.search.cost >= plain.search.cost


@pytest.mark.parametrize(("shape", "window"), [((23, 31), 1.5), ((40, 40), 4.7), ((6, 9), 15.0),
                                             ((12, 12), 0.5)])
def test_obstacle_term_is_the_brute_force_sum(shape, window):
    """Eq 13's sum from one FFT per map equals the sum over the window's cells, every cell."""
    occ = np.random.default_rng(len(shape) + int(10 * window)).random(shape) < 0.25
    rows, cols = np.nonzero(occ)
    want = np.zeros(shape)
    for r in range(shape[0]):
        for c in range(shape[1]):
            d = np.hypot(rows - r, cols - c)
            want[r, c] = np.sum(1.0 / d[(d > 0) & (d <= window)])
    np.testing.assert_allclose(obstacle_term(occ, window), want, rtol=1e-9, atol=1e-12)
    assert np.all((obstacle_term(occ, window) == 0) == (want == 0))


def test_improved_search_with_the_kept_field_is_the_same_search():
    occ = random_map(np.random.default_rng(7), (50, 60), 0.2, "blocks")
    occ[:2, :2] = occ[-2:, -2:] = False
    opts = {"h_gain": 0.5, "o_gain": 1.0, "window": 2.5}
    fresh = search(occ, (0, 0), (49, 59), **opts)
    kept = search(occ, (0, 0), (49, 59), obstacle_field=obstacle_term(occ, 2.5), **opts)
    assert fresh.found and fresh.expanded == kept.expanded and fresh.cost == kept.cost
    np.testing.assert_array_equal(fresh.cells, kept.cells)
    with pytest.raises(ValueError, match="obstacle_field has shape"):
        search(occ, (0, 0), (49, 59), obstacle_field=np.zeros((3, 3)), **opts)


def heapq_eq13(occ: np.ndarray, s: tuple[int, int], t: tuple[int, int], h_gain: float,
               o_gain: float, window: float) -> tuple[float, int, list[tuple[int, int]]]:
    """Independent plain-Python A* with eq 13's priority: a binary heapq, lazy deletion.

    f = g + h - h_gain h (R - r) / R + o_gain sum 1 / d_i (cells; octile h, Euclidean r,
    R = |start - goal|), popped by f - 1e-9 g, FIFO among equal keys. Returns
    ``(cost, expanded, path cells)``.
    """
    n_rows, n_cols = occ.shape
    obst = obstacle_term(occ, window)
    big_r = math.hypot(s[0] - t[0], s[1] - t[1])

    def priority(v: tuple[int, int], g: float) -> float:
        dr, dc = abs(v[0] - t[0]), abs(v[1] - t[1])
        h = max(dr, dc) + (SQRT2 - 1.0) * min(dr, dc)
        return g + h - h_gain * h * (big_r - math.hypot(dr, dc)) / big_r + o_gain * obst[v]

    g, parent, closed = {s: 0.0}, {s: s}, set()
    heap, count, expanded = [(priority(s, 0.0), 0, s)], 1, 0
    while heap:
        u = heapq.heappop(heap)[2]
        if u in closed:
            continue
        closed.add(u)
        expanded += 1
        if u == t:
            path = [u]
            while path[-1] != s:
                path.append(parent[path[-1]])
            return g[t], expanded, path[::-1]
        for dr, dc in ((1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (1, -1), (-1, 1), (-1, -1)):
            v = (u[0] + dr, u[1] + dc)
            if not (0 <= v[0] < n_rows and 0 <= v[1] < n_cols) or occ[v] or v in closed:
                continue
            if dr and dc and (occ[u[0] + dr, u[1]] or occ[u[0], u[1] + dc]):
                continue
            ng = g[u] + (SQRT2 if dr and dc else 1.0)
            if ng < g.get(v, math.inf):
                g[v], parent[v] = ng, u
                heapq.heappush(heap, (priority(v, ng) - 1e-9 * ng, count, v))
                count += 1
    return math.inf, expanded, []


@pytest.mark.parametrize(("h_gain", "o_gain", "window"), [(0.5, 1.0, 2.5), (0.0, 2.0, 1.5),
                                                          (1.0, 0.0, 0.0)])
def test_improved_search_expands_like_a_plain_heapq_eq13_search(h_gain, o_gain, window):
    """The kernel pops in eq 13's order: the same cost, nodes and path as an independent A*.

    Catches a successor kept out of the heap (the kernel's shortcut for the best
    new successor) when something in the heap has a smaller key. Without the
    obstacle term, exactly equal keys (mirror cells) may be popped in another
    order, so there only the cost and the node count are compared.
    """
    for seed in range(12):
        occ = random_map(np.random.default_rng(seed), (40, 50), 0.2,
                         "cells" if seed % 2 else "blocks")
        occ[:2, :2] = occ[-2:, -2:] = False
        cost, expanded, path = heapq_eq13(occ, (0, 0), (39, 49), h_gain, o_gain, window)
        got = search(occ, (0, 0), (39, 49), h_gain=h_gain, o_gain=o_gain, window=window)
        assert got.cost == pytest.approx(cost, abs=1e-9) and got.expanded == expanded, seed
        if o_gain > 0.0:
            np.testing.assert_array_equal(got.cells, np.array(path).reshape(-1, 2))


# ------------------------------------------------------------------ registration, options
def test_planners_registered_and_run_from_a_scenario():
    assert {"astar", "improved_astar"} <= set(planner_names())
    for name in ("astar", "improved_astar"):
        sc = scenario_from_dict(scenario_dict(planner=name, planner_options={"inflate": 0.4}))
        path = sc.leader_path
        np.testing.assert_array_equal(path[0], [2.0, 2.0])
        np.testing.assert_array_equal(path[-1], [17.0, 2.0])
        assert path[:, 1].max() > 7.0  # goes round the wall
        assert not sc.world.grid.is_occupied_at(postprocess.sample_path(path, 0.05)).any()


@pytest.mark.parametrize(("planner", "options", "key"), [
    ("astar", {"heuristic": "manhattan"}, "leader.planner_options.heuristic"),
    ("astar", {"inflate": -1.0}, "leader.planner_options.inflate"),
    ("astar", {"alpha": 0.5}, "leader.planner_options.alpha"),
    ("improved_astar", {"const1": 0.0}, "leader.planner_options.const1"),
    ("improved_astar", {"shorten": "yes"}, "leader.planner_options.shorten"),
])
def test_bad_planner_options_name_the_key(planner, options, key):
    with pytest.raises(ScenarioError, match=key.replace(".", r"\.")):
        scenario_from_dict(scenario_dict(planner=planner, planner_options=options), "s.toml")


# ------------------------------------------------------------------ comparison
def test_random_map_is_seeded_and_has_the_density():
    a = random_map(np.random.default_rng(1), (50, 60), 0.2, "blocks")
    b = random_map(np.random.default_rng(1), (50, 60), 0.2, "blocks")
    np.testing.assert_array_equal(a, b)
    assert a.shape == (50, 60) and 0.2 <= a.mean() < 0.3
    assert abs(random_map(np.random.default_rng(1), (100, 100), 0.2, "cells").mean() - 0.2) < 0.02
    with pytest.raises(ValueError):
        random_map(np.random.default_rng(1), (5, 5), 1.0)


def test_compare_planners_rows_and_markdown():
    tasks = random_tasks(np.random.default_rng(0), 3, (32, 32), 0.2)
    rows = compare_planners(tasks, default_planners(), repeats=2)
    assert len(rows) == 3 * len(default_planners())
    for r in rows:
        assert r["found"] and r["nodes"] > 0 and r["time_ms"] > 0 and r["length_m"] > 0
        assert r["length_m"] <= r["raw_length_m"] + 1e-9 and r["min_clearance_m"] >= 0
    text = comparison_markdown(rows)
    assert f"{PAPER_CLAIMS['time']:+.0%}" in text and f"{PAPER_CLAIMS['nodes']:+.0%}" in text
    assert "improved_astar" in text and "nodes expanded" in text


# ------------------------------------------------------------------ jump point search
def maze(rng: np.random.Generator, shape: tuple[int, int]) -> np.ndarray:
    """Corridors one cell wide (every other row free, random gaps in the walls between)."""
    occ = np.ones(shape, dtype=bool)
    occ[::2] = False
    occ[1::2] = rng.random((shape[0] // 2, shape[1])) > 0.3
    return occ


def test_jps_matches_astar_on_many_maps():
    """Same optimal cost as A* (checked against Dijkstra above) on open, cell, block and
    maze maps; the path is free, 8-connected, cuts no corner and sums to the cost."""
    rng = np.random.default_rng(21)
    for k in range(60):
        shape = tuple(int(v) for v in rng.integers(2, 40, 2))
        kind = k % 4
        if kind == 0:
            occ = np.zeros(shape, dtype=bool)
        elif kind == 3:
            occ = maze(rng, shape)
        else:
            occ = random_map(rng, shape, rng.uniform(0.05, 0.45), ("cells", "blocks")[kind - 1])
        if (~occ).sum() < 2:
            continue
        for _ in range(4):
            s, g = random_free_pair(rng, occ)
            ref = search(occ, s, g)
            res = search(occ, s, g, method="jps")
            assert res.found == ref.found
            if not ref.found:
                assert res.cells.shape == (0, 2) and math.isinf(res.cost)
                continue
            assert res.cost == pytest.approx(ref.cost, abs=1e-9)
            assert tuple(res.cells[0]) == s and tuple(res.cells[-1]) == g
            assert_valid_moves(occ, res.cells)
            assert len({tuple(c) for c in res.cells.tolist()}) == len(res.cells)
            assert postprocess.path_length(res.cells) == pytest.approx(res.cost, abs=1e-9)


def test_jps_expands_few_jump_points_on_open_maps():
    occ = np.zeros((48, 48), dtype=bool)
    res = search(occ, (2, 3), (45, 40), method="jps")
    assert res.cost == pytest.approx(search(occ, (2, 3), (45, 40)).cost)
    assert res.expanded <= 3  # the start, and the goal reached by one diagonal-first jump
    assert len(res.cells) == 44  # written out cell by cell
    occ[10:40, 20] = True  # a wall: a few more jump points, still optimal
    res = search(occ, (25, 2), (25, 45), method="jps")
    assert res.cost == pytest.approx(dijkstra_cost(occ, (25, 2), (25, 45)), abs=1e-9)
    assert res.expanded < search(occ, (25, 2), (25, 45)).expanded / 5


def test_jps_unreachable_blocked_outside_and_start_goal():
    occ = np.zeros((10, 10), dtype=bool)
    occ[:, 5] = True
    for s, g in (((2, 2), (2, 8)), ((0, 5), (2, 8)), ((2, 2), (2, 12)), ((-1, 0), (2, 2))):
        res = search(occ, s, g, method="jps")
        assert not res.found and res.cells.shape == (0, 2) and math.isinf(res.cost)
    res = search(occ, (4, 4), (4, 4), method="jps")
    assert res.found and res.cost == 0.0 and res.cells.tolist() == [[4, 4]]
    corner = np.zeros((3, 3), dtype=bool)
    corner[0, 1] = corner[1, 0] = True  # (0, 0) is shut in: no squeezing through the corner
    assert not search(corner, (0, 0), (2, 2), method="jps").found
    corner[1, 0] = False  # one side free: no corner cutting, so no diagonal out of (0, 0)
    res = search(corner, (0, 0), (2, 2), method="jps")
    assert res.cost == pytest.approx(2.0 + SQRT2) and res.cells[1].tolist() == [1, 0]


@pytest.mark.parametrize("options", [{"corner_cutting": True}, {"h_gain": 0.5},
                                     {"o_gain": 1.0, "window": 2.0}, {"goal_shortcut": True}])
def test_jps_refuses_what_it_is_not_optimal_for(options):
    occ = np.zeros((5, 5), dtype=bool)
    name = next(iter(options))
    with pytest.raises(ValueError, match=f"jps.*{name}"):
        search(occ, (0, 0), (4, 4), method="jps", **options)
    with pytest.raises(ValueError, match="method"):
        search(occ, (0, 0), (4, 4), method="theta")


@pytest.mark.parametrize(("planner", "options"), [
    ("astar", {"method": "jps", "corner_cutting": True}),
    ("improved_astar", {"method": "jps"}),  # eq 13 defaults: alpha 0.5, beta 1
    ("astar", {"method": "dijkstra"}),
])
def test_jps_bad_combinations_name_the_key(planner, options):
    with pytest.raises(ScenarioError, match=r"leader\.planner_options\.method"):
        scenario_from_dict(scenario_dict(planner=planner, planner_options=options), "s.toml")


def test_jps_runs_from_a_scenario_and_plans_like_astar():
    for planner, options in (("astar", {"method": "jps"}),
                             ("improved_astar", {"method": "jps", "alpha": 0.0, "beta": 0.0,
                                                 "goal_shortcut": False})):
        sc = scenario_from_dict(scenario_dict(planner=planner,
                                              planner_options={"inflate": 0.4, **options}))
        path = sc.leader_path
        np.testing.assert_array_equal(path[0], [2.0, 2.0])
        np.testing.assert_array_equal(path[-1], [17.0, 2.0])
        assert not sc.world.grid.is_occupied_at(postprocess.sample_path(path, 0.05)).any()
    task = random_tasks(np.random.default_rng(2), 1, (40, 40), 0.2)[0]
    a = plan(task.grid, task.start, task.goal, AStarParams(inflate=0.0))
    j = plan(task.grid, task.start, task.goal, AStarParams(inflate=0.0, method="jps"))
    assert j.search.cost == pytest.approx(a.search.cost, abs=1e-9)
    assert j.expanded < a.expanded


def test_default_improved_astar_is_the_full_reading_and_expands_fewer_nodes_on_dfcoa_maps():
    from dfcoa_opt.bench.recipes.astar import dfcoa_tasks

    assert ImprovedAStarParams().goal_shortcut  # the flowchart's node optimisation is on
    tasks, inflate = dfcoa_tasks(Path(__file__).resolve().parents[1] / "scenarios")
    for t in tasks:
        trad = plan(t.grid, t.start, t.goal, AStarParams(inflate=inflate)).expanded
        full = plan(t.grid, t.start, t.goal, ImprovedAStarParams(inflate=inflate)).expanded
        eq13 = plan(t.grid, t.start, t.goal,
                    ImprovedAStarParams(inflate=inflate, goal_shortcut=False)).expanded
        # eq 13 alone widens the search; with the node optimisation it ends early
        assert full < trad < eq13, (t.name, full, trad, eq13)
