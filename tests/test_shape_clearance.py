"""The numba clearance kernel against the numpy reference, bit for bit."""

from pathlib import Path

import numpy as np
import pytest

from dfcoa_opt.scenario.loader import load_scenario, scenario_from_dict

SCEN = Path(__file__).resolve().parents[1] / "scenarios"


@pytest.mark.parametrize("name", ["example_obstacles.toml", "dfcoa_s1.toml", "dfcoa_s2.toml",
                                  "bench/large_100.toml", "paper001/table1_crossing.toml"])
def test_kernel_matches_numpy_reference_bit_for_bit(name):
    world = load_scenario(SCEN / name).world
    lo, hi = world.grid.extent[0::2], world.grid.extent[1::2]
    rng = np.random.default_rng(11)
    pts = rng.uniform(lo, hi, size=(3000, 2))
    # points on vertices, on edges and at circle centres hit the ties of both paths
    extra = [v for poly in world.polygons for v in poly]
    extra += [0.5 * (poly[0] + poly[1]) for poly in world.polygons]
    extra += [c.center for c in world.circles]
    pts = np.vstack([pts, np.reshape(extra, (-1, 2))])
    for cap in (0.5, 10.0):
        fast, ref = world.clearance(pts, cap), world.clearance_reference(pts, cap)
        assert np.array_equal(fast, ref)
    assert np.any(fast == 0.0) and np.any((fast > 0.0) & (fast < 10.0))


def test_clutter_world_of_circles_and_nonconvex_polygon():
    sc = scenario_from_dict({
        "name": "t", "dt": 0.1, "t_max": 1.0,
        "world": {"size": [10.0, 10.0], "resolution": 10, "obstacles": [
            {"type": "polygon", "vertices": [[1, 1], [5, 1], [5, 5], [3, 2], [1, 5]]},
            {"type": "circle", "center": [7.0, 7.0], "radius": 1.0},
            {"type": "circle", "center": [7.5, 2.0], "radius": 0.5}]},
        "team": {"n": 1}, "formation": {"shape": "line", "spacing": 1.0},
        "leader": {"start": [8.5, 5.0], "goal": [9.0, 5.0], "planner": "straight"}})
    world = sc.world
    pts = np.random.default_rng(2).uniform(0.0, 10.0, size=(5000, 2))
    assert np.array_equal(world.clearance(pts), world.clearance_reference(pts))
    # the notch of the non-convex polygon is free, its arms are not
    assert world.clearance(np.array([[3.0, 4.0]]))[0] > 0.0
    assert world.clearance(np.array([[1.5, 4.0], [7.0, 7.5]])).tolist() == [0.0, 0.0]


def test_stacked_worlds_measure_each_point_in_its_own_world_bit_for_bit():
    from dfcoa_opt.scenario.scenario import World
    from dfcoa_opt.world.shape_clearance import shape_clearance_worlds

    names = ["dfcoa_s1.toml", "bench/clutter.toml", "example_empty.toml", "dfcoa_s2.toml"]
    worlds = [load_scenario(SCEN / name, seed=3).world for name in names]
    rng = np.random.default_rng(5)
    pts = rng.uniform(0.0, 30.0, size=(4000, 2))
    which = rng.integers(0, len(worlds), len(pts))
    got = shape_clearance_worlds(pts, which, *World.stacked_shapes(worlds), 10.0)
    for w, world in enumerate(worlds):
        assert np.array_equal(got[which == w], world.clearance(pts[which == w], 10.0))
    # one world per point matters: the first world's answer differs for the others' points
    assert not np.array_equal(got, worlds[0].clearance(pts, 10.0))


def test_a_world_with_a_map_raster_is_not_stacked():
    from dfcoa_opt.scenario.scenario import World

    base = {"name": "t", "dt": 0.1, "t_max": 1.0, "team": {"n": 1},
            "formation": {"shape": "line", "spacing": 1.0},
            "leader": {"start": [1.5, 1.5], "goal": [2.5, 1.5], "planner": "straight"}}
    mapped = scenario_from_dict({**base, "world": {
        "map_ascii": "....\n.#..\n....\n....", "resolution": 1}}).world
    plain = scenario_from_dict({**base, "world": {"size": [4.0, 4.0], "resolution": 1}}).world
    assert mapped.raster is not None
    assert World.stacked_shapes([plain, plain]) is not None
    assert World.stacked_shapes([plain, mapped]) is None
