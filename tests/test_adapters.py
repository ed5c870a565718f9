import numpy as np
import pytest

from dfcoa_opt.control.adapters import convert, velocity_to_unicycle
from dfcoa_opt.scenario.schema import RobotSpec
from dfcoa_opt.world.robots.models import DoubleIntegrator, RobotState, SingleIntegrator, Unicycle

POSE = np.array([[0.0, 0.0, 0.3], [1.0, 2.0, -2.0]])
VEL = np.array([[0.1, 0.0], [0.0, -0.2]])


def test_nid_point_moves_with_commanded_velocity():
    ell = 0.15
    vd = np.array([[0.3, 0.2], [-0.1, 0.25]])
    u = velocity_to_unicycle(vd, POSE[:, 2], ell)
    m = Unicycle(RobotSpec(v_max=10, w_max=10))
    dt = 1e-5
    s2 = m.step(RobotState.at_rest(POSE), u, dt)

    def point(p):
        return p[:, :2] + ell * np.stack((np.cos(p[:, 2]), np.sin(p[:, 2])), 1)

    assert np.allclose((point(s2.pose) - point(POSE)) / dt, vd, atol=1e-4)


def test_acceleration_to_velocity_integrates_one_step():
    a = np.array([[1.0, -1.0], [0.0, 2.0]])
    out = convert(a, "acceleration", "velocity", POSE, VEL, 0.1, 0.1)
    assert np.allclose(out, VEL + 0.1 * a)


def test_velocity_to_acceleration_is_deadbeat_on_double_integrator():
    vd = np.array([[0.2, 0.1], [0.0, 0.0]])
    acc = convert(vd, "velocity", "acceleration", POSE, VEL, 0.5, 0.1)
    s0 = RobotState(POSE, VEL, np.zeros((2, 2)))
    s2 = DoubleIntegrator(RobotSpec(a_max=100.0)).step(s0, acc, 0.5)
    assert np.allclose(s2.velocity, vd)


def test_unicycle_command_on_single_integrator_moves_like_a_unicycle():
    u = np.array([[0.4, 0.5], [0.2, -1.0]])
    dt = 0.01
    s_uni, s_si = RobotState.at_rest(POSE), RobotState.at_rest(POSE)
    uni, si = Unicycle(RobotSpec(v_max=5, w_max=5)), SingleIntegrator(RobotSpec(v_max=5, w_max=5))
    for _ in range(200):
        s_uni = uni.step(s_uni, u, dt)
        cmd = convert(u, "unicycle", "velocity", s_si.pose, s_si.velocity, dt, 0.1)
        s_si = si.step(s_si, cmd, dt)
    assert np.allclose(s_uni.pose[:, :2], s_si.pose[:, :2], atol=5e-3)
    assert np.allclose(np.cos(s_uni.pose[:, 2]), np.cos(s_si.pose[:, 2]), atol=1e-9)


def test_same_kind_is_identity_and_unknown_kind_fails():
    c = np.ones((2, 2))
    assert convert(c, "velocity", "velocity", POSE, VEL, 0.1, 0.1) is c
    with pytest.raises(ValueError):
        convert(c, "torque", "velocity", POSE, VEL, 0.1, 0.1)
