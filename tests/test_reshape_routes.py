"""Formation routes of reshape: configuration space against shapely, routes, the large teams."""

import math
from pathlib import Path

import numpy as np
import pytest
import shapely
from shapely.geometry import Point

from comparisons.reshape.routes import ConfigurationSpace, bin_heading, heading_bin
from dfcoa_opt.scenario.formation import v_offsets
from dfcoa_opt.scenario.loader import load_scenario
from dfcoa_opt.sim.simulator import run_scenario
from dfcoa_opt.world.grid import OccupancyGrid
from dfcoa_opt.world.shapes import Circle, Rectangle

ROOT = Path(__file__).resolve().parents[1]
RES = 10.0
H = 1.0 / RES
RHO = 0.3


def _world(seed):
    rng = np.random.default_rng(seed)
    shapes = [Circle(tuple(rng.uniform([2, 2], [18, 10])), float(rng.uniform(0.3, 1.0)))
              for _ in range(6)]
    shapes.append(Rectangle((9.0, 0.0), (10.0, 4.0)))
    grid = OccupancyGrid.from_shapes((20.0, 12.0), RES, shapes)
    oracle = shapely.union_all([Point(s.center).buffer(s.radius, 256) if isinstance(s, Circle)
                                else shapely.box(*s.min, *s.max)
                                for s in shapes])
    return grid, oracle


def _slots(centre, offsets, scale, k):
    c, s = math.cos(bin_heading(k)), math.sin(bin_heading(k))
    return centre + scale * offsets @ np.array([[c, -s], [s, c]]).T


@pytest.mark.parametrize("seed", range(6))
def test_configuration_space_agrees_with_shapely_both_ways(seed):
    grid, oracle = _world(seed)
    offsets = v_offsets(5, 1.0, 0.6)
    offsets = offsets - offsets.mean(axis=0)
    cs = ConfigurationSpace(grid, offsets, RHO)
    rng = np.random.default_rng(100 + seed)
    for scale, k in [(1.0, 0), (0.7, 3), (0.85, 9)]:
        blocked = cs.blocked(scale, k)
        rows, cols = rng.integers(0, grid.shape[0], 400), rng.integers(0, grid.shape[1], 400)
        centres = grid.cell_centers()[rows, cols]
        for centre, hit in zip(centres, blocked[rows, cols], strict=True):
            slots = _slots(centre, offsets, scale, k)
            inside = bool(np.all((slots >= RHO) & (slots <= [20.0 - RHO, 12.0 - RHO])))
            gap = min(oracle.distance(Point(*p)) for p in slots)
            if not hit:  # free: every disc clear, up to the rasterisation (half a diagonal)
                assert gap >= RHO - H * math.sqrt(2) / 2 - 1e-9
                assert np.all((slots > -H) & (slots < [20.0 + H, 12.0 + H]))
            elif inside:  # blocked inside the map: some disc within a cell and a half more
                assert gap <= RHO + 1.5 * H * math.sqrt(2) + 1e-9


@pytest.mark.parametrize("seed", range(6))
def test_every_route_point_is_free_and_the_route_joins_start_to_goal(seed):
    grid, oracle = _world(seed)
    offsets = v_offsets(4, 0.8, 0.6)
    offsets = offsets - offsets.mean(axis=0)
    cs = ConfigurationSpace(grid, offsets, RHO)
    start, goal = np.array([2.5, 6.0]), np.array([17.5, 6.0])
    way = cs.route(start, goal, 0.8, 0)
    if way is None:
        pytest.skip("no passage in this world")
    assert cs.free_at(way.points, 0.8, 0).all()
    steps = np.hypot(*np.diff(way.points, axis=0).T)
    assert steps.max() <= H * math.sqrt(2) + 1e-9  # 8-connected, no jumps
    free = grid.cell_centers()[~cs.blocked(0.8, 0)]
    for end, want in ((way.points[0], start), (way.points[-1], goal)):
        # its own cell when the formation fits there, else the nearest cell where it does
        nearest = np.hypot(*(free - want).T).min()
        assert np.hypot(*(end - want)) <= max(nearest, H * math.sqrt(2) / 2) + 1e-9
    assert way.length == pytest.approx(steps.sum())
    np.testing.assert_allclose(way.point_at(way.length), way.points[-1])
    assert way.project(way.points[len(way.points) // 2]) == pytest.approx(
        way.arc[len(way.points) // 2])


def test_a_wall_with_a_gap_lets_a_single_robot_through_but_not_the_v():
    wall = [Rectangle((9.5, 0.0), (10.5, 5.3)), Rectangle((9.5, 6.7), (10.5, 12.0))]
    grid = OccupancyGrid.from_shapes((20.0, 12.0), RES, wall)
    one = ConfigurationSpace(grid, np.zeros((1, 2)), RHO)
    v = v_offsets(5, 1.0, 0.6)
    cs = ConfigurationSpace(grid, v - v.mean(axis=0), RHO)
    start, goal = np.array([3.0, 6.0]), np.array([17.0, 6.0])
    assert one.route(start, goal, 1.0, 0) is not None
    assert cs.route(start, goal, 1.0, 0) is None
    assert heading_bin(bin_heading(5) + 0.05) == 5 and heading_bin(-0.01) == 0


@pytest.mark.parametrize("name", ["large_20"])
def test_the_large_team_goes_around_the_circles_rigid_and_arrives(name):
    """Every other controller leaves a robot behind the central circle (issue 20)."""
    scenario = load_scenario(ROOT / "scenarios" / "bench" / f"{name}.toml", seed=1)
    log = run_scenario(scenario, "reshape", seed=1)
    assert log.meta["reached_goal"]
    assert int(np.sum(log.robot_contacts + log.obstacle_contacts)) == 0
    # around the obstacle field, not through it: the centroid leaves the leader's line
    assert np.abs(log.pose[:, :, 1].mean(axis=1) - 10.0).max() > 3.0
