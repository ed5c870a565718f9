"""`reshape_passage`: the coordination layer (deadlock test, queues, recovery, yielding)."""

from pathlib import Path

import numpy as np
import pytest

import dfcoa_opt as d
from comparisons.reshape.controller import Reshape
from comparisons.reshape.coordination import Coordination
from comparisons.reshape.params import ReshapeParams
from comparisons.reshape.passage import Passage, PassageParams
from comparisons.reshape.progress import MOVING, STUCK, WAITING, ProgressMonitor
from comparisons.reshape.routes import Route
from comparisons.reshape.tracking import Guidance
from dfcoa_opt.control.base import MovingObstacles, Observation
from dfcoa_opt.world.grid import OccupancyGrid
from dfcoa_opt.world.shapes import Rectangle

ROOT = Path(__file__).resolve().parents[1]
HELDOUT = ROOT / "scenarios" / "heldout"
#: hand-made worlds of the passage tests (their headers draw them)
WORLDS = ROOT / "tests" / "data" / "passage"
#: the held-out settings under which every method is judged (scenarios/sweeps/heldout.toml)
JUDGED = {"stop_on_collision": True, "stop_on_deadlock": True, "controllers.cbf.solver": "exact"}


def _feed(monitor, frames, dt=0.5, moving_near=False):
    """Feed ``(progress, positions)`` frames every ``dt`` s; the last classification."""
    state = None
    for k, (progress, positions) in enumerate(frames):
        state = monitor.update(k * dt, progress, np.asarray(positions, float), moving_near)
    return state


def _doorway_queue(steps):
    """Five robots queued at a doorway at x = 0: the head files through, the rest stand."""
    team = np.array([[-0.5, 0.0], [-1.5, 0.0], [-2.5, 0.0], [-3.5, 0.0], [-4.5, 0.0]])
    frames = []
    for k in range(steps):
        p = team.copy()
        p[0, 0] += 0.08 * k  # 0.16 m/s through the doorway
        frames.append((10.0 + 0.01 * k / steps, p))  # the centroid's progress barely moves
    return frames


def test_a_team_queued_at_a_doorway_is_waiting_not_stuck():
    monitor = ProgressMonitor(window=4.0, advance=0.1, displacement=0.1)
    assert _feed(monitor, _doorway_queue(12)) == WAITING


def test_a_team_pinned_in_a_dead_end_is_stuck():
    rng = np.random.default_rng(0)
    team = rng.uniform(0.0, 2.0, (5, 2))
    frames = [(7.0 + 0.001 * k, team + rng.normal(0.0, 0.005, team.shape)) for k in range(12)]
    monitor = ProgressMonitor(window=4.0, advance=0.1, displacement=0.1)
    assert _feed(monitor, frames) == STUCK
    # the same stillness with a walker near the team: the team lets it by
    assert _feed(ProgressMonitor(4.0, 0.1, 0.1), frames, moving_near=True) == WAITING


def test_progress_is_moving_and_a_short_history_is_not_judged():
    team = np.zeros((3, 2))
    monitor = ProgressMonitor(window=4.0, advance=0.1, displacement=0.1)
    assert _feed(monitor, [(0.05 * k, team) for k in range(12)]) == MOVING  # 0.55 m in 5.5 s
    short = ProgressMonitor(window=4.0, advance=0.1, displacement=0.1)
    assert _feed(short, [(0.0, team)] * 8) == MOVING  # 3.5 s of history: not yet judged
    assert short.update(4.0, 0.0, team) == STUCK
    short.clear()
    assert short.update(4.5, 0.0, team) == MOVING


def test_the_window_slides():
    """Motion older than the window does not count: 4 s of stillness after a move is stuck."""
    team = np.zeros((2, 2))
    monitor = ProgressMonitor(window=4.0, advance=0.1, displacement=0.1)
    frames = [(0.0, team + [[k * 0.5, 0.0]]) for k in range(4)]  # robots move 1.5 m
    frames += [(0.0, team + [[1.5, 0.0]])] * 9  # then stand 4.5 s
    assert _feed(monitor, frames) == STUCK


def test_the_column_is_led_by_its_front_robot():
    """The front robot's projection on the route, among the robots near it."""
    xs = np.linspace(0.0, 10.0, 101)  # a route is a polyline of cell centres
    way = Route(np.column_stack([xs, np.zeros_like(xs)]), xs)
    pos = np.array([[1.0, 0.2], [3.0, -0.3], [8.0, 5.0]])  # the third is off the route
    assert way.front(pos, 1.0, -1.0) == pytest.approx(3.0)
    assert way.front(pos[2:], 1.0, -1.0) == -1.0


def test_passage_is_reshape_with_the_layer_on():
    p = PassageParams()
    assert p.coordinate and p.yield_time == 1.0
    assert Passage.Params is PassageParams


def test_yielding_grows_each_sensed_disc_by_its_speed():
    ctrl = Passage(PassageParams(yield_time=1.5))
    mv = MovingObstacles(np.zeros((1, 2, 2)), np.array([[[0.3, 0.4], [0.0, 0.0]]]),
                         np.array([[0.25, 0.0]]), np.array([[True, False]]))
    obs = Observation(0.0, 0.1, np.array([0]), np.zeros((1, 3)), np.zeros((1, 2)),
                      np.zeros((1, 2)), None, None, mv, np.zeros(5), np.zeros(2),
                      np.zeros((1, 2)), np.zeros((1, 2)))
    grown = ctrl._yielding(obs).obstacles
    assert grown.radius[0, 0] == pytest.approx(0.25 + 1.5 * 0.5)
    assert grown.radius[0, 1] == 0.0
    assert Passage(PassageParams(yield_time=0.0))._yielding(obs) is obs


def test_a_guidance_path_to_a_slot_by_a_wall_ends_at_the_nearest_free_cell():
    """A slot nearer a wall than the guidance clearance lies in a blocked cell of the
    inflated map: reshape's guidance finds no path to it, and a robot behind the wall heads
    straight at it (into the wall); passage's path ends at the nearest free cell."""
    grid = OccupancyGrid.from_shapes((10.0, 10.0), 10.0, [Rectangle((4.0, 0.0), (5.0, 7.0))])
    pos, slot = np.array([3.0, 3.0]), np.array([5.15, 3.0])  # 0.15 m off the wall's far side
    assert Guidance(grid, 0.3).path(pos, slot) is None
    assert Guidance(grid, 0.3).waypoints(pos[None], slot[None]) == {}
    guide = Guidance(grid, 0.3, goal_reach=0.6)
    path = guide.path(pos, slot)
    assert path is not None and path[:, 1].max() > 7.0  # over the wall
    end = guide.inflated.world_to_cell(path[-1])
    assert np.hypot(*(path[-1] - slot)) <= 0.6 and not guide.inflated.occupied[end]
    wp = guide.waypoints(pos[None], slot[None])
    assert set(wp) == {0} and wp[0][1] > pos[1]  # round the wall's top, not into it
    assert Guidance(grid, 0.3, goal_reach=0.6).path(pos, np.array([4.5, 3.0])) is None  # in it


def test_guidance_keeps_the_distance_the_filter_keeps_from_obstacles():
    """A unicycle's filter keeps its near-identity point r + offset + margin (0.35 m) from
    obstacles, more than the guidance's r + margin: reshape's guidance led robots into
    0.5 m gaps where the filter stops them. Passage's paths keep the filter's distance."""
    sc = d.load(HELDOUT / "cellular.toml", seed=1)
    rngs = [np.random.default_rng(0)]
    plain, passage = Reshape(ReshapeParams()), Passage(PassageParams())
    plain.reset_batch([sc], rngs)
    passage.reset_batch([sc], rngs)
    keep = passage.safety.obstacle_distance
    r, v = sc.spec.robots.radius, sc.spec.robots
    assert keep == pytest.approx(r + v.nid_distance + 0.05)  # the filter's default margin
    assert passage.runs[0]._guide.clearance == pytest.approx(max(keep, r + PassageParams().margin))
    assert plain.runs[0]._guide.clearance == pytest.approx(r + ReshapeParams().margin)
    # a 0.6 m gap in a wall: open to a path at r + margin (margin 0.05 m), closed at the
    # filter's distance, which a robot in it could not keep
    grid = OccupancyGrid.from_shapes((10.0, 10.0), 10.0, [Rectangle((4.0, 0.0), (5.0, 4.7)),
                                                         Rectangle((4.0, 5.3), (5.0, 10.0))])
    a, b = np.array([2.0, 5.0]), np.array([8.0, 5.0])
    assert Guidance(grid, r + 0.05).path(a, b) is not None
    assert Guidance(grid, keep).path(a, b) is None


def test_guidance_measures_its_clearance_on_the_shapes_the_filter_keeps_off():
    """The grid marks a cell occupied when its centre lies in a disc, so a disc's edge lies
    up to a cell beyond its outermost occupied centre, and an inflation from the cell
    centres leaves free cells 0.28 m from a disc at a 0.35 m clearance: a gap closed to the
    filter stays open to the path (a robot of clutter seed 10 stood in one). Passage's map
    measures the distance to the shapes themselves: every free cell keeps the clearance
    less half a cell, as the grid's inflation does along walls on cell edges."""
    from dfcoa_opt.scenario.loader import scenario_from_dict

    a, r = 4.58, 0.3
    b = a + (2.0 * r + 0.55) / np.sqrt(2.0)  # a diagonal gap of 0.55 m between the discs
    data = {"dt": 0.1, "t_max": 1.0, "sensors": {"lidar": {"enabled": False}},
            "world": {"size": [10.0, 10.0], "resolution": 10, "obstacles": [
                {"type": "circle", "center": [a, a], "radius": r},
                {"type": "circle", "center": [b, b], "radius": r}]},
            "team": {"n": 4}, "leader": {"start": [2.0, 8.0], "goal": [3.0, 8.0]}}
    world = scenario_from_dict(data, "<gap>").world
    keep, half = 0.35, 0.5 * world.grid.cell_size
    centres = world.grid.cell_centers().reshape(-1, 2)

    def least(guide: Guidance) -> float:
        return float(world.clearance(centres[~guide.inflated.occupied.reshape(-1)]).min())

    assert least(Guidance(world.grid, keep)) < keep - half - 0.01  # the rasterised edge
    exact = Guidance(world.grid, keep, exact=lambda p: world.clearance(p, cap=keep))
    assert least(exact) >= keep - half


def test_a_team_with_less_way_left_than_its_leader_rejoins_its_slots():
    coord = Coordination(stuck_window=4.0, recover_time=10.0, far=3.0, extent=1.5)
    team = np.array([[0.0, 0.0], [1.0, 0.0]])
    for k in range(10):  # standing still: stuck, a recovery starts
        coord.watch(0.5 * k, 2.0, team, False)
    assert coord.recovering(4.5) and not coord.rejoining(4.5)
    coord.rejoin(5.0)  # the planner found its route shorter than the leader's path
    assert coord.rejoining(5.0) and coord.rejoining(14.9) and not coord.rejoining(15.0)
    assert not coord.recovering(5.0)  # it heads for its slots, not along its route


def _crossings(x, line):
    """Steps at which ``x`` ``(T,)`` crosses ``line`` eastward, and westward."""
    side = np.sign(x - line)
    step = np.flatnonzero(np.diff(side) != 0)
    return step[side[step + 1] > 0], step[side[step + 1] < 0]


def _free_run(run):
    """The run succeeded, without a contact of any kind."""
    m = run.metrics
    assert m["outcome"] == "success"
    assert m["collisions"] == 0 and m["robot_contact_steps"] == 0
    assert m["obstacle_contact_steps"] == 0


def test_two_robots_meeting_in_a_one_robot_passage_both_get_through_front_first():
    """Robot 0 follows the leader east into a 3 m one-robot passage; robot 1 came
    in from the east towards its slot behind robot 0. They stand nose to nose,
    the team is stuck, and the recovery's route orders the passage by where the
    robots stand along it: the robot ahead (robot 1) takes the front slot and
    leaves by the far end first; robot 0 follows it through. Both then take
    their own slots at the goal.
    """
    sc = d.load(WORLDS / "doorway_two_sides.toml", overrides=JUDGED)
    run = d.run(sc, "reshape_passage", seed=0)
    _free_run(run)
    assert run.metrics["ctl_recoveries"] >= 1
    x = np.asarray(run.log.pose)[:, :, 0]
    east0, _ = _crossings(x[:, 0], 8.5)  # the passage's far end
    east1, west1 = _crossings(x[:, 1], 8.5)
    assert len(west1) == 1 and len(east0) >= 1 and len(east1) >= 1  # robot 1 came in once
    assert east1[-1] < east0[0]  # the stated order: robot 1 out first, robot 0 after it
    deepest = float(x[:, 1].min())
    assert deepest < 7.5  # robot 1 was well inside: they met there


@pytest.mark.parametrize("outside", [False, True])
def test_a_dead_end_leads_to_backing_off_and_another_way(outside):
    """The leader's straight line runs into a pocket closed by a wall.

    From inside the pocket the team backs away from the goal out of its mouth
    (x < 5) and goes around it (more than 3 m off the line); from outside it
    goes around without entering, where ``reshape`` stands at the mouth.
    """
    ov = dict(JUDGED, **({"leader.start": [2.0, 5.0]} if outside else {}))
    sc = d.load(WORLDS / "dead_end.toml", overrides=ov)
    run = d.run(sc, "reshape_passage", seed=0)
    _free_run(run)
    centroid = np.asarray(run.log.pose)[:, :, :2].mean(axis=1)
    assert float(np.abs(centroid[:, 1] - 5.0).max()) > 3.0  # around the pocket
    if outside:
        assert d.run(sc, "reshape", seed=0).metrics["outcome"] == "deadlock"
        inside = (centroid[:, 0] > 5.0) & (centroid[:, 0] < 8.0) & \
            (np.abs(centroid[:, 1] - 5.0) < 2.5)
        assert not inside.any()  # never entered it
    else:
        assert centroid[0, 0] > 6.0 and float(centroid[:, 0].min()) < 5.0  # backed out


@pytest.mark.parametrize(("family", "seed"), [("rooms_10", 43), ("cellular", 38),
                                             ("corridors", 64), ("cellular", 270),
                                             ("cellular", 336)])
def test_passage_gets_through_where_reshape_deadlocks(family, seed):
    """Training worlds (no test seed) where reshape's planner freezes its own targets.

    rooms_10 43: a column placed around its centroid where the route bends
    back stands still (the front-led column goes on). cellular 38: a route
    whose points run ahead of the leader's path holds the team; the stuck team
    recovers. corridors 64: a route shorter than the leader's path brings the
    team to the goal's room ahead of its leader, where the leader cap held it
    off its slots; the team goes back to its slots. cellular 270: the recovery
    route passes south of the blobs while the leader goes north; with less way
    left than its leader the team stood still, and now rejoins its slots.
    cellular 336: guidance through a gap the filter keeps closed held a robot.
    """
    sc = d.load(HELDOUT / f"{family}.toml", seed=seed, overrides=JUDGED)
    assert d.run(sc, "reshape", seed=seed).metrics["outcome"] == "deadlock"
    run = d.run(sc, "reshape_passage", seed=seed)
    assert run.metrics["outcome"] == "success"


def test_a_batch_of_passage_runs_is_its_single_runs_with_recoveries():
    seeds = [13, 18, 38]
    sc = d.load(HELDOUT / "cellular.toml", seed=seeds[0], overrides=JUDGED)
    batch = d.run_batch(sc, "reshape_passage", seeds)
    alone = [d.run(sc, "reshape_passage", seed=s) for s in seeds]
    assert [r.log.digest() for r in batch] == [r.log.digest() for r in alone]
    assert [r.metrics.get("ctl_recoveries") for r in batch] == \
        [r.metrics.get("ctl_recoveries") for r in alone]
    assert sum(r.metrics.get("ctl_recoveries", 0) for r in alone) > 0  # the layer acted


def test_the_filter_gain_never_asks_for_more_braking_than_the_wheels_give(monkeypatch):
    """S1 with wheels that accelerate at most 0.5 m/s^2 (the acceleration ladder's rung).

    ``reshape_passage`` caps the barrier's gain at ``a / v_max`` (0.5 / 0.6 here):
    seed 0 succeeds without a contact. With the gain as tuned (5 /s) the barrier asks
    a robot to brake at 5 v, ten times what its wheels give, and it grazes a wall.
    ``reshape`` and unlimited wheels keep the gain.
    """
    ov = {**JUDGED, "robots.dynamics": "actuated", "robots.wheel_accel_max": 0.5}
    sc = d.load(ROOT / "scenarios" / "dfcoa_s1.toml", overrides=ov)
    robots = sc.spec.robots
    passage, reshape = Reshape(ReshapeParams(coordinate=True)), Reshape(ReshapeParams())
    assert passage.gamma_for(robots) == pytest.approx(0.5 / 0.6)
    assert reshape.gamma_for(robots) == reshape.p.gamma == passage.p.gamma
    free = d.load(ROOT / "scenarios" / "dfcoa_s1.toml").spec.robots
    assert passage.gamma_for(free) == passage.p.gamma
    run = d.run(sc, "reshape_passage", seed=0)
    assert run.metrics["outcome"] == "success" and run.metrics["collisions"] == 0
    monkeypatch.setattr(Reshape, "gamma_for", lambda self, robots: self.p.gamma)
    assert d.run(sc, "reshape_passage", seed=0).metrics["collisions"] > 0
