"""``nmpc``: distributed nonlinear MPC (casadi) tracking the formation slot."""

import importlib
import math
import re

import casadi as ca
import numpy as np
import pytest

import comparisons.nmpc.problem as nmpc_problem
from comparisons.constraints.distance import StaticObstacles
from comparisons.nmpc import Nmpc, goto_command
from comparisons.nmpc.geometry import (
    neighbour_predictions,
    obstacle_halfplanes,
    plan_positions,
    robot_halfplanes,
    slot_reference,
)
from comparisons.nmpc.problem import arc_step, rollout
from dfcoa_opt.control.base import STATUS_OK, STATUS_SOLVER_FAIL, MovingObstacles, slot_velocity
from dfcoa_opt.control.registry import available, build_controller
from dfcoa_opt.core.errors import ScenarioError
from dfcoa_opt.metrics import filter_counts
from dfcoa_opt.metrics.solver import solve_time_stats
from dfcoa_opt.scenario.formation import slot_positions
from dfcoa_opt.scenario.loader import load_scenario
from dfcoa_opt.sim.simulator import Simulator, run_scenario
from dfcoa_opt.world.robots.models import integrate_unicycle
from dfcoa_opt.world.shapes import Circle, Rectangle
from tests.helpers import neighbours_from_lists
from tests.nmpc_support import ROOT, R, break_every_solver, controller, observation, scenario


# ----------------------------------------------------------------- registry and parameters
def test_registered_with_a_unicycle_command():
    assert "nmpc" in available()
    assert Nmpc.command == "unicycle" and Nmpc.uses_scan is False
    p = Nmpc.Params()
    assert p.solver == "sqp" and p.on_failure == "shift" and p.horizon == 10


@pytest.mark.parametrize("key, value", [("horizon", 1), ("margin", -0.1), ("solver", "osqp"),
                                        ("on_failure", "brake"), ("max_iter", 0),
                                        ("step", 0.0), ("w_track", math.nan), ("horizn", 5)])
def test_bad_params_name_the_key(key, value):
    with pytest.raises(ScenarioError, match=rf"controllers\.nmpc\.{key}"):
        build_controller("nmpc", {"nmpc": {key: value}}, "x.toml")


def test_scenario_file_overrides_reach_the_controller():
    sc = load_scenario(ROOT / "scenarios/dfcoa_s1.toml",
                       overrides={"t_max": 0.1, "controllers.nmpc.horizon": 6})
    ctrl = build_controller("nmpc", sc.spec.controllers, sc.source)
    assert ctrl.p.horizon == 6


def test_old_name_of_solve_time_stats_warns_and_is_the_metrics_function():
    package = importlib.import_module("comparisons.nmpc")
    moved = "comparisons.nmpc.solve_time_stats moved to dfcoa_opt.metrics.solver.solve_time_stats"
    with pytest.warns(DeprecationWarning, match=re.escape(moved)):
        from comparisons.nmpc import solve_time_stats as old
    assert old is solve_time_stats
    with pytest.warns(DeprecationWarning, match="dfcoa_opt.metrics.solver"):
        assert package.solve_time_stats is solve_time_stats
    assert "solve_time_stats" not in package.__all__
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        package.nothing  # noqa: B018


# ----------------------------------------------------------------- model and references
def test_rollout_and_casadi_arc_match_the_simulator_model():
    rng = np.random.default_rng(3)
    pose = rng.uniform(-2, 2, (5, 3))
    u = np.column_stack((rng.uniform(-0.6, 0.6, 5), rng.uniform(-2, 2, 5)))
    u[0, 1] = 0.0  # straight line
    ours = rollout(pose, np.repeat(u[:, None], 3, axis=1), 0.1)
    ref = pose
    for k in range(3):
        ref = integrate_unicycle(ref, u[:, 0], u[:, 1], 0.1)
        np.testing.assert_allclose(ours[:, k + 1, :2], ref[:, :2], atol=1e-12)
        np.testing.assert_allclose(np.cos(ours[:, k + 1, 2]), np.cos(ref[:, 2]), atol=1e-12)
    x, v = ca.SX.sym("x", 3), ca.SX.sym("u", 2)
    f = ca.Function("f", [x, v], [arc_step(x, v, 0.1)])
    for i in range(5):
        np.testing.assert_allclose(np.asarray(f(pose[i], u[i])).ravel(), ours[i, 1], atol=1e-12)


def test_slot_reference_follows_the_leader_arc():
    leader = np.array([1.0, 2.0, 0.3, 0.4, 0.5])
    offsets = np.array([[1.0, 0.5], [-1.0, -0.5], [0.0, 0.0]])
    times = np.array([0.0, 0.5, 1.0])
    ref, heading, twist = slot_reference(leader, offsets, times)
    for k, t in enumerate(times):
        lp = integrate_unicycle(leader[:3], leader[3], leader[4], t) if t else leader[:3]
        lp = np.array([lp[0], lp[1], leader[2] + leader[4] * t])
        np.testing.assert_allclose(ref[:, k], slot_positions(lp, offsets), atol=1e-12)
        vel = slot_velocity(np.r_[lp, leader[3:]], ref[:, k])
        np.testing.assert_allclose(twist[:, k, 0], np.hypot(vel[:, 0], vel[:, 1]), atol=1e-12)
        np.testing.assert_allclose(heading[:, k], np.arctan2(vel[:, 1], vel[:, 0]), atol=1e-12)
    assert np.all(twist[..., 1] == leader[4])


# ----------------------------------------------------------------- constraint builders
def test_static_halfplanes_for_a_disc_and_a_rectangle():
    static = StaticObstacles.from_shapes([Circle((5.0, 5.0), 1.0),
                                          Rectangle((8.0, 4.0), (9.0, 6.0))])
    lin = np.array([[[3.0, 5.0], [7.2, 5.0], [20.0, 5.0]]])  # stage 0: disc, 1: rectangle, 2: far
    no_moving = MovingObstacles(np.zeros((1, 0, 2)), np.zeros((1, 0, 2)), np.zeros((1, 0)),
                                np.zeros((1, 0), bool))
    d = R + 0.1
    normal, offset = obstacle_halfplanes(lin, static, no_moving, 0.1, 2, d, reach=1.5)
    # disc: nearest point (4, 5), normal (-1, 0): -x >= -4 + d
    np.testing.assert_allclose(normal[0, 0, 0], [-1.0, 0.0])
    assert offset[0, 0, 0] == pytest.approx(-4.0 + d)
    # rectangle edge x = 8 (0.8 m): normal (-1, 0); the disc (1.2 m) is the second row
    np.testing.assert_allclose(normal[0, 1, 0], [-1.0, 0.0])
    assert offset[0, 1, 0] == pytest.approx(-8.0 + d)
    np.testing.assert_allclose(normal[0, 1, 1], [1.0, 0.0])
    assert offset[0, 1, 1] == pytest.approx(6.0 + d)
    assert np.all(offset[0, 0, 1:] == -np.inf)  # the rectangle is 4 m from (3, 5): out of reach
    assert np.all(offset[0, 2] == -np.inf)
    # every point of both shapes violates its own half-plane (it contains the obstacle)
    for pt, row in (((5.0, 5.9), 0), ((8.5, 4.0), 1)):
        assert normal[0, row, 0] @ np.array(pt) < offset[0, row, 0]


def test_moving_disc_is_predicted_at_constant_velocity():
    static = StaticObstacles.from_shapes([])
    h = 4
    lin = np.tile([[-1.0, 0.0]], (1, h, 1))
    moving = MovingObstacles(np.array([[[2.0, 0.0]]]), np.array([[[-1.0, 0.0]]]),
                             np.array([[0.3]]), np.array([[True]]))
    normal, offset = obstacle_halfplanes(lin, static, moving, 0.5, 1, 0.3, reach=10.0)
    for k in range(h):  # centre at 2 - 0.5 (k + 1): boundary 0.3 nearer, normal (-1, 0)
        centre = 2.0 - 0.5 * (k + 1)
        np.testing.assert_allclose(normal[0, k, 0], [-1.0, 0.0])
        assert offset[0, k, 0] == pytest.approx(-(centre - 0.3) + 0.3)


def test_neighbour_plans_are_followed_and_translated_else_constant_velocity():
    h, tau = 3, 0.1
    plans = np.zeros((3, h + 1, 2))
    plans[1] = [[0.0, 0.0], [0.1, 0.0], [0.2, 0.0], [0.3, 0.0]]  # robot 1 moves +x 1 m/s
    age = np.array([np.inf, 1.0, np.inf])  # robot 1's plan is one stage old, robot 2 has none
    nb = neighbours_from_lists([[5.0, 5.0], [1.0, 1.0], [2.0, 2.0]],
                               [[0.0, 0.0], [0.0, 0.0], [0.0, -1.0]], [[1, 2], [], []])
    pred, mask = neighbour_predictions(nb, 3, plans, age, tau, h)
    assert mask.tolist() == [[True, True, False], [False] * 3, [False] * 3]
    # robot 1: plan from stage 1 on, translated to its broadcast position (1, 1)
    np.testing.assert_allclose(pred[0, 0], [[1.1, 1.0], [1.2, 1.0], [1.3, 1.0]], atol=1e-12)
    # robot 2: no plan -> its broadcast velocity (0, -1)
    np.testing.assert_allclose(pred[0, 1], [[2.0, 1.9], [2.0, 1.8], [2.0, 1.7]], atol=1e-12)


def test_plan_positions_interpolate_and_extrapolate():
    plans = np.array([[[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]]])
    out = plan_positions(plans, np.array([1.5]), 2)
    np.testing.assert_allclose(out[0, :, 0], [1.5, 2.5, 3.5])


def test_robot_halfplanes_use_pair_geometry():
    lin = np.array([[[0.0, 0.0], [0.0, 0.0]]])
    pred = np.array([[[[1.0, 0.0], [0.0, 3.0]]]])  # one neighbour, at (1, 0) then (0, 3)
    normal, offset = robot_halfplanes(lin, pred, np.array([[True]]), 0.5, reach=2.0)
    np.testing.assert_allclose(normal[0, 0, 0], [-1.0, 0.0])
    assert offset[0, 0, 0] == pytest.approx(-1.0 + 0.5)  # x <= 0.5
    assert offset[0, 1, 0] == -np.inf  # 3 m away: out of reach


# ----------------------------------------------------------------- solver behaviour
@pytest.mark.parametrize("solver", ["sqp", "ipopt"])
def test_tracks_a_straight_moving_slot(solver):
    sc = scenario(poses=[(2.0, 4.0, 0.5)], offsets=[(0.0, 0.0)], t_max=8.0)
    log = Simulator(sc, controller(sc, solver=solver)).run()
    err = np.hypot(*(log.pose[:, 0, :2] - log.slots[:, 0]).T)
    assert err[0] > 0.9
    assert err[-20:].max() < 0.05
    assert np.all(log.filter_status == STATUS_OK)
    assert np.all(log.filter_time > 0.0)


def test_predicted_plan_respects_the_obstacle_halfplanes():
    wall = {"type": "rectangle", "min": [3.0, 4.0], "max": [3.5, 6.0]}
    sc = scenario(poses=[(2.0, 5.0, 0.0)], obstacles=[wall])
    ctrl = controller(sc, margin=0.1)
    d = R + 0.1
    pose = np.array([2.3, 5.0, 0.0])
    for k in range(3):  # the slot is beyond the wall
        obs = observation(pose, [[4.5, 5.0]], t=0.1 * k)
        u = ctrl.act(obs)[0]
        assert ctrl.last_result.status[0] == STATUS_OK
        plan = ctrl.plans._w["x"][0, 1:, :2]
        # the linearisation points: the shifted last plan (the current position at first)
        u0, age = ctrl.plans.shifted(obs.t, np.array([0]))
        lin = rollout(pose[None], u0, 0.1)[0, 1:, :2] if age[0] < 10 else \
            np.tile(pose[:2], (10, 1))
        assert (age[0] < 10) == (k > 0)
        normal, offset = obstacle_halfplanes(lin[None], ctrl.static, obs.obstacles, 0.1, 4, d, 1.5)
        slack = ctrl.last_result.slack[0]
        assert np.all(np.einsum("hmd,hd->hm", normal[0], plan) >= offset[0] - slack - 1e-6)
        assert ctrl.static.nearest(plan, 1, 10.0).delta.min() >= d - slack - 1e-6
        pose = integrate_unicycle(pose, u[0], u[1], 0.1)


def test_two_robots_crossing_keep_their_distance():
    # each robot starts on the other's slot: they must pass each other
    sc = scenario(n=2, poses=[(2.0, 6.0, -math.pi / 2), (2.0, 4.0, math.pi / 2)],
                  offsets=[(0.0, -1.0), (0.0, 1.0)], t_max=8.0)
    log = run_scenario(sc, "nmpc")
    assert log.min_inter_robot.min() >= 2 * R - 1e-6
    assert int(log.collision_events.sum()) == 0
    err = np.hypot(*(log.pose[-1, :, :2] - log.slots[-1]).T)
    assert err.max() < 0.3


def test_wheel_speed_limit_is_a_constraint():
    sc = scenario(poses=[(2.0, 3.0, 1.5)], t_max=2.0,
                  robots={"wheel_speed_max": 8.0, "wheel_radius": 0.05, "track_width": 0.3})
    log = run_scenario(sc, "nmpc")
    v, w = log.command[:, 0, 0], log.command[:, 0, 1]
    rim = 0.05 * 8.0
    assert np.all(np.abs(v + 0.15 * w) <= rim + 1e-4)
    assert np.all(np.abs(v - 0.15 * w) <= rim + 1e-4)


@pytest.mark.parametrize("solver", ["sqp", "ipopt"])
def test_warm_start_needs_fewer_iterations(solver):
    """Shifted plan + multipliers vs cold starts of the same problems: robots 1.5 rad off,
    the leader turning at 0.2 rad/s (interpreted: the compiled solver does not count)."""
    off = np.array([[0.5, 1.0], [0.5, 0.0], [0.5, -1.0]])
    pose = np.array([[2.0, 6.0, 1.5], [2.0, 5.0, 1.5], [2.0, 4.0, 1.5]])
    sc = scenario(n=3, poses=[tuple(p) for p in pose], offsets=[tuple(o) for o in off])
    ctrl = controller(sc, solver=solver, compiled=False)
    leader = np.array([2.0, 5.0, 0.0, 0.3, 0.2])
    lists = [[1], [0, 2], [1]]
    warm, cold = 0, 0
    for k in range(8):
        obs = observation(pose, slot_positions(leader[:3], off), t=0.1 * k, leader=leader,
                          lists=lists)
        if k:  # the same problems from a cold start: controls 0, no multipliers
            plans = ctrl.plans
            plans._r = {key: v.copy() for key, v in plans._w.items()}
            plans._t = obs.t
            u0, _ = plans.shifted(obs.t, np.arange(3))
            _, params, lbg = ctrl._problems(obs, u0, np.zeros(3, bool))
            zero = ctrl.problem.guesses(np.zeros((3, 10, 2)), np.repeat(pose[:, None], 10, 1))
            cold += sum(ctrl.problem.solve(zero[i], params[i], lbg[i]).iterations
                        for i in range(3))
        u = ctrl.act(obs)
        assert np.all(ctrl.last_result.status == STATUS_OK)
        if k:
            warm += int(ctrl.last_iterations.sum())
        pose = np.vstack([integrate_unicycle(pose[i], u[i, 0], u[i, 1], 0.1) for i in range(3)])
        leader[:3] = integrate_unicycle(leader[:3], leader[3], leader[4], 0.1)
    assert warm < 0.75 * cold


# ----------------------------------------------------------------- failures
@pytest.mark.parametrize("policy", ["shift", "stop", "goto"])
def test_forced_solver_failure_applies_the_policy_and_is_counted(monkeypatch, policy):
    sc = scenario(poses=[(2.0, 4.0, 0.0)], t_max=0.5)
    ctrl = controller(sc, on_failure=policy)
    leader = (2.0, 5.0, 0.0, 0.3, 0.0)
    obs0 = observation([2.0, 4.0, 0.0], [[2.0, 5.0]], t=0.0, leader=leader)
    ctrl.act(obs0)
    plan_u = ctrl.plans._w["u"][0].copy()
    obs1 = observation([2.02, 4.0, 0.05], [[2.03, 5.0]], t=0.1, leader=leader)
    break_every_solver(monkeypatch)
    u = ctrl.act(obs1)[0]
    assert ctrl.last_result.status.tolist() == [STATUS_SOLVER_FAIL]
    expected = {"shift": plan_u[1], "stop": np.zeros(2),
                "goto": goto_command(obs1.pose[0], obs1.slot[0], 1.0, ctrl.spec)}[policy]
    np.testing.assert_allclose(u, expected)
    # and through the simulator: every step counted in the log and the metrics
    log = Simulator(sc, controller(sc, on_failure=policy)).run()
    assert np.all(log.filter_status == STATUS_SOLVER_FAIL)
    assert filter_counts(log)["filter_solver_failures"] == log.filter_status.size
    assert solve_time_stats(log)["failures"] == log.filter_status.size


def test_shift_runs_out_after_the_horizon(monkeypatch):
    sc = scenario(poses=[(2.0, 4.0, 0.0)])
    ctrl = controller(sc, on_failure="shift", horizon=3)
    leader = (2.0, 5.0, 0.0, 0.3, 0.0)
    ctrl.act(observation([2.0, 4.0, 0.0], [[2.0, 5.0]], t=0.0, leader=leader))
    plan_u = ctrl.plans._w["u"][0].copy()
    break_every_solver(monkeypatch)
    got = [ctrl.act(observation([2.0, 4.0, 0.0], [[2.0, 5.0]], t=0.1 * k, leader=leader))[0]
           for k in range(1, 5)]
    np.testing.assert_allclose(got[:2], plan_u[1:3])
    np.testing.assert_allclose(got[2:], 0.0)


def test_sqp_failure_is_rescued_by_ipopt(monkeypatch):
    sc = scenario(poses=[(2.0, 4.0, 0.0)])
    ctrl = controller(sc)
    orig = nmpc_problem.NmpcProblem._unpack

    def sqp_fails(self, *args, **kwargs):
        out = orig(self, *args, **kwargs)
        if self.spec.solver == "sqp":
            out.success[:] = False
        return out

    monkeypatch.setattr(nmpc_problem.NmpcProblem, "_unpack", sqp_fails)
    ctrl.act(observation([2.0, 4.0, 0.0], [[2.0, 5.0]], leader=(2.0, 5.0, 0.0, 0.3, 0.0)))
    assert ctrl.last_result.status.tolist() == [STATUS_OK]
    assert ctrl.last_rescued.tolist() == [True]
    no_rescue = controller(sc, rescue=False)
    no_rescue.act(observation([2.0, 4.0, 0.0], [[2.0, 5.0]], leader=(2.0, 5.0, 0.0, 0.3, 0.0)))
    assert no_rescue.last_result.status.tolist() == [STATUS_SOLVER_FAIL]


# ----------------------------------------------------------------- distributedness
def _history(ctrl, pose, slots, lists, steps=2):
    leader = (3.0, 5.0, 0.0, 0.3, 0.0)  # run until every robot has a plan; the next obs
    for k in range(steps):
        ctrl.act(observation(pose, slots, t=0.1 * k, leader=leader, lists=lists))
    return observation(pose, slots, t=0.1 * steps, leader=leader, lists=lists)


def test_rows_depend_on_own_row_and_neighbours_plans_only():
    pose = np.array([[2.0, 5.0, 0.0], [2.6, 5.1, 0.0], [5.0, 5.0, math.pi], [5.5, 4.6, 1.0]])
    slots = np.array([[4.0, 5.0], [4.0, 6.0], [3.0, 5.0], [3.0, 4.0]])
    lists = [[1, 2], [0], [0, 3], [2]]
    sc = scenario(n=4, poses=[tuple(p) for p in pose], offsets=[(0.0, 0.0)] * 4)
    ctrl = controller(sc)
    obs = _history(ctrl, pose, slots, lists)
    full = ctrl.act(obs)
    for i in range(4):  # a row alone gives the same command (plans are from the last step)
        np.testing.assert_array_equal(ctrl.act(obs.take([i]))[0], full[i])
    # robot 3 is not robot 1's neighbour, nor robot 1 robot 3's: moving it leaves row 1 alone
    moved = observation(np.vstack((pose[:3], [[3.0, 4.7, 2.0]])), slots, t=obs.t,
                        leader=obs.leader, lists=lists)
    again = ctrl.act(moved)
    np.testing.assert_array_equal(again[1], full[1])
    assert not np.array_equal(again[3], full[3])
    # and the plan of a non-neighbour is never read: robot 3's plan now meets robot 2 (going
    # -x at 0.6 m/s) in 1 s (a constant offset would not do: plans are translated to the
    # broadcast position, and this plan is one stage old)
    ctrl.plans._r["x"][3, :, :2] = pose[3, :2] + (np.arange(11)[:, None] - 1) / 10 * (
        np.array([4.4, 5.0]) - pose[3, :2])
    np.testing.assert_array_equal(ctrl.act(obs)[1], full[1])
    assert not np.array_equal(ctrl.act(obs)[2], full[2])  # robot 2 reads robot 3's plan


# ----------------------------------------------------------------- end to end
def test_runs_end_to_end_on_dfcoa_s1():
    sc = load_scenario(ROOT / "scenarios/dfcoa_s1.toml", overrides={"t_max": 3.0})
    log = run_scenario(sc, "nmpc")
    assert log.meta["controller"] == "nmpc" and log.meta["steps"] == 31
    assert int(log.collision_events.sum()) == 0
    stats = solve_time_stats(log)
    assert stats["entries"] == 31 * 4 and 0.0 < stats["median"] <= stats["p95"] < 0.5
    assert stats["failures"] == int(np.count_nonzero(log.filter_status == STATUS_SOLVER_FAIL))
    counts = filter_counts(log)
    assert counts["filter_time_median"] == pytest.approx(stats["median"])
