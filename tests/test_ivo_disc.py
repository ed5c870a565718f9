"""The closed-form IVO of a static disc (comparisons/orca/ivo/discs.py) and its batching.

A disc ``D(c, R)`` is its own eq-8 ellipse ``O' = D(c, R + m)``; its line must be
the one the numerical ellipse path (:func:`comparisons.orca.ivo.ivo_line`) gives
for ``a = b = R + m``, and ``ivo_lines`` must merge disc and segment lines
nearest first within the range.
"""

import numpy as np
import pytest

from comparisons.orca.filter import OrcaFilter
from comparisons.orca.ivo import ivo_line, ivo_lines
from comparisons.orca.ivo.discs import disc_line
from comparisons.orca.ivo.ellipse import Ellipse, polygon_segments, segment_ellipse
from comparisons.orca.lines import agent_lines
from comparisons.orca.lp import solve_lines
from dfcoa_opt import metrics
from dfcoa_opt.scenario.loader import scenario_from_dict
from dfcoa_opt.sim.simulator import run_scenario

RNG_SEED = 20240917
TOL = 1e-6  # the numerical path's accuracy (golden sections, bisected legs)


def _rotate(x, angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([c * x[0] - s * x[1], s * x[0] + c * x[1]])


def _random_disc_case(rng, kind):
    """``(pos, v_opt, r, centre, R, m)``: outside, inside ``K`` or ``v_opt`` near a leg."""
    centre = rng.uniform(-3, 3, 2)
    big, r = rng.uniform(0.1, 1.5), rng.uniform(0.1, 0.5)
    m = [None, 0.0, float(rng.uniform(0.0, 0.8))][rng.integers(3)]
    rad = big + (r if m is None else m) + r  # radius of K = O' (+) D(r_A)
    ang = rng.uniform(0, 2 * np.pi)
    unit = np.array([np.cos(ang), np.sin(ang)])
    if kind == "inside":
        pos = centre + rng.uniform(0.0, 0.999) * rad * unit
        v = rng.uniform(-2, 2, 2)
    else:
        pos = centre + rad * rng.uniform(1.001, 6.0) * unit
        v = rng.uniform(-2, 2, 2) * [0.0, 0.01, 1.0, 1.0][rng.integers(4)]
        if kind == "leg":  # along a leg of the cone, slightly to either side
            to_c = centre - pos
            half = np.arcsin(rad / np.linalg.norm(to_c))
            leg = _rotate(to_c / np.linalg.norm(to_c), rng.choice([-1.0, 1.0]) * half)
            v = rng.uniform(0.05, 3.0) * leg + rng.uniform(-1e-3, 1e-3) * _rotate(leg, np.pi / 2)
    return pos, v, r, centre, big, m


@pytest.mark.parametrize("kind", ["outside", "leg", "inside"])
def test_disc_line_is_the_numeric_line_of_the_equal_axes_ellipse(kind):
    rng = np.random.default_rng(RNG_SEED + ["outside", "leg", "inside"].index(kind))
    for _ in range(300):
        pos, v, r, centre, big, m = _random_disc_case(rng, kind)
        tau = ["center", "gap", float(rng.uniform(0.2, 5.0))][rng.integers(3)]
        kw = {"tau": tau, "tau_min": float(rng.choice([0.1, 0.5])),
              "tau_max": float(rng.choice([3.0, 10.0])), "alpha": float(rng.choice([1.0, 0.5])),
              "push_speed": float(rng.choice([0.0, 0.2]))}
        a = big + (r if m is None else m)
        axis = _rotate([1.0, 0.0], rng.uniform(0, 2 * np.pi))
        ref = ivo_line(pos, v, r, Ellipse(centre, axis, a, a), **kw)
        got = disc_line(pos, v, r, centre, big, clearance=m, **kw)
        assert got.inside == ref.inside == (kind == "inside")
        assert got.tau == pytest.approx(ref.tau, rel=1e-9, abs=1e-12)
        for name in ("point", "direction", "normal", "u"):
            np.testing.assert_allclose(getattr(got, name), getattr(ref, name), atol=TOL,
                                       err_msg=name)


def test_disc_line_known_answers():
    """Head-on: centre at x = 4, R = 1, r_A = m = 0.3 (K has radius 1.6, O' 1.3)."""
    s = 1.0
    line = disc_line([0, 0], [s, 0], 0.3, [4.0, 0.0], 1.0)
    assert not line.inside
    assert line.tau == pytest.approx((4.0 - 1.3) / s)  # "center": dist(p_A, O') / |v|
    np.testing.assert_allclose(line.point, [(4.0 - 1.6) / line.tau, 0.0], atol=1e-12)
    np.testing.assert_allclose(line.normal, [-1.0, 0.0], atol=1e-12)
    gap = disc_line([0, 0], [s, 0], 0.3, [4.0, 0.0], 1.0, tau="gap")
    assert gap.tau == pytest.approx(2.4) and np.allclose(gap.u, 0.0, atol=1e-12)
    rest = disc_line([0, 0], [0, 0], 0.3, [4.0, 0.0], 1.0, tau_max=8.0)
    assert rest.tau == 8.0
    np.testing.assert_allclose(rest.point, [2.4 / 8.0, 0.0], atol=1e-12)
    # inside K: push-out line n . v >= push_speed, n from the centre to p_A
    inside = disc_line([2.6, 0.5], [1.0, 1.0], 0.3, [4.0, 0.0], 1.0, push_speed=0.1)
    n = np.array([-1.4, 0.5]) / np.hypot(1.4, 0.5)
    assert inside.inside and inside.tau == 0.0
    np.testing.assert_allclose(inside.normal, n, atol=1e-12)
    assert inside.point @ n == pytest.approx(0.1)
    with pytest.raises(ValueError):
        disc_line([0, 0], [1, 0], 0.3, [4, 0], -1.0)


def test_disc_line_shares_the_orca_agent_line_geometry():
    """With alpha = 1/2 and a resting neighbour the disc line is RVO2's agent line, bit for bit."""
    rng = np.random.default_rng(RNG_SEED + 3)
    for _ in range(200):
        pos, v, r, centre, big, _ = _random_disc_case(rng, ["outside", "leg"][rng.integers(2)])
        tau = float(rng.uniform(0.2, 5.0))
        line = disc_line(pos, v, r, centre, big, clearance=0.0, tau=tau, alpha=0.5)
        P, D = np.empty((1, 2)), np.empty((1, 2))
        agent_lines(pos[0], pos[1], v[0], v[1], r, centre[None], np.zeros((1, 2)),
                    np.array([big]), 1, 1.0 / tau, 10.0, P, D, 0)
        np.testing.assert_array_equal(line.point, P[0])
        np.testing.assert_array_equal(line.direction, D[0])


def test_disc_line_velocities_stay_off_the_disc():
    """Independent check: every allowed velocity keeps p_A + t v out of K for t <= tau."""
    rng = np.random.default_rng(RNG_SEED + 4)
    t = np.linspace(0.0, 1.0, 2001)
    for _ in range(200):
        pos, v, r, centre, big, m = _random_disc_case(rng, ["outside", "leg"][rng.integers(2)])
        line = disc_line(pos, v, r, centre, big, clearance=m)
        rad = big + (r if m is None else m) + r
        s, k = np.meshgrid(np.linspace(-4.0, 4.0, 17), [0.0, 1e-3, 0.5, 2.0])
        vs = line.point + s.reshape(-1, 1) * line.direction + k.reshape(-1, 1) * line.normal
        path = pos + (line.tau * t)[None, :, None] * vs[:, None, :]
        assert np.linalg.norm(path - centre, axis=-1).min() >= rad - 1e-9
        # v_opt + u is on the VO's boundary: its path just touches K
        touch = pos + (line.tau * t)[:, None] * (v + line.u)
        assert np.linalg.norm(touch - centre, axis=-1).min() == pytest.approx(rad, abs=1e-6)


def _distances(pos, seg, discs):
    d_seg = []
    for x0, y0, x1, y1 in seg:
        a, d = np.array([x0, y0]), np.array([x1 - x0, y1 - y0])
        t = np.clip((pos - a) @ d / (d @ d), 0, 1)
        d_seg.append(np.linalg.norm(pos - a - t * d))
    d_disc = [max(np.linalg.norm(pos - c[:2]) - c[2], 0.0) for c in discs]
    return np.array(d_seg + d_disc)


def test_batch_merges_discs_and_segments_nearest_first():
    rng = np.random.default_rng(RNG_SEED + 5)
    polys = [np.array([[2, -1], [3, -1], [3, 1], [2, 1]], float), np.array([[-4, 3], [4, 3.5]])]
    discs = np.array([[-2.0, -1.0, 0.5], [0.5, -3.0, 0.8], [1.0, 1.5, 0.2], [6.0, 0.0, 2.5]])
    pos = rng.uniform(-1.5, 1.5, (8, 2))
    pos[6] = [20.0, 20.0]  # nothing in range
    pos[7] = [-2.1, -0.8]  # inside the first disc's K
    vel = rng.uniform(-1, 1, (8, 2))
    radius = rng.uniform(0.1, 0.3, 8)
    max_range = 3.5
    P, D, count = ivo_lines(pos, vel, radius, polys, max_range, discs=discs)
    seg = polygon_segments(polys)
    assert count[6] == 0 and P.shape == (8, count.max(), 2)
    n_disc_lines = 0
    for i in range(8):
        dist = _distances(pos[i], seg, discs)
        order = [k for k in np.argsort(dist, kind="stable") if dist[k] <= max_range]
        assert count[i] == len(order)
        assert np.all(np.diff(dist[order]) >= 0.0)
        for j, k in enumerate(order):
            if k < len(seg):
                e = segment_ellipse(seg[k, :2], seg[k, 2:], radius[i])
                line = ivo_line(pos[i], vel[i], radius[i], e)
            else:
                c = discs[k - len(seg)]
                line = disc_line(pos[i], vel[i], radius[i], c[:2], c[2])
                n_disc_lines += 1
            np.testing.assert_allclose(P[i, j], line.point, atol=1e-9)
            np.testing.assert_allclose(D[i, j], line.direction, atol=1e-9)
    assert n_disc_lines >= 8
    # the big disc is culled by its boundary, not its centre: 6 m away, boundary at 3.5 m
    far = ivo_lines([[0.0, 0.0]], [[0.0, 0.0]], 0.2, None, 3.5, discs=discs[3:])[2]
    near = ivo_lines([[0.0, 0.0]], [[0.0, 0.0]], 0.2, None, 3.49, discs=discs[3:])[2]
    assert far[0] == 1 and near[0] == 0
    # max_lines keeps the nearest
    P2, D2, count2 = ivo_lines(pos, vel, radius, polys, max_range, discs=discs, max_lines=2)
    assert count2.max() == 2
    np.testing.assert_array_equal(count2, np.minimum(count, 2))
    full = count2 == 2
    np.testing.assert_array_equal(P2[full], P[full, :2])
    np.testing.assert_array_equal(D2[full], D[full, :2])


def test_batch_without_discs_is_unchanged():
    """Polygon-only callers get the same arrays with or without an empty ``discs``."""
    rng = np.random.default_rng(RNG_SEED + 6)
    polys = [np.array([[2, -1], [3, -1], [3, 1], [2, 1]], float)]
    pos, vel = rng.uniform(-1, 1, (5, 2)), rng.uniform(-1, 1, (5, 2))
    base = ivo_lines(pos, vel, 0.2, polys, 4.0)
    for discs in (None, np.zeros((0, 3))):
        for a, b in zip(base, ivo_lines(pos, vel, 0.2, polys, 4.0, discs=discs), strict=True):
            np.testing.assert_array_equal(a, b)
    only = ivo_lines(pos, vel, 0.2, [], 4.0, discs=[[2.0, 0.0, 0.5]])
    assert np.all(only[2] == 1)
    with pytest.raises(ValueError):
        ivo_lines(pos, vel, 0.2, polys, 4.0, discs=[[2.0, 0.0, -0.5]])


def test_lp_with_hard_disc_lines_avoids_a_disc():
    """One robot whose v_pref crosses a disc: it goes round, at least m = r_A off the disc."""
    centre, big = np.array([3.0, 0.1]), 1.0
    r, v_max, dt = 0.25, 1.0, 0.1
    pos, vel, goal = np.array([0.0, 0.0]), np.zeros(2), np.array([6.0, 0.0])
    min_gap = np.inf
    for _ in range(300):
        to_goal = goal - pos
        pref = to_goal / max(np.linalg.norm(to_goal), 1e-9) * min(v_max, np.linalg.norm(to_goal))
        P, D, count = ivo_lines(pos[None], vel[None], r, None, 3.0, tau_min=dt,
                                discs=[[*centre, big]])
        vel = solve_lines(P, D, count, count, pref[None], np.array([v_max]))[0][0]
        pos = pos + dt * vel
        min_gap = min(min_gap, np.linalg.norm(pos - centre) - big - r)
    assert min_gap >= r - 1e-9
    assert np.linalg.norm(pos - goal) < 0.05


def test_filter_takes_circles_as_discs_in_ivo_mode():
    """Mode 'ivo' gets one disc per circle (rectangles stay edges); the run stays clear."""
    data = {
        "name": "disc", "dt": 0.1, "t_max": 30.0, "seed": 0,
        "world": {"size": [14.0, 8.0], "resolution": 10, "obstacles": [
            {"type": "circle", "center": [6.0, 4.1], "radius": 1.0},
            {"type": "rectangle", "min": [9.5, 0.5], "max": [10.5, 2.0]}]},
        "robots": {"model": "single_integrator", "radius": 0.25, "v_max": 1.0},
        "team": {"n": 1, "placement": "explicit", "poses": [[2.0, 4.0, 0.0]]},
        "formation": {"shape": "offsets", "offsets": [[0.0, 0.0]]},
        "leader": {"start": [2.0, 4.0], "goal": [12.0, 4.0], "speed": 0.6},
        "sensors": {"lidar": {"enabled": False}},
        "controllers": {"orca_nav": {"obstacles": "ivo", "speed": 0.6}},
    }
    sc = scenario_from_dict(data, "<disc>")
    flt = OrcaFilter(OrcaFilter.Params(obstacles="ivo"))
    flt.reset(sc, np.random.default_rng(0))
    np.testing.assert_array_equal(flt._ivo_discs, [[6.0, 4.1, 1.0]])
    assert flt._ivo_segments.shape == (4, 4)  # the rectangle's edges only
    assert flt._segments.shape == (32 + 4, 2, 2)  # other modes: the circle's 32-gon
    log = run_scenario(sc, "orca_nav")
    s = metrics.summary(log, sc.spec.metrics)
    assert s["collisions"] == 0 and log.meta["reached_goal"]
    # log.clearance is centre to obstacle: the centre stays out of K, r_A + m = 2 r_A
    assert log.clearance.min() >= 0.5 - 1e-9
