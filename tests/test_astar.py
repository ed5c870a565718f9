"""A* planners: MovingAI and Dijkstra oracles, move rules, post-processing, registration.

Eq 13 (improved A*) is in ``test_astar_improved.py``, jump point search in ``test_jps.py``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from dfcoa_opt.core.errors import ScenarioError
from dfcoa_opt.planning import postprocess
from dfcoa_opt.planning.astar import AStarParams, plan, search
from dfcoa_opt.planning.improved_astar import (
    PAPER_CLAIMS,
    ImprovedAStarParams,
    compare_planners,
    comparison_markdown,
    default_planners,
    random_map,
    random_tasks,
)
from dfcoa_opt.planning.registry import get_planner, planner_names
from dfcoa_opt.scenario.loader import scenario_from_dict
from dfcoa_opt.world.grid import OccupancyGrid
from tests.astar_oracles import (
    MOVINGAI,
    SQRT2,
    assert_valid_moves,
    dijkstra_cost,
    load_movingai_map,
    movingai_problems,
    random_free_pair,
    sampled_segment_free,
    scenario_dict,
)


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
