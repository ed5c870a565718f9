import numpy as np

from dfcoa_opt.planning.pure_pursuit import PurePursuit
from dfcoa_opt.world.robots.models import integrate_unicycle


def drive(pp, pose, steps, dt=0.1):
    traj = [pose]
    for _ in range(steps):
        v, w, _ = pp.command(pose)
        assert abs(w) <= pp.w_max + 1e-12
        pose = integrate_unicycle(pose, v, w, dt)
        traj.append(pose)
    return np.array(traj)


def test_converges_onto_a_straight_line():
    pp = PurePursuit(np.array([[0.0, 0.0], [20.0, 0.0]]), 0.5, 1.0, 1.5)
    traj = drive(pp, np.array([0.0, 1.0, 0.0]), 200)
    assert abs(traj[-1, 1]) < 0.02 and traj[-1, 0] > 8.0


def test_follows_corner_path_monotonically():
    path = np.array([[0.0, 0.0], [5.0, 0.0], [5.0, 5.0]])
    pp = PurePursuit(path, 0.3, 0.5, 3.5)
    traj = drive(pp, np.array([0.0, 0.0, 0.0]), 330)  # 9.9 m at 0.3 m/s
    assert np.hypot(*(traj[:, :2] - [5.0, 5.0]).T).min() < 0.3
    # never farther than the look-ahead from the path
    d = np.minimum(np.abs(traj[:, 1]) + np.maximum(traj[:, 0] - 5, 0), np.abs(traj[:, 0] - 5))
    assert d.max() < 0.5
    assert pp.length == 10.0 and np.allclose(pp.point_at(7.0), [5.0, 2.0])


def _project_numpy(pp, p):
    """The vectorised numpy projection the numba kernel replaced (reference)."""
    a, b = pp.path[:-1], pp.path[1:]
    ab = b - a
    t = np.clip(((p - a) * ab).sum(1) / pp._seg_len**2, 0.0, 1.0)
    s_all = pp._cum[:-1] + t * pp._seg_len
    d = np.linalg.norm(a + t[:, None] * ab - p, axis=1)
    d = np.where(pp._cum[1:] >= pp._s, d, np.inf)
    return max(float(s_all[int(np.argmin(d))]), pp._s)


def test_projection_kernel_matches_numpy_reference_bit_for_bit():
    rng = np.random.default_rng(4)
    for trial in range(40):
        path = np.cumsum(rng.normal(size=(int(rng.integers(2, 30)), 2)), axis=0)
        if trial % 4 == 0:  # axis-aligned grid path: equal distances to several segments
            path = np.round(path)
        pp = PurePursuit(path, 0.5, 0.4, 1.0)
        for p in rng.normal(size=(25, 2)) * 3.0 + path.mean(axis=0):
            pp._s = float(rng.uniform(0.0, pp.length)) if rng.random() < 0.5 else 0.0
            assert pp._project(p) == _project_numpy(pp, p)
