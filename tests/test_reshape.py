"""The `reshape` controller: formation choice in a region, assignment, the doorway, policies."""

import itertools
from pathlib import Path

import numpy as np
import pytest

from comparisons.reshape import planner
from comparisons.reshape.controller import Reshape
from comparisons.reshape.region import Region, grow_region, shape_segments
from comparisons.reshape.tracking import FREED_MEMORY, Guidance, StuckMonitor
from dfcoa_opt.control.registry import make_controller
from dfcoa_opt.metrics.outcome import leader_path, stalled_steps
from dfcoa_opt.scenario.formation import line_offsets, v_offsets
from dfcoa_opt.scenario.loader import load_scenario
from dfcoa_opt.sim.simulator import Simulator
from dfcoa_opt.sim.stall import formation_progress
from dfcoa_opt.world.shapes import Circle, Rectangle

ROOT = Path(__file__).resolve().parents[1]
CORRIDOR = ROOT / "scenarios" / "bench" / "corridor.toml"


def _box_region(xmin, xmax, ymin, ymax):
    A = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
    b = np.array([xmax, -xmin, ymax, -ymin])
    return Region(A, b, np.eye(2) * 0.1, np.array([(xmin + xmax) / 2, (ymin + ymax) / 2]))


@pytest.mark.parametrize("seed", range(15))
def test_every_chosen_slot_lies_in_the_region_with_the_robot_radius(seed):
    rng = np.random.default_rng(seed)
    shapes = [Circle(tuple(rng.uniform([2, 2], [18, 10])), float(rng.uniform(0.3, 1.0)))
              for _ in range(8)]
    shapes.append(Rectangle((9.0, 0.0), (10.0, 4.0)))
    start = rng.uniform([2, 5], [4, 7])
    goal = start + np.array([4.0, 0.0])
    region = grow_region(np.array([start, start + [0.5, 0.0]]), shape_segments(shapes),
                         (0.0, 20.0, 0.0, 12.0))
    templates = {"v": v_offsets(5, 1.0, 0.6), "line": line_offsets(5, 0.8)}
    cand = planner.choose(region, templates, {"v": 0.0, "line": 1.0}, goal, 0.0,
                          np.linspace(-1.0, 1.0, 5), np.array([1.0, 0.75, 0.5]), 0.3, None,
                          planner.Weights())
    if cand is None:
        pytest.skip("nothing fits this region")
    slots = cand.slots(templates[cand.template])
    assert region.contains(slots, margin=0.3 - 1e-7).all()


def test_choice_prefers_the_scenario_shape_in_open_space_and_a_column_in_a_narrow_band():
    templates = {"scenario": v_offsets(5, 1.0, 0.6),
                 "column": np.column_stack([-1.0 * np.arange(5), np.zeros(5)])}
    cost = {"scenario": 0.0, "column": 1.0}
    rot, scales = np.linspace(-0.5, 0.5, 5), np.array([1.0, 0.75, 0.5])
    wide = planner.choose(_box_region(0, 20, 0, 14), templates, cost, np.array([10.0, 7.0]),
                          0.0, rot, scales, 0.3, None, planner.Weights())
    assert (wide.template, wide.scale, wide.theta) == ("scenario", 1.0, 0.0)
    np.testing.assert_allclose(wide.t, [10.0, 7.0])
    band = planner.choose(_box_region(0, 20, 6.3, 7.7), templates, cost, np.array([10.0, 7.0]),
                          0.0, rot, scales, 0.3, None, planner.Weights())
    assert band.template == "column"
    assert planner.choose(_box_region(0, 20, 6.9, 7.1), templates, cost,
                          np.array([10.0, 7.0]), 0.0, rot, scales, 0.3, None,
                          planner.Weights()) is None  # narrower than a robot


@pytest.mark.parametrize("n", [2, 3, 5, 7])
def test_assignment_is_optimal_against_brute_force(n):
    rng = np.random.default_rng(n)
    ctrl = Reshape(Reshape.Params())
    ctrl._n, ctrl._assign, ctrl._template = n, np.arange(n), None
    for _ in range(5):
        pos = rng.uniform(0, 5, (n, 2))
        slots = rng.uniform(0, 5, (n, 2))
        got = ctrl._assignment(pos, slots, "line")
        cost = np.sum((pos[:, None] - slots[None]) ** 2, axis=2)
        best = min(sum(cost[i, p[i]] for i in range(n))
                   for p in itertools.permutations(range(n)))
        assert sorted(got) == list(range(n))
        assert cost[np.arange(n), got].sum() == pytest.approx(best)
    # the scenario's own template keeps every robot on its own slot
    assert ctrl._assignment(pos, slots, "scenario").tolist() == list(range(n))


def test_assignment_hysteresis_keeps_a_nearly_as_good_assignment():
    ctrl = Reshape(Reshape.Params(hysteresis=0.5))
    pos = np.array([[0.0, 0.0], [1.0, 0.0]])
    slots = np.array([[0.4, 0.0], [0.6, 0.0]])
    ctrl._n, ctrl._template = 2, "line"
    ctrl._assign = np.array([1, 0])  # crossed: cost 0.72 against the optimum 0.32
    assert ctrl._assignment(pos, slots, "line").tolist() == [0, 1]  # more than 50 % worse
    ctrl._assign = np.array([1, 0])
    near = np.array([[0.49, 0.0], [0.51, 0.0]])  # crossed 0.5202 vs 0.4802: within 50 %
    assert ctrl._assignment(pos, near, "line").tolist() == [1, 0]


def _run(path, seed=3, overrides=None, **params):
    sc = load_scenario(path, seed, overrides)
    ctrl = make_controller("reshape", params)
    return Simulator(sc, ctrl).run(), ctrl, sc


def test_corridor_the_v_becomes_a_column_at_the_doorway_and_a_v_behind_it():
    log, ctrl, _ = _run(CORRIDOR)
    assert log.meta["reached_goal"]
    assert int(np.sum(log.robot_contacts + log.obstacle_contacts)) == 0  # a success
    phases = [k for k, _ in itertools.groupby(h[1] for h in ctrl.history)]
    assert phases[0] == "scenario" and phases[-1] == "scenario" and "column" in phases
    first_col = next(h[0] for h in ctrl.history if h[1] == "column")
    back = next(h[0] for h in ctrl.history if h[0] > first_col and h[1] == "scenario"
                and h[2] == 1.0)
    x = log.pose[:, :, 0]
    # the apex may enter the 1.4 m doorway in the V; two robots at once only in single file
    inside = np.flatnonzero(((x >= 10.0) & (x <= 11.5)).sum(axis=1) >= 2)
    assert first_col < log.t[inside[0]] < back  # a column before the doorway, a V after
    assert log.meta["controller_counters"]["switches"] >= 2
    # the column does not get ahead of the leader's formation and stand waiting for it:
    # the centroid's progress stays behind that of the leader's slots' centre, and no
    # 10 s window is stalled (so stop_on_deadlock, as in the ladders, would not end it)
    path = leader_path(log)
    centroid = formation_progress(log.pose[..., :2], path)
    nominal = formation_progress(log.slots, path)
    assert np.max(centroid - nominal) < 0.3
    assert not stalled_steps(log, load_scenario(CORRIDOR).spec.metrics).any()


def test_when_only_the_v_may_pass_the_look_ahead_shrinks_and_the_team_stops_counted():
    log, ctrl, _ = _run(CORRIDOR, templates=("scenario",), s_min=1.0, scales=1)
    c = log.meta["controller_counters"]
    assert c["shrinks"] > 0 and not log.meta["reached_goal"]
    assert int(np.sum(log.obstacle_contacts)) == 0  # stopped, not pushing into the wall
    assert log.pose[:, :, 0].max() < 11.5  # nobody through the doorway


def test_when_nothing_fits_the_formation_waits_counted():
    log, ctrl, _ = _run(CORRIDOR, overrides={"t_max": 5.0}, margin=7.0)
    c = log.meta["controller_counters"]
    assert c["waits"] == c["replans"] > 0 and c["shrinks"] == 3 * c["waits"]
    assert all(h[1] is None for h in ctrl.history)
    moved = np.hypot(*(log.pose[-1, :, :2] - log.pose[0, :, :2]).T)
    assert moved.max() < 0.3  # it holds where it is


def test_same_seed_same_run():
    a, _, _ = _run(CORRIDOR, seed=5, overrides={"t_max": 20.0})
    b, _, _ = _run(CORRIDOR, seed=5, overrides={"t_max": 20.0})
    assert a.digest() == b.digest()
    assert np.isfinite(a.pose).all()


def test_a_robot_held_still_away_from_its_target_is_turned():
    monitor = StuckMonitor(np.zeros((2, 2)), after=3.0, angle=np.pi / 2)
    ids = np.arange(2)
    target = np.array([[5.0, 0.0], [0.05, 0.0]])  # robot 1 is at its target
    u = np.array([[0.5, 0.0], [0.5, 0.0]])
    pos = np.array([[0.05, 0.0], [0.0, 0.05]])  # both within 0.1 m of their anchors
    out, n = monitor.turn(2.9, ids, pos, target, u)
    np.testing.assert_array_equal(out, u)
    assert n == 0
    out, n = monitor.turn(3.0, ids, pos, target, u)
    np.testing.assert_allclose(out, [[0.0, 0.5], [0.5, 0.0]], atol=1e-12)  # turned CCW
    assert n == 1
    out, n = monitor.turn(6.0, ids, pos, target, u)  # still after two periods: turned twice
    np.testing.assert_allclose(out, [[-0.5, 0.0], [0.5, 0.0]], atol=1e-12)
    assert monitor.stuck(6.0).tolist() == [0, 1]  # both still; robot 1 is not turned (at target)
    moved = np.array([[0.5, 0.0], [0.0, 0.05]])  # robot 0 moved: a new anchor, not stuck
    out, n = monitor.turn(6.1, ids, moved, target, u)
    np.testing.assert_array_equal(out, u)
    assert n == 0 and monitor.since[0] == 6.1 and monitor.anchor[0].tolist() == [0.5, 0.0]
    assert monitor.stuck(6.1).tolist() == [1]
    assert monitor.freed(6.1).tolist() == [0]  # it got moving from being stuck
    assert monitor.freed(6.1 + FREED_MEMORY).tolist() == []


def test_a_stuck_robot_plans_around_the_robots_settled_in_its_way():
    from dfcoa_opt.world.grid import OccupancyGrid
    guide = Guidance(OccupancyGrid.empty((10.0, 10.0), 10.0), 0.3)
    # robot 0 must pass robot 1, which sits on the straight line to its target
    pos = np.array([[2.0, 5.0], [3.0, 5.0]])
    targets = np.array([[4.0, 5.0], [3.0, 5.0]])
    assert guide.waypoints(pos, targets) == {}  # no static obstacle: no waypoint
    wp = guide.waypoints(pos, targets, np.array([0]), keep=0.65)
    assert set(wp) == {0}
    assert abs(wp[0][1] - 5.0) > 0.2  # off the line, around robot 1
    assert np.hypot(*(wp[0] - pos[1])) >= 0.65  # outside what the filter keeps
    # freed (stuck until lately): it keeps the path while its line passes robot 1 ...
    assert set(guide.waypoints(pos, targets, np.array([], int), 0.65, np.array([0]))) == {0}
    # ... and drops it once the line is clear of the others by keep
    clear = np.array([[2.0, 5.0], [3.0, 6.0]])
    assert guide.waypoints(clear, targets, np.array([], int), 0.65, np.array([0])) == {}


def test_a_stuck_robot_in_a_pocket_backs_out_rather_than_squeeze_through_a_narrow_gap():
    from dfcoa_opt.world.grid import OccupancyGrid
    guide = Guidance(OccupancyGrid.empty((10.0, 10.0), 10.0), 0.3)
    # robot 0 inside a V (robots 1-4 settled), its slot at the apex beyond the 1.12 m gap
    # between robots 1 and 2; it is nearer them than keep, so its own cell is blocked
    pos = np.array([[5.0, 5.0], [5.3, 5.56], [5.3, 4.44], [4.5, 6.1], [4.5, 3.9]])
    targets = pos.copy()
    targets[0] = [6.2, 5.0]
    wp = guide.waypoints(pos, targets, np.array([0]), keep=0.75)
    assert wp[0][0] < pos[0, 0]  # backs out of the V's open side
    # a keep below half the gap would send it through the gap
    assert guide.waypoints(pos, targets, np.array([0]), keep=0.4)[0][0] > pos[0, 0]


def test_guidance_heads_for_the_farthest_visible_point_of_the_path_around_a_wall():
    from dfcoa_opt.world.grid import OccupancyGrid
    grid = OccupancyGrid.from_shapes((10.0, 10.0), 10.0, [Rectangle((4.0, 0.0), (5.0, 7.0))])
    guide = Guidance(grid, 0.3)
    pos, target = np.array([[3.0, 3.0], [3.0, 8.5]]), np.array([[7.0, 3.0], [7.0, 8.5]])
    wp = guide.waypoints(pos, target)
    assert set(wp) == {0}  # robot 1's line passes above the wall
    assert guide.free(pos[0], wp[0], 0.3)  # visible from the robot
    assert np.hypot(*(wp[0] - pos[0])) > 1.0  # not the next cell: as far as it sees
    path = guide.path(pos[0], target[0])
    assert path is not None and path[:, 1].max() > 7.0  # the path goes over the wall
    assert guide.path(pos[0], np.array([4.5, 3.0])) is None  # a goal in the wall


def test_free_segment_answer_does_not_depend_on_the_clearance_cap():
    """``Guidance.free`` caps the exact distances at the clearance it tests (speed); the
    answer must equal the uncapped test on segments that pass near and far from walls."""
    from dfcoa_opt.world.grid import OccupancyGrid
    grid = OccupancyGrid.from_shapes((20.0, 20.0), 10.0, [Rectangle((4.0, 0.0), (5.0, 7.0)),
                                                         Circle((12.0, 12.0), 1.0)])
    guide = Guidance(grid, 0.3)
    rng = np.random.default_rng(4)
    answers = []
    for _ in range(300):
        a, b = rng.uniform(0.0, 20.0, (2, 2))
        c = float(rng.uniform(0.05, 2.0))
        steps = max(2, int(np.ceil(np.hypot(*(b - a)) / 0.1)) + 1)
        pts = a + np.linspace(0.0, 1.0, steps)[:, None] * (b - a)
        expected = bool(np.all(grid.clearance(pts) >= c))  # default 10 m cap
        assert guide.free(a, b, c) == expected
        answers.append(expected)
    assert 30 < sum(answers) < 270  # both answers occur


def test_free_probes_only_the_part_of_a_segment_near_the_map():
    """An estimate far off the map (huge pose noise) made free_many probe every 0.1 m of
    the way: 1e9 m took gigabytes. Beyond the map by more than the clearance nothing is
    occupied, so only the part of a segment within that margin is probed."""
    from dfcoa_opt.world.grid import OccupancyGrid
    grid = OccupancyGrid.from_shapes((20.0, 20.0), 10.0, [Rectangle((4.0, 0.0), (5.0, 7.0))])
    guide = Guidance(grid, 0.3)
    far = 1e9
    a = np.array([[2.0, 3.0], [2.0, 12.0], [-far, -far], [-far, 3.0]])
    b = np.array([[far, 3.0], [far, 12.0], [-far, far], [far, 3.0]])
    # through the wall; above it; never near the map; across the map through the wall
    assert guide.free_many(a, b, 0.3).tolist() == [False, True, True, False]
    # the answer of a segment inside the map is the probe test's, as before
    np.testing.assert_array_equal(guide.free_many(a[:2] * [1, 1], np.array([[7.0, 3.0],
                                                                          [7.0, 12.0]]), 0.3),
                                  [False, True])
