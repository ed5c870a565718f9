import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from dfcoa_opt.scenario.schema import RobotSpec
from dfcoa_opt.world.robots.models import (
    DoubleIntegrator,
    RobotState,
    SingleIntegrator,
    Unicycle,
    integrate_unicycle,
    twist_from_wheels,
    wheel_speeds,
)


def fine_euler(pose, v, w, dt, n=20000):
    x, y, th = pose
    h = dt / n
    for _ in range(n):
        x += v * np.cos(th) * h
        y += v * np.sin(th) * h
        th += w * h
    return np.array([x, y, th])


def test_arc_integration_matches_fine_integration():
    pose = np.array([1.0, -2.0, 0.4])
    for v, w in [(0.5, 1.3), (0.3, -2.0), (0.7, 0.0), (0.0, 1.0)]:
        exact = integrate_unicycle(pose, v, w, 0.7)
        ref = fine_euler(pose, v, w, 0.7)
        assert np.allclose(exact[:2], ref[:2], atol=5e-5)
        assert np.isclose(np.cos(exact[2]), np.cos(ref[2]))


def test_wheel_mapping_is_eq2():
    r, d = 0.05, 0.3
    pr, pl = 10.0, 6.0
    v, w = twist_from_wheels(pr, pl, r, d)
    assert np.isclose(v, r / 2 * (pr + pl)) and np.isclose(w, r / d * (pr - pl))
    assert np.allclose(wheel_speeds(v, w, r, d), (pr, pl))


def test_unicycle_saturation_keeps_curvature_at_wheel_limit():
    spec = RobotSpec(v_max=5.0, w_max=10.0, wheel_radius=0.05, track_width=0.3,
                     wheel_speed_max=8.0)
    u = Unicycle(spec).saturate(np.array([[1.0, 2.0], [9.0, 0.0], [0.1, 50.0]]))
    pr, pl = wheel_speeds(u[:, 0], u[:, 1], 0.05, 0.3)
    assert np.all(np.maximum(abs(pr), abs(pl)) <= 8.0 + 1e-9)
    assert np.isclose(u[0, 1] / u[0, 0], 2.0)  # curvature w/v preserved
    assert u[2, 1] <= 10.0


def test_unicycle_disturbance_adds_world_velocity():
    m = Unicycle(RobotSpec())
    s = RobotState.at_rest([[0.0, 0.0, 0.0], [5.0, 5.0, 0.0]])
    dist = np.array([[0.0, 1.0], [0.0, 0.0]])
    s2 = m.step(s, np.array([[0.2, 0.0], [0.2, 0.0]]), 0.5, dist)
    assert np.allclose(s2.pose[0, :2], [0.1, 0.5]) and np.allclose(s2.pose[1, :2], [5.1, 5.0])


def test_single_integrator_heading_rules():
    m = SingleIntegrator(RobotSpec(v_max=1.0, w_max=2.0))
    s = RobotState.at_rest([[0.0, 0.0, 0.3], [0.0, 0.0, 0.3]])
    s2 = m.step(s, np.array([[0.0, 2.0], [0.0, 0.0]]), 0.1)
    assert np.allclose(s2.pose[0], [0.0, 0.1, np.pi / 2])  # clipped to |v| = 1, faces motion
    assert np.isclose(s2.pose[1, 2], 0.3)  # at rest: heading kept
    s3 = m.step(s, np.array([[0.0, 0.0, 5.0], [0.0, 0.0, -1.0]]), 0.1)
    assert np.allclose(s3.pose[:, 2], [0.5, 0.2])  # 3rd column = turn rate (clipped to 2)


def test_double_integrator_is_paper004_eq3():
    m = DoubleIntegrator(RobotSpec(v_max=10.0, a_max=10.0))
    s = RobotState(np.array([[1.0, 2.0, 0.0]]), np.array([[0.5, -0.5]]), np.zeros((1, 2)))
    u = np.array([[2.0, 1.0]])
    s2 = m.step(s, u, 0.2)
    assert np.allclose(s2.pose[0, :2], [1.0 + 0.2 * 0.5, 2.0 - 0.2 * 0.5])  # p+ = p + T v
    assert np.allclose(s2.velocity[0], [0.5 + 0.4, -0.5 + 0.2])  # v+ = v + T u
    s3 = m.step(s, u, 0.2, force=np.array([[1.0, 0.0]]))  # mass 1 kg
    assert np.allclose(s3.velocity[0], [0.5 + 0.6, -0.5 + 0.2])


finite = st.floats(-20, 20, allow_nan=False)


@settings(max_examples=60, deadline=None)
@given(arrays(np.float64, (5, 2), elements=finite), arrays(np.float64, (5, 2), elements=finite),
       st.floats(0.01, 0.5))
def test_every_model_respects_its_limits(cmd, vel0, dt):
    spec = RobotSpec(v_max=0.7, v_min=-0.2, w_max=1.1, a_max=0.9, wheel_speed_max=12.0)
    pose = np.zeros((5, 3))
    s = RobotState(pose, vel0 * 0.0, np.zeros((5, 2)))
    u = Unicycle(spec).step(s, cmd, dt)
    assert np.all(u.twist[:, 0] <= 0.7 + 1e-12) and np.all(u.twist[:, 0] >= -0.2 - 1e-12)
    assert np.all(np.abs(u.twist[:, 1]) <= 1.1 + 1e-12)
    pr, pl = wheel_speeds(u.twist[:, 0], u.twist[:, 1], spec.wheel_radius, spec.track_width)
    assert np.all(np.maximum(abs(pr), abs(pl)) <= 12.0 + 1e-9)
    si = SingleIntegrator(spec).step(s, cmd, dt)
    assert np.all(np.hypot(*si.velocity.T) <= 0.7 + 1e-12)
    sd = RobotState(pose, SingleIntegrator(spec).saturate(vel0), np.zeros((5, 2)))
    di = DoubleIntegrator(spec).step(sd, cmd, dt)
    assert np.all(np.hypot(*di.velocity.T) <= 0.7 + 1e-12)
    acc = (di.velocity - sd.velocity) / dt
    assert np.all(np.hypot(*acc.T) <= 0.9 + 1e-9)


def test_unicycle_kernel_matches_numpy_reference_bit_for_bit():
    """The numba step is the numpy step, bit for bit, with and without the wheel limit."""
    rng = np.random.default_rng(8)
    n = 400
    pose = np.column_stack((rng.normal(size=(n, 2)) * 10.0, rng.uniform(-np.pi, np.pi, n)))
    pose[:5, 2] = [np.pi, -np.pi, 0.0, np.pi / 2, 3.1415]
    cmd = np.column_stack((rng.normal(size=n) * 2.0, rng.normal(size=n) * 3.0))
    cmd[5:10, 1] = [0.0, 1e-12, -1e-11, 5e-9, 2.0]  # straight, nearly straight, fast turns
    vel = rng.normal(size=(n, 2))
    state = RobotState(pose, vel, np.zeros((n, 2)))
    for spec in (RobotSpec(v_max=1.5, w_max=2.5),
                 RobotSpec(v_max=5.0, w_max=10.0, wheel_radius=0.05, track_width=0.3,
                           wheel_speed_max=8.0)):
        model = Unicycle(spec)
        for dist in (None, rng.normal(size=(n, 2))):
            for dt in (0.1, 0.01, 0.7):
                fast = model.step(state, cmd, dt, dist)
                ref = model.step_reference(state, cmd, dt, dist)
                for a, b in zip((fast.pose, fast.velocity, fast.twist),
                                (ref.pose, ref.velocity, ref.twist), strict=True):
                    assert np.array_equal(a, b)
    # headings that wrap exactly onto -pi come out as +pi on both paths
    edge = RobotState(np.array([[0.0, 0.0, np.pi - 0.1]]), np.zeros((1, 2)), np.zeros((1, 2)))
    out = Unicycle(RobotSpec(w_max=10.0)).step(edge, np.array([[0.0, 1.0]]), 0.1)
    assert out.pose[0, 2] == Unicycle(RobotSpec(w_max=10.0)).step_reference(
        edge, np.array([[0.0, 1.0]]), 0.1).pose[0, 2]

