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
