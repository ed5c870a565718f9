import numpy as np

from dfcoa_opt.world.dynamic import DynamicObstacles, MovingDisc


def test_stop_loop_bounce_and_start_time():
    d = DynamicObstacles((
        MovingDisc(0.3, 1.0, ((0.0, 0.0), (2.0, 0.0), (2.0, 2.0))),
        MovingDisc(0.3, 1.0, ((0.0, 0.0), (2.0, 0.0)), end="loop"),
        MovingDisc(0.3, 1.0, ((0.0, 0.0), (2.0, 0.0)), end="bounce"),
        MovingDisc(0.5, 2.0, ((5.0, 5.0), (5.0, 9.0)), start_time=1.0),
        MovingDisc(0.2, 0.0, ((1.0, 1.0),)),
    ))
    p, v = d.state(3.0)
    assert np.allclose(p[0], [2.0, 1.0]) and np.allclose(v[0], [0.0, 1.0])
    assert np.allclose(p[1], [1.0, 0.0]) and np.allclose(v[1], [-1.0, 0.0])  # going home
    assert np.allclose(p[2], [1.0, 0.0]) and np.allclose(v[2], [-1.0, 0.0])
    assert np.allclose(p[3], [5.0, 9.0]) and np.allclose(v[3], 0.0)  # 4 m done at t=3
    assert np.allclose(p[4], [1.0, 1.0]) and np.allclose(v[4], 0.0)
    p0, _ = d.state(0.5)
    assert np.allclose(p0[3], [5.0, 5.0])
    p9, v9 = d.state(10.0)
    assert np.allclose(p9[0], [2.0, 2.0]) and np.allclose(v9[0], 0.0)
    assert np.allclose(d.radii, [0.3, 0.3, 0.3, 0.5, 0.2])


def test_empty():
    p, v = DynamicObstacles().state(1.0)
    assert p.shape == (0, 2) and v.shape == (0, 2)


def test_states_at_many_times_are_the_states_at_each_time_bit_for_bit():
    """The simulator asks once for every t_k = k dt; each row must equal state(k * dt)."""
    d = DynamicObstacles((
        MovingDisc(0.3, 0.7, ((0.0, 0.0), (2.0, 0.3), (2.1, 2.0), (0.4, 1.1)), end="loop"),
        MovingDisc(0.3, 1.3, ((0.0, 0.0), (2.0, 0.0), (2.5, 1.5)), end="bounce"),
        MovingDisc(0.5, 2.0, ((5.0, 5.0), (5.0, 9.0)), start_time=1.0),
        MovingDisc(0.2, 0.0, ((1.0, 1.0),)),
    ))
    dt, steps = 0.05, 400
    pos, vel = d.state(np.arange(steps) * dt)
    assert pos.shape == vel.shape == (steps, 4, 2)
    for k in range(steps):
        p, v = d.state(k * dt)
        np.testing.assert_array_equal(pos[k], p)
        np.testing.assert_array_equal(vel[k], v)
    still = DynamicObstacles((MovingDisc(0.2, 1.0, ((1.0, 2.0),)),))
    p, v = still.state(np.arange(3) * dt)
    assert np.array_equal(p, np.tile([1.0, 2.0], (3, 1, 1))) and not v.any()
    p, v = DynamicObstacles().state(np.arange(3) * dt)
    assert p.shape == v.shape == (3, 0, 2)
