"""Actuated differential drive (dfcoa_opt.world.robots.actuated) against closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dfcoa_opt.scenario.schema import RobotSpec
from dfcoa_opt.world.robots.models import ActuatedUnicycle, RobotState, Unicycle, make_model

R, D = 0.05, 0.3  # wheel radius and track, m


def spec(**kw) -> RobotSpec:
    base = dict(model="unicycle", dynamics="actuated", v_max=2.0, w_max=10.0, wheel_radius=R,
                track_width=D)
    return RobotSpec(**{**base, **kw})


def drive(model, command, steps, dt=0.1, pose=(0.0, 0.0, 0.0)):
    state = RobotState.at_rest(np.array([pose], dtype=float))
    out = [state]
    for _ in range(steps):
        state = model.step(state, np.array([command], dtype=float), dt)
        out.append(state)
    return out


def test_make_model_picks_actuated_only_when_asked():
    assert type(make_model(RobotSpec())) is Unicycle
    assert type(make_model(spec())) is ActuatedUnicycle


@pytest.mark.parametrize("substeps", [1, 4])
def test_constant_curvature_with_lag_follows_the_closed_form(substeps):
    """From rest both wheels rise as 1 - exp(-t / tau): the robot stays on the circle R = v / w.

    Arc length s(t) = v (t - tau (1 - exp(-t / tau))), heading s / R; exact with any substeps.
    """
    tau, v, w, dt = 0.3, 0.4, 0.8, 0.1
    states = drive(ActuatedUnicycle(spec(motor_time_constant=tau, substeps=substeps)),
                   (v, w), 40, dt)
    radius = v / w
    for k, st in enumerate(states):
        t = k * dt
        s = v * (t - tau * -math.expm1(-t / tau))
        th = s / radius
        x, y = radius * math.sin(th), radius * (1.0 - math.cos(th))
        assert st.pose[0, 0] == pytest.approx(x, abs=1e-12)
        assert st.pose[0, 1] == pytest.approx(y, abs=1e-12)
        assert math.remainder(st.pose[0, 2] - th, 2 * math.pi) == pytest.approx(0.0, abs=1e-12)
    # the wheels at the end of step k: the first-order step response
    t_end = 40 * dt
    rise = -math.expm1(-t_end / tau)
    sr, sl = (v + 0.5 * D * w) / R, (v - 0.5 * D * w) / R
    np.testing.assert_allclose(states[-1].wheels[0], [sr * rise, sl * rise], rtol=1e-12)


def test_motor_lag_step_response_reaches_63_percent_at_tau():
    tau, dt = 0.2, 0.05
    states = drive(ActuatedUnicycle(spec(motor_time_constant=tau)), (0.5, 0.0), 8, dt)
    sp = 0.5 / R
    for k, st in enumerate(states[1:], start=1):
        assert st.wheels[0, 0] == pytest.approx(sp * -math.expm1(-k * dt / tau), rel=1e-12)
    assert states[4].wheels[0, 0] / sp == pytest.approx(1 - math.exp(-1), rel=1e-12)
    # the logged twist is the step's mean speed: the travelled distance over dt
    d = np.hypot(*(states[3].pose[0, :2] - states[2].pose[0, :2]))
    assert states[3].twist[0, 0] * dt == pytest.approx(d, rel=1e-12)


def test_acceleration_limit_ramps_then_holds():
    """tau = 0 and a rim acceleration a: v = a t until the set point, distance a t^2 / 2."""
    a, v, dt = 0.25, 0.3, 0.1
    states = drive(ActuatedUnicycle(spec(wheel_accel_max=a)), (v, 0.0), 20, dt)
    t_reach = v / a  # 1.2 s
    for k, st in enumerate(states):
        t = k * dt
        dist = 0.5 * a * t * t if t <= t_reach else 0.5 * a * t_reach ** 2 + v * (t - t_reach)
        assert st.pose[0, 0] == pytest.approx(dist, abs=1e-12)
        assert st.velocity[0, 0] == pytest.approx(min(a * t, v), abs=1e-12)


def test_acceleration_limit_with_lag_ramps_then_decays():
    """Far from the set point the rate is bounded by alpha; within alpha tau it decays."""
    a, tau, dt = 0.5, 0.2, 0.01
    states = drive(ActuatedUnicycle(spec(wheel_accel_max=a, motor_time_constant=tau)),
                   (0.4, 0.0), 200, dt)
    v = np.array([s.velocity[0, 0] for s in states])
    t1 = (0.4 - a * tau) / a  # 0.6 s of ramp
    k1 = round(t1 / dt)
    np.testing.assert_allclose(v[:k1 + 1], a * dt * np.arange(k1 + 1), atol=1e-12)
    rest = np.arange(k1, len(v)) * dt - t1
    np.testing.assert_allclose(v[k1:], 0.4 - a * tau * np.exp(-rest / tau), atol=1e-12)
    assert np.max(np.diff(v)) <= a * dt * (1 + 1e-12)


def test_wheel_saturation_keeps_the_curvature():
    """A command beyond the wheel limit is scaled on both wheels: omega / v unchanged."""
    m = ActuatedUnicycle(spec(wheel_speed_max=6.0))
    states = drive(m, (1.0, 2.0), 3)
    v, w = states[-1].twist[0]
    assert w / v == pytest.approx(2.0, rel=1e-12)
    assert np.max(np.abs(states[-1].wheels)) == pytest.approx(6.0, rel=1e-12)


def test_without_lag_or_limits_it_is_the_kinematic_model():
    pose = np.array([[0.3, -1.0, 0.4], [2.0, 1.0, -2.9], [0.0, 0.0, 3.1]])
    cmd = np.array([[0.5, 0.7], [-0.2, 3.0], [0.6, -12.0]])
    kin = Unicycle(spec(dynamics="kinematic", wheel_speed_max=15.0))
    act = ActuatedUnicycle(spec(wheel_speed_max=15.0))
    a = kin.step(RobotState.at_rest(pose), cmd, 0.1)
    b = act.step(RobotState.at_rest(pose), cmd, 0.1)
    np.testing.assert_allclose(b.pose, a.pose, atol=1e-12)
    np.testing.assert_allclose(b.twist, a.twist, atol=1e-12)
    np.testing.assert_allclose(b.velocity, a.velocity, atol=1e-12)


def test_substeps_converge_on_a_changing_curvature():
    """Wheels rising at different rates turn the path; more substeps, smaller error (O(h^2))."""
    cmd = (0.4, 1.5)

    def end(substeps):
        m = ActuatedUnicycle(spec(wheel_accel_max=0.3, motor_time_constant=0.25,
                                  substeps=substeps))
        return drive(m, cmd, 10)[-1].pose[0, :2]

    ref = end(1000)
    errs = [np.hypot(*(end(k) - ref)) for k in (1, 2, 4, 8)]
    assert errs[0] > 1e-5  # the curvature does change within a step
    for coarse, fine in zip(errs, errs[1:], strict=False):
        assert fine < coarse / 3.0


def test_rows_are_independent_bit_for_bit():
    """A batch of rows gives each row's bits alone (runs in a batch never mix)."""
    m = ActuatedUnicycle(spec(wheel_accel_max=0.4, motor_time_constant=0.1, wheel_speed_max=9.0))
    rng = np.random.default_rng(3)
    pose = rng.uniform(-1, 1, (6, 3))
    cmd = rng.uniform(-1, 1, (6, 2))
    wheels = rng.uniform(-5, 5, (6, 2))
    st = RobotState(pose, np.zeros((6, 2)), np.zeros((6, 2)), wheels)
    all_rows = m.step(st, cmd, 0.1)
    for i in range(6):
        one = m.step(st.rows(slice(i, i + 1)), cmd[i:i + 1], 0.1)
        assert one.pose.tobytes() == all_rows.pose[i:i + 1].tobytes()
        assert one.wheels.tobytes() == all_rows.wheels[i:i + 1].tobytes()
