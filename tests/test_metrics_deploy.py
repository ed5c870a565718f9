"""The deployability report (dfcoa_opt.metrics.deploy) on logs made by hand, and on a run."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

import dfcoa_opt as d
from dfcoa_opt.metrics.deploy import DEPLOY_KEYS, deployability
from dfcoa_opt.scenario.loader import load_scenario
from dfcoa_opt.scenario.schema import RobotSpec
from dfcoa_opt.world.robots.profiles import PROFILES, ROBOTARIUM
from tests.test_metrics import make_log

R, D = 0.05, 0.3


def robots(**kw):
    spec = RobotSpec(wheel_radius=R, track_width=D, v_max=0.5, w_max=1.5, **kw)
    return dataclasses.asdict(spec)


def log_with(command, kind="unicycle", pose=None, spec=None, **fields):
    command = np.asarray(command, dtype=float)
    n_t, n = command.shape[:2]
    if pose is None:
        pose = np.zeros((n_t, n, 3))
        pose[..., 0] = np.arange(n) * 3.0
    meta = {"command_kind": kind, "robots": spec or robots()}
    return make_log(pose=pose, meta=meta, command=command, **fields)


def test_unicycle_commands_give_the_wheel_speeds_of_eq_2():
    # two robots, three steps: (v, omega) asked
    cmd = [[[0.2, 0.0], [0.1, 1.0]], [[0.5, 0.0], [0.1, 1.0]], [[0.6, 0.0], [0.0, 0.0]]]
    out = deployability(log_with(cmd))
    # right wheel of robot 1: (0.1 + 0.15 * 1.0) / 0.05 = 5; robot 0 at 0.6 m/s: 12 rad/s
    assert out["wheel_speed_peak"] == pytest.approx(12.0)
    assert math.isnan(out["wheel_speed_ratio"])  # no wheel limit
    # rim speed jumps: robot 0 from 0.2 to 0.5 in 0.1 s = 3 m/s^2; robot 1 from 0.25 to 0: 2.5
    assert out["wheel_accel_peak"] == pytest.approx(3.0)
    # robot 0 asks 0.6 > v_max at the last step: 1 of 6 robot-steps
    assert out["saturated_pct"] == pytest.approx(100.0 / 6.0)


def test_a_wheel_limit_counts_saturation_and_the_ratio():
    cmd = [[[0.4, 0.0]], [[0.4, 1.0]]]  # the turn asks (0.4 + 0.15) / 0.05 = 11 rad/s
    out = deployability(log_with(cmd, spec=robots(wheel_speed_max=10.0)))
    assert out["wheel_speed_peak"] == pytest.approx(11.0)
    assert out["wheel_speed_ratio"] == pytest.approx(1.1)
    assert out["saturated_pct"] == pytest.approx(50.0)


def test_velocity_commands_go_through_the_near_identity_map():
    """Heading 0, velocity (vx, 0): the robot is asked v = vx, omega = 0."""
    cmd = [[[0.3, 0.0]], [[0.3, 0.0]]]
    out = deployability(log_with(cmd, kind="velocity"))
    assert out["wheel_speed_peak"] == pytest.approx(0.3 / R)
    assert out["wheel_accel_peak"] == pytest.approx(0.3 / 0.1)


def test_body_gap_and_holonomic_robots():
    cmd = np.zeros((3, 2, 2))
    log = log_with(cmd, spec=robots(model="single_integrator"),
                   min_inter_robot=np.array([1.0, 0.55, 0.7]))
    out = deployability(log)
    assert out["body_gap_min"] == pytest.approx(0.55 - 0.4)
    assert math.isnan(out["wheel_speed_peak"]) and math.isnan(out["saturated_pct"])
    assert out["robotarium_ok"] is None


def gritsbot_log(spread, gap, speed):
    spec = robots(profile="gritsbot")
    spec.update(PROFILES["gritsbot"]["robots"])
    pose = np.zeros((2, 2, 3))
    pose[:, 1, 0] = gap  # robot 1 on the x axis, both facing +x
    pose[1, 0, 1] = spread  # robot 0 moves up by `spread`
    cmd = np.full((2, 2, 2), 0.0)
    cmd[..., 0] = speed
    return log_with(cmd, pose=pose, spec=spec)


def test_robotarium_checks_of_a_gritsbot_run():
    ok = deployability(gritsbot_log(spread=1.0, gap=0.3, speed=0.1))
    assert ok["robotarium_arena"] and ok["robotarium_collision"] and ok["robotarium_speed"]
    assert ok["robotarium_ok"] is True
    tall = deployability(gritsbot_log(spread=2.5, gap=0.3, speed=0.1))
    assert tall["robotarium_arena"] is False and tall["robotarium_ok"] is False
    # side by side along x, both discs offset the same way: the gap is the centre distance
    close = deployability(gritsbot_log(spread=0.0, gap=ROBOTARIUM["collision_diameter"] - 1e-3,
                                       speed=0.1))
    assert close["robotarium_collision"] is False
    fast = deployability(gritsbot_log(spread=0.0, gap=0.3, speed=0.25))
    assert fast["robotarium_speed"] is False and fast["robotarium_arena"] is True


def test_every_key_in_a_run_summary():
    sc = load_scenario("scenarios/example_empty.toml", overrides={"t_max": 2.0})
    m = d.run(sc, "goto_slot", seed=0).metrics
    assert set(DEPLOY_KEYS) <= set(m)
    assert m["wheel_speed_peak"] > 0 and m["body_gap_min"] > 0


def test_the_acceleration_is_judged_against_the_robot_or_its_profile():
    cmd = [[[0.2, 0.0]], [[0.5, 0.0]]]  # rim from 0.2 to 0.5 m/s in 0.1 s: 3 m/s^2
    assert math.isnan(deployability(log_with(cmd))["wheel_accel_ratio"])
    own = deployability(log_with(cmd, spec=robots(dynamics="actuated", wheel_accel_max=2.0)))
    assert own["wheel_accel_ratio"] == pytest.approx(1.5)
    spec = robots(profile="turtlebot3_burger")  # kinematic: the profile's 2.5 m/s^2
    assert deployability(log_with(cmd, spec=spec))["wheel_accel_ratio"] == pytest.approx(1.2)
