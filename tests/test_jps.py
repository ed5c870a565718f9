"""Jump point search (``method="jps"``): the same optimal costs as A*, few jump points,
what it refuses, and its use from a scenario."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dfcoa_opt.core.errors import ScenarioError
from dfcoa_opt.planning import postprocess
from dfcoa_opt.planning.astar import AStarParams, plan, search
from dfcoa_opt.planning.improved_astar import random_map, random_tasks
from dfcoa_opt.scenario.loader import scenario_from_dict
from tests.astar_oracles import (
    SQRT2,
    assert_valid_moves,
    dijkstra_cost,
    maze,
    random_free_pair,
    scenario_dict,
)


def test_jps_matches_astar_on_many_maps():
    """Same optimal cost as A* (checked against Dijkstra in test_astar.py) on open, cell, block and
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
