"""The improved velocity obstacle of paper 001 (eq 8-11) against independent geometry.

The reference geometry here does not use the support-function machinery of
:mod:`comparisons.orca.ivo`: ellipse membership is the quadratic form, the
distance to an ellipse is Eberly's bisection on the closest-point equation, and
"the ray t v reaches O' (+) D(r_A) within tau" is checked by sampling ``t``.
"""

import numpy as np
import pytest

from comparisons.orca.ivo import ivo_line, ivo_lines
from comparisons.orca.ivo.ellipse import Ellipse, ellipse_support, polygon_segments, segment_ellipse
from comparisons.orca.lines import agent_lines
from comparisons.orca.lp import FEASIBLE, solve_lines

RNG_SEED = 20240601


# ----------------------------------------------------------------- reference geometry


def _local(points, e: Ellipse):
    d = np.asarray(points, dtype=float) - e.centre
    return d @ e.axis, d @ np.array([-e.axis[1], e.axis[0]])


def _quad(points, e: Ellipse):
    x, y = _local(points, e)
    return (x / e.a) ** 2 + (y / e.b) ** 2


def _ellipse_distance(points, e: Ellipse):
    """Euclidean distance from points to the closed ellipse (0 inside), Eberly's bisection.

    A degenerate ellipse (``b = 0``, clearance 0) is its major-axis segment.
    """
    x, y = _local(points, e)
    y0, y1 = np.abs(x), np.abs(y)
    if e.b == 0.0:
        return np.hypot(np.maximum(y0 - e.a, 0.0), y1)
    y1 = np.maximum(y1, 1e-12)
    e0, e1 = e.a, e.b
    lo = -e1 * e1 + e1 * y1
    hi = -e1 * e1 + np.sqrt((e0 * y0) ** 2 + (e1 * y1) ** 2) + 1e-12
    for _ in range(64):
        t = 0.5 * (lo + hi)
        f = (e0 * y0 / (t + e0 * e0)) ** 2 + (e1 * y1 / (t + e1 * e1)) ** 2 - 1.0
        lo = np.where(f > 0.0, t, lo)
        hi = np.where(f > 0.0, hi, t)
    t = 0.5 * (lo + hi)
    cx, cy = e0 * e0 * y0 / (t + e0 * e0), e1 * e1 * y1 / (t + e1 * e1)
    dist = np.hypot(cx - y0, cy - y1)
    return np.where((y0 / e0) ** 2 + (y1 / e1) ** 2 <= 1.0, 0.0, dist)


def _boundary(e: Ellipse, k=20000):
    t = np.linspace(0.0, 2.0 * np.pi, k, endpoint=False)
    e2 = np.array([-e.axis[1], e.axis[0]])
    return e.centre + np.outer(e.a * np.cos(t), e.axis) + np.outer(e.b * np.sin(t), e2)


def _reach_margin(vs, pos, r, e: Ellipse, tau, k=1000):
    """min over t in [0, tau] of dist(p_A + t v, O') - r_A per velocity: < 0 iff v is in the VO.

    Args:
        vs: ``(2,)`` or ``(K, 2)`` velocities (eq 9's ``v``).
    """
    vs = np.asarray(vs, dtype=float)
    t = np.linspace(0.0, tau, k)
    pts = np.asarray(pos) + t[None, :, None] * vs.reshape(-1, 1, 2)
    margin = _ellipse_distance(pts.reshape(-1, 2), e).reshape(-1, k).min(axis=1) - r
    return margin if vs.ndim == 2 else margin[0]


def _random_case(rng, clearance=None):
    """A random segment, robot outside O' (+) D(r_A), and v_opt."""
    while True:
        p0 = rng.uniform(-3, 3, 2)
        p1 = p0 + rng.uniform(0.2, 4.0) * np.array([np.cos(th := rng.uniform(0, 6.3)), np.sin(th)])
        r = rng.uniform(0.1, 0.5)
        e = segment_ellipse(p0, p1, r, clearance=clearance, stretch=rng.choice([1.0, 1.0, 1.5]))
        pos = rng.uniform(-6, 6, 2)
        if _ellipse_distance(pos[None], e)[0] > r + 1e-3:
            return e, pos, r, rng.uniform(-2, 2, 2)


# ----------------------------------------------------------------- eq 8: the ellipse


@pytest.mark.parametrize("length", [0.0, 0.3, 1.0, 4.0, 12.0])
@pytest.mark.parametrize("clearance", [0.05, 0.3])
@pytest.mark.parametrize("stretch", [1.0, 1.3, 2.0])
def test_ellipse_contains_segment_with_clearance(length, clearance, stretch):
    p0 = np.array([1.0, -2.0])
    p1 = p0 + length * np.array([0.6, 0.8])
    e = segment_ellipse(p0, p1, 0.2, clearance=clearance, stretch=stretch)
    np.testing.assert_allclose(e.centre, 0.5 * (p0 + p1))
    assert e.a >= e.b > 0.0
    seg = p0 + np.linspace(0, 1, 200)[:, None] * (p1 - p0)
    assert np.all(_quad(seg, e) < 1.0)
    # eq 8 (words): every segment point is at least the clearance inside the boundary ...
    bnd = _boundary(e)
    gap = np.min(np.linalg.norm(seg[:, None, :] - bnd[None, ::4, :], axis=2))
    assert gap >= clearance - 1e-6
    # ... and b is the smallest such semi-axis: the clearance is attained
    assert gap <= clearance + 2e-3
    thinner = Ellipse(e.centre, e.axis, e.a, 0.99 * e.b)
    ang = np.linspace(0, 2 * np.pi, 2000)
    capsule = np.vstack([end + clearance * np.c_[np.cos(ang), np.sin(ang)] for end in (p0, p1)])
    assert np.all(_quad(capsule, e) <= 1.0 + 1e-9)
    assert np.any(_quad(capsule, thinner) > 1.0)
    # eq 8 (formula): dist(l, boundary of O' (+) D(r_A)) > r_A, boundary = offset curve
    r = 0.2
    x, y = _local(bnd, e)
    normal = np.c_[x / e.a**2, y / e.b**2]
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    e2 = np.array([-e.axis[1], e.axis[0]])
    offset = bnd + r * (np.outer(normal[:, 0], e.axis) + np.outer(normal[:, 1], e2))
    assert np.min(np.linalg.norm(seg[:, None, :] - offset[None, ::4, :], axis=2)) > r


def test_default_clearance_is_robot_radius_and_stretch_one_closed_form():
    e = segment_ellipse([0, 0], [4, 0], 0.3)
    assert e.a == pytest.approx(2.3)
    assert e.b == pytest.approx(np.sqrt(0.3 * 2.3))
    assert segment_ellipse([0, 0], [4, 0], 0.3, clearance=0.0).b == 0.0
    with pytest.raises(ValueError):
        segment_ellipse([0, 0], [4, 0], 0.3, stretch=0.9)


# ----------------------------------------------------------------- eq 9: Minkowski sum


def test_support_is_that_of_the_minkowski_sum():
    e = segment_ellipse([0.5, 1.0], [3.0, 2.0], 0.4)
    r = 0.4
    bnd = _boundary(e, 4000)
    ang = np.linspace(0, 2 * np.pi, 400, endpoint=False)
    disc = r * np.c_[np.cos(ang), np.sin(ang)]
    normals = np.c_[np.cos(ang), np.sin(ang)]
    sampled = (bnd @ normals.T).max(axis=0) + (disc @ normals.T).max(axis=0)
    np.testing.assert_allclose(ellipse_support(e, normals, r), sampled, atol=1e-4)


def test_inflating_the_semi_axes_does_not_enclose_the_minkowski_sum():
    """Why the sum is treated exactly: ``(a + r, b + r)`` misses points of ``O' (+) D(r)``."""
    e = Ellipse(np.zeros(2), np.array([1.0, 0.0]), 2.0, 0.5)
    r = 0.5
    t = np.pi / 4
    q = np.array([2.0 * np.cos(t), 0.5 * np.sin(t)])
    n = np.array([q[0] / 4.0, q[1] / 0.25])
    point = q + r * n / np.linalg.norm(n)  # on the boundary of the Minkowski sum
    assert _ellipse_distance(point[None], e)[0] == pytest.approx(r)
    assert (point[0] / 2.5) ** 2 + (point[1] / 1.0) ** 2 > 1.0


# ----------------------------------------------------------------- eq 9-10: the half-plane


def _in_half_plane(line, v):
    d, p = line.direction, line.point
    return d[0] * (p[1] - v[..., 1]) - d[1] * (p[0] - v[..., 0]) <= 1e-12


@pytest.mark.parametrize("tau", ["center", "gap", 2.0])
def test_half_plane_velocities_do_not_reach_the_obstacle(tau):
    rng = np.random.default_rng(RNG_SEED)
    for _ in range(16):
        e, pos, r, v_opt = _random_case(rng)
        line = ivo_line(pos, v_opt, r, e, tau=tau)
        assert not line.inside
        n, d = line.normal, line.direction
        np.testing.assert_allclose(np.linalg.norm(d), 1.0)
        np.testing.assert_allclose([-d[1], d[0]], n, atol=1e-12)  # left normal is n
        if tau == 2.0:
            assert line.tau == 2.0
        s, k = np.meshgrid(np.linspace(-4.0, 4.0, 9), [0.0, 0.05, 0.5, 2.0])
        vs = line.point + s.reshape(-1, 1) * d + k.reshape(-1, 1) * n
        assert np.all(_in_half_plane(line, vs))
        assert np.all(_reach_margin(vs, pos, r, e, line.tau) >= -1e-7)


@pytest.mark.parametrize("tau", ["center", 3.0])
def test_line_is_tight_and_v_opt_side_matches_vo(tau):
    """``v_opt + u`` is on the VO boundary and ``v_opt`` satisfies its line iff it is outside."""
    rng = np.random.default_rng(RNG_SEED + 1)
    for _ in range(30):
        e, pos, r, v_opt = _random_case(rng)
        line = ivo_line(pos, v_opt, r, e, tau=tau)
        boundary = v_opt + line.u
        np.testing.assert_allclose(boundary, line.point, atol=1e-12)
        assert abs(_reach_margin(boundary, pos, r, e, line.tau, 20000)) < 2e-3
        outside = _reach_margin(v_opt, pos, r, e, line.tau) > 1e-6
        inside = _reach_margin(v_opt, pos, r, e, line.tau) < -1e-6
        if outside:
            assert _in_half_plane(line, v_opt)
        if inside:
            assert not _in_half_plane(line, v_opt)


def test_circle_ellipse_matches_orca_agent_line():
    """For ``a = b`` the IVO is the disc VO: u equals twice the ORCA half-step of lines.py."""
    rng = np.random.default_rng(RNG_SEED + 2)
    checked = 0
    while checked < 40:
        centre = rng.uniform(-5, 5, 2)
        big, r = rng.uniform(0.2, 1.5), rng.uniform(0.1, 0.5)
        v = rng.uniform(-2, 2, 2)
        if np.linalg.norm(centre) <= big + r + 1e-3:
            continue
        tau = rng.uniform(0.5, 5.0)
        e = Ellipse(centre, np.array([1.0, 0.0]), big, big)
        line = ivo_line([0.0, 0.0], v, r, e, tau=tau)
        P, D = np.empty((1, 2)), np.empty((1, 2))
        agent_lines(0.0, 0.0, v[0], v[1], r, centre[None], np.zeros((1, 2)), np.array([big]),
                    1, 1.0 / tau, 10.0, P, D, 0)
        np.testing.assert_allclose(line.u, 2.0 * (P[0] - v), atol=1e-6)
        np.testing.assert_allclose(line.direction, D[0], atol=1e-6)
        checked += 1


def test_head_on_known_answers():
    """A wall segment across the x axis at x = 3, the robot at the origin moving along +x."""
    r, s, wall_x = 0.3, 1.0, 3.0
    e = segment_ellipse([wall_x, -1.0], [wall_x, 1.0], r)
    b = e.b
    assert b == pytest.approx(np.sqrt(0.3 * 1.3))
    # eq 9 "center": tau = dist(p_A, O') / |v_opt|; the line caps the approach speed
    line = ivo_line([0, 0], [s, 0], r, e)
    assert line.tau == pytest.approx((wall_x - b) / s)
    np.testing.assert_allclose(line.point, [s * (wall_x - b - r) / (wall_x - b), 0.0], atol=1e-9)
    np.testing.assert_allclose(line.direction, [0.0, 1.0], atol=1e-9)
    np.testing.assert_allclose(line.u, [-s * r / (wall_x - b), 0.0], atol=1e-9)
    # "gap": tau is the time to contact, v_opt lies on the cut-off (u = 0)
    line = ivo_line([0, 0], [s, 0], r, e, tau="gap")
    assert line.tau == pytest.approx((wall_x - b - r) / s)
    np.testing.assert_allclose(line.u, [0.0, 0.0], atol=1e-9)
    # fixed tau: the cut-off point is gap / tau
    line = ivo_line([0, 0], [s, 0], r, e, tau=2.0)
    np.testing.assert_allclose(line.point, [(wall_x - b - r) / 2.0, 0.0], atol=1e-9)
    # at rest: tau_max; v = 0 is allowed
    line = ivo_line([0, 0], [0, 0], r, e, tau_max=7.0)
    assert line.tau == 7.0
    np.testing.assert_allclose(line.point, [(wall_x - b - r) / 7.0, 0.0], atol=1e-9)
    # responsibility alpha scales the step (eq 10)
    half = ivo_line([0, 0], [s, 0], r, e, alpha=0.5)
    np.testing.assert_allclose(half.point, [s - 0.5 * s * r / (wall_x - b), 0.0], atol=1e-9)


def test_parallel_wall_far_away_is_unconstrained():
    r = 0.3
    e = segment_ellipse([-5.0, 3.0], [5.0, 3.0], r)
    assert 3.0 - e.b - r > 0.5
    for tau in ("center", "gap", 5.0, 50.0):
        line = ivo_line([0, 0], [1.0, 0.0], r, e, tau=tau)
        assert _in_half_plane(line, np.array([1.0, 0.0]))
        P, D, count = ivo_lines([[0.0, 0.0]], [[1.0, 0.0]], r, [[[-5, 3], [5, 3]]], 10.0, tau=tau)
        vel, status, _ = solve_lines(P, D, count, count, np.array([[1.0, 0.0]]), np.array([2.0]))
        assert status[0] == FEASIBLE
        np.testing.assert_allclose(vel[0], [1.0, 0.0], atol=1e-12)


def test_inside_gives_push_out_line():
    r = 0.3
    e = segment_ellipse([0.0, 1.0], [4.0, 1.0], r)
    pos = np.array([2.0, 1.0 - e.b - 0.1])  # centre within r_A of O'
    line = ivo_line(pos, [0.0, 1.0], r, e)
    assert line.inside and line.tau == 0.0
    np.testing.assert_allclose(line.normal, [0.0, -1.0], atol=1e-9)
    assert _in_half_plane(line, np.zeros(2))
    assert not _in_half_plane(line, np.array([0.0, 0.1]))
    pushed = ivo_line(pos, [0.0, 1.0], r, e, push_speed=0.2)
    assert _in_half_plane(pushed, np.array([0.0, -0.2]))
    assert not _in_half_plane(pushed, np.array([0.0, -0.19]))


def test_every_line_contains_zero_velocity():
    rng = np.random.default_rng(RNG_SEED + 3)
    for _ in range(50):
        e, pos, r, v_opt = _random_case(rng)
        assert _in_half_plane(ivo_line(pos, v_opt, r, e, tau="center"), np.zeros(2))


def test_zero_clearance_is_the_exact_segment():
    """With m = 0 (the literal eq 8) O' is the segment; its VO keeps the robot off it."""
    rng = np.random.default_rng(RNG_SEED + 4)
    for _ in range(20):
        e, pos, r, v_opt = _random_case(rng, clearance=0.0)
        assert e.b == 0.0
        line = ivo_line(pos, v_opt, r, e, tau=2.0)
        vs = line.point + np.linspace(-3, 3, 7)[:, None] * line.direction + 0.1 * line.normal
        assert np.all(_reach_margin(vs, pos, r, e, 2.0) >= -1e-9)
        assert abs(_reach_margin(line.point, pos, r, e, 2.0, 20000)) < 2e-3


# ----------------------------------------------------------------- batched lines


def test_polygon_segments():
    square = np.array([[0, 0], [2, 0], [2, 2], [0, 2]], float)
    assert polygon_segments([square]).shape == (4, 4)
    assert polygon_segments([np.vstack([square, square[:1]])]).shape == (4, 4)
    assert polygon_segments([[[0, 0], [3, 0]]]).shape == (1, 4)
    split = polygon_segments([[[0, 0], [3, 0]]], max_segment=1.0)
    np.testing.assert_allclose(split, [[0, 0, 1, 0], [1, 0, 2, 0], [2, 0, 3, 0]])


def test_batch_matches_single_lines_nearest_first():
    rng = np.random.default_rng(RNG_SEED + 5)
    polys = [np.array([[2, -1], [3, -1], [3, 1], [2, 1]], float), np.array([[-4, 3], [4, 3.5]])]
    pos = rng.uniform(-1, 1, (6, 2))
    pos[5] = [20.0, 20.0]  # nothing in range
    vel = rng.uniform(-1, 1, (6, 2))
    radius = rng.uniform(0.1, 0.3, 6)
    P, D, count = ivo_lines(pos, vel, radius, polys, max_range=4.0, tau="center")
    seg = polygon_segments(polys)
    assert count[5] == 0
    assert P.shape == (6, count.max(), 2)
    for i in range(6):
        dist = []
        for x0, y0, x1, y1 in seg:
            a, d = np.array([x0, y0]), np.array([x1 - x0, y1 - y0])
            t = np.clip((pos[i] - a) @ d / (d @ d), 0, 1)
            dist.append(np.linalg.norm(pos[i] - a - t * d))
        order = [k for k in np.argsort(dist, kind="stable") if dist[k] <= 4.0]
        assert count[i] == len(order)
        prev = -1.0
        for j, k in enumerate(order):
            assert dist[k] >= prev
            prev = dist[k]
            e = segment_ellipse(seg[k, :2], seg[k, 2:], radius[i])
            line = ivo_line(pos[i], vel[i], radius[i], e)
            np.testing.assert_allclose(P[i, j], line.point, atol=1e-9)
            np.testing.assert_allclose(D[i, j], line.direction, atol=1e-9)
    P2, _, count2 = ivo_lines(pos, vel, radius, polys, max_range=4.0, max_lines=2)
    assert count2.max() <= 2
    np.testing.assert_allclose(P2[:, :2][count2 == 2], P[:, :2][count2 == 2])


@pytest.mark.parametrize(("tau", "max_segment"), [("center", None), ("center", 1.0),
                                                 ("gap", 1.0), (2.0, 1.0)])
def test_lp_with_hard_ivo_lines_avoids_a_polygon(tau, max_segment):
    """One robot whose v_pref crosses a square; the hard IVO lines keep it off the square.

    With ``tau >= dt`` the centre never enters ``O' (+) D(r_A)``, so it stays at
    least ``r_A + m = 2 r_A`` from every edge (gap to the robot's edge ``>= r_A``).
    """
    square = np.array([[2.0, -1.0], [4.0, -1.0], [4.0, 1.0], [2.0, 1.0]])
    r, v_max, dt = 0.25, 1.0, 0.1
    pos, vel = np.array([0.0, 1.0]), np.zeros(2)
    goal = np.array([7.0, 0.0])
    seg = polygon_segments([square])
    min_gap, max_slack, crossed = np.inf, 0.0, False
    for _ in range(300):
        to_goal = goal - pos
        pref = to_goal / max(np.linalg.norm(to_goal), 1e-9) * min(v_max, np.linalg.norm(to_goal))
        P, D, count = ivo_lines(pos[None], vel[None], r, [square], max_range=3.0, tau=tau,
                                tau_min=dt, max_segment=max_segment)
        new, _, slack = solve_lines(P, D, count, count, pref[None], np.array([v_max]))
        max_slack = max(max_slack, slack[0])
        vel = new[0]
        pos = pos + dt * vel
        w = pos[None] - seg[:, :2]
        d = seg[:, 2:] - seg[:, :2]
        t = np.clip(np.sum(w * d, 1) / np.sum(d * d, 1), 0, 1)
        min_gap = min(min_gap, np.min(np.linalg.norm(w - t[:, None] * d, axis=1)) - r)
        crossed |= bool(2.0 <= pos[0] <= 4.0)
    assert max_slack <= 1e-9
    assert crossed  # it went past the square, not around the far side of the field
    assert min_gap >= r - 1e-9
    assert np.linalg.norm(pos - goal) < 0.05
