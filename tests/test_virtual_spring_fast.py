"""The fast paths of comparisons/virtual_spring*.py give bit for bit the reference formulas.

Oracles: :mod:`dfcoa_opt.core.geometry` (nearest points on segments, even-odd rule),
``np.linalg.norm``, the per-kind composition of eq 7 from the pure functions
(:func:`disc_normals`, :func:`polygon_normals`, :func:`spring_force`) and the
plain numpy forms of eq 15-17 (``(a * b).sum(-1)``, ``norm(...) == 0``).
"""

import numpy as np
import pytest

from comparisons.virtual_spring.conflict import conflict_resolution, vo_conflict
from comparisons.virtual_spring.equations import (
    disc_normals,
    norm2,
    polygon_edge_table,
    polygon_normals,
    spring_force,
    unit_vectors,
)
from dfcoa_opt.core.geometry import closest_point_on_segment, points_in_polygons, polygon_edges
from tests.test_virtual_spring import R, course, ctrl, observation


def same_bits(a, b):
    """Equal shapes, dtypes and bytes (signed zeros and NaN payloads included)."""
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


def random_polygons(rng, q):
    """Rectangles on a 0.5 m grid (edges on cell lines) and star-shaped polygons, m."""
    out = []
    for _ in range(q):
        c = rng.uniform(-5.0, 5.0, 2)
        if rng.random() < 0.5:
            w, h = rng.integers(1, 4, 2) * 0.5
            out.append(c.round(1) + np.array([[0.0, 0.0], [w, 0.0], [w, h], [0.0, h]]))
        else:
            ang = np.sort(rng.uniform(0.0, 2.0 * np.pi, rng.integers(3, 8)))
            out.append(c + rng.uniform(0.5, 2.0, (len(ang), 1))
                       * np.column_stack((np.cos(ang), np.sin(ang))))
    return out


def random_points(rng, polygons, n):
    """Random points, some on vertices and some with round coordinates (edge cases), m."""
    p = rng.uniform(-7.0, 7.0, (n, 2))
    verts = np.concatenate(polygons)
    p[:3] = verts[rng.integers(0, len(verts), 3)]
    p[3:6] = p[3:6].round(1)
    return p


def reference_polygon_normals(p, polygons):
    """Polygon normals straight from :mod:`dfcoa_opt.core.geometry` (the first version)."""
    a, b = polygon_edges(polygons)
    closest = closest_point_on_segment(p[:, None, None, :], a, b)
    k = np.argmin(np.linalg.norm(p[:, None, None, :] - closest, axis=-1), axis=-1)
    nearest = np.take_along_axis(closest, k[..., None, None], axis=2)[:, :, 0]
    inside = points_in_polygons(p, a, b)
    rel = p[:, None, :] - nearest
    d = np.linalg.norm(rel, axis=-1)
    unit = np.where((d > 1e-12)[..., None], rel / np.where(d > 1e-12, d, 1.0)[..., None], 0.0)
    return np.where(inside[..., None], -unit, unit), np.where(inside, -d, d)


@pytest.mark.parametrize("seed", range(4))
def test_polygon_edge_table_matches_the_geometry_module(seed):
    rng = np.random.default_rng(seed)
    inside = 0
    for _ in range(25):
        polygons = random_polygons(rng, rng.integers(1, 5))
        p = random_points(rng, polygons, 12)
        want = reference_polygon_normals(p, polygons)
        for given in (polygon_edge_table(polygons), polygons):
            got = polygon_normals(p, given)
            assert same_bits(got[0], want[0]) and same_bits(got[1], want[1])
        inside += (want[1] < 0.0).sum()
    assert inside > 0
    for given in (polygon_edge_table([]), []):
        empty = polygon_normals(np.zeros((3, 2)), given)
        assert empty[0].shape == (3, 0, 2) and empty[1].shape == (3, 0)


def test_norm2_and_unit_vectors_are_numpys_bit_for_bit():
    rng = np.random.default_rng(5)
    v = rng.normal(size=(40, 7, 2)) * 10.0 ** rng.integers(-170, 150, (40, 7, 2))
    v[rng.random(v.shape) < 0.2] = 0.0
    v[rng.random(v.shape) < 0.1] = -0.0
    assert same_bits(norm2(v), np.linalg.norm(v, axis=-1))
    norm = np.linalg.norm(v, axis=-1)
    safe = np.where(norm > 1e-12, norm, 1.0)
    want = np.where((norm > 1e-12)[..., None], v / safe[..., None], 0.0)
    unit, n = unit_vectors(v)
    assert same_bits(unit, want) and same_bits(n, norm)


def reference_conflict_resolution(p_i, v_i, p_k, v_k, conflict, share):
    """Eq 17 written with np.linalg.norm and sums over the last axis (the first version)."""
    p_i, v_i = p_i[:, None, :], v_i[:, None, :]

    def unit(x):
        n = np.linalg.norm(x, axis=-1)
        return np.where((n > 1e-12)[..., None], x / np.where(n > 1e-12, n, 1.0)[..., None], 0.0)

    axis = unit(v_i + v_k)
    for fallback in (unit(np.broadcast_to(v_i, v_k.shape)), unit(v_k)):
        none = np.linalg.norm(axis, axis=-1) == 0.0
        axis = np.where(none[..., None], fallback, axis)
    front = ((p_i - p_k) * axis).sum(-1) > 0.0
    half = 0.5 * np.linalg.norm(v_i - v_k, axis=-1) * share
    step = np.where(front, half, -half) * conflict
    return (step[..., None] * axis).sum(axis=1)


def reference_vo_conflict(d, w, radius, horizon):
    ww = (w**2).sum(-1)
    tau = np.clip((d * w).sum(-1) / np.where(ww > 0.0, ww, 1.0), 0.0, horizon)
    tau = np.where(ww > 0.0, tau, 0.0)
    return np.linalg.norm(d - tau[..., None] * w, axis=-1) <= radius


@pytest.mark.parametrize("horizon", [3.0, np.inf])
def test_eq15_17_fast_forms_match_the_plain_numpy_forms(horizon):
    rng = np.random.default_rng(7)
    for _ in range(30):
        n, k = rng.integers(1, 12), rng.integers(1, 9)
        p_i, v_i = rng.normal(size=(n, 2)), rng.normal(0.0, 0.3, (n, 2))
        p_k, v_k = p_i[:, None] + rng.normal(size=(n, k, 2)), rng.normal(0.0, 0.3, (n, k, 2))
        # the fallbacks: v_k = -v_i (no mean direction), v_i = 0, padding at the origin;
        # a robot on top of the other (neither in front)
        v_k[:, 0] = -v_i
        p_k[:, -1] = p_i
        v_i[rng.random(n) < 0.3] = 0.0
        pad = rng.random((n, k)) < 0.3
        p_k[pad], v_k[pad] = 0.0, -0.0
        radius = rng.uniform(0.2, 1.0, (n, k))
        hit = vo_conflict(p_k - p_i[:, None], v_i[:, None] - v_k, radius, horizon)
        assert same_bits(hit, reference_vo_conflict(p_k - p_i[:, None], v_i[:, None] - v_k,
                                                    radius, horizon))
        conflict = hit | (rng.random((n, k)) < 0.5)
        share = np.where(rng.random((n, k)) < 0.5, 1.0, 2.0)
        assert same_bits(conflict_resolution(p_i, v_i, p_k, v_k, conflict, share),
                         reference_conflict_resolution(p_i, v_i, p_k, v_k, conflict, share))


def reference_spring(c, obs):
    """Eq 7 composed kind by kind from the pure functions (the first version of ``spring``)."""
    pos, r, n = obs.pose[:, :2], R, obs.n
    parts = []
    if len(c._circle_r):
        parts.append((*disc_normals(pos, c._circles, c._circle_r),
                      np.ones((n, len(c._circle_r)), dtype=bool)))
    if c._polygons:
        parts.append((*polygon_normals(pos, c._polygons), np.ones((n, len(c._polygons)), bool)))
    nb, mo = obs.neighbours, obs.obstacles
    parts.append((*disc_normals(pos, nb.position, np.full(nb.index.shape, r)), nb.mask))
    parts.append((*disc_normals(pos, mo.position, mo.radius), mo.mask))
    n_hat = np.concatenate([q[0] for q in parts], axis=1)
    clear = np.concatenate([q[1] for q in parts], axis=1) - r
    mask = np.concatenate([q[2] for q in parts], axis=1) & (clear <= c.p.spring_range)
    delta = n_hat * np.maximum(clear, c.p.spring_min_distance)[..., None]
    return spring_force(delta, mask, c.p.spring_gain)


@pytest.mark.parametrize("circles, polygons", [
    ((((6.2, 7.0), 0.3), ((8.0, 10.5), 0.3)), ()),
    ((), ([[5.0, 5.0], [6.0, 5.0], [6.0, 6.0], [5.0, 6.0]],)),
    ((((6.2, 7.0), 0.3),), ([[5.0, 5.0], [6.0, 5.0], [6.0, 6.0], [5.0, 6.0]],
                            [[7.0, 4.0], [8.5, 4.5], [7.5, 6.0]])),
    ((), ()),
])
def test_controller_spring_is_the_composition_of_the_pure_functions(circles, polygons):
    sc = course(circles=circles, polygons=polygons)
    c = ctrl(scenario=sc, spring_range=2.0)
    rng = np.random.default_rng(3)
    for _ in range(20):
        pos = rng.uniform(4.0, 9.0, (5, 2))
        pos[0] = [5.5, 5.4]  # inside the square (when there is one)
        vel = rng.normal(0.0, 0.3, (5, 2))
        nb = [[j for j in range(5) if j != i and rng.random() < 0.7] for i in range(5)]
        humans = [(tuple(rng.uniform(4.0, 9.0, 2)), tuple(rng.normal(0.0, 0.3, 2)), 0.2)
                  for _ in range(rng.integers(0, 3))]
        obs = observation(pos, vel, nb, humans=humans)
        assert same_bits(c.spring(obs), reference_spring(c, obs))


def reference_resolve(c, obs, v):
    """Eq 15-17 composed from the pure functions (the numpy version of ``resolve``)."""
    nb, mo, r, p = obs.neighbours, obs.obstacles, R, c.p
    pos = obs.pose[:, :2]
    p_k = np.concatenate((nb.position, mo.position), axis=1)
    v_k = np.concatenate((nb.velocity, mo.velocity), axis=1)
    rad = np.concatenate((np.full(nb.mask.shape, 2.0 * r), mo.radius + r), axis=1)
    share = np.concatenate((np.ones(nb.mask.shape), np.full(mo.mask.shape, p.obstacle_share)),
                           axis=1)
    hit = np.concatenate((nb.mask, mo.mask), axis=1) & vo_conflict(
        p_k - pos[:, None], v[:, None] - v_k, rad + p.vo_margin, p.vo_horizon)
    if not hit.any() and not np.signbit(v[v == 0.0]).any():
        return np.zeros_like(v), hit.sum(axis=1)
    return conflict_resolution(pos, v, p_k, v_k, hit, share), hit.sum(axis=1)


@pytest.mark.parametrize("horizon", [2.0, np.inf])
def test_controller_resolve_is_the_composition_of_the_pure_functions(horizon):
    """The compiled eq 15-17 of ``resolve`` equals vo_conflict + conflict_resolution bit for
    bit: crowded and sparse teams, humans, a robot still (-0 and +0), opposite velocities,
    no conflict at all."""
    c = ctrl(scenario=course(), vo_horizon=horizon, obstacle_share=0.7)
    rng = np.random.default_rng(11)
    hits = 0
    for trial in range(40):
        spread = 1.0 if trial % 2 else 6.0
        pos = rng.uniform(0.0, spread, (5, 2))
        vel = rng.normal(0.0, 0.3, (5, 2))
        nb = [[j for j in range(5) if j != i and rng.random() < 0.7] for i in range(5)]
        humans = [(tuple(rng.uniform(0.0, spread, 2)), tuple(rng.normal(0.0, 0.3, 2)), 0.2)
                  for _ in range(rng.integers(0, 3))]
        obs = observation(pos, vel, nb, humans=humans)
        v = rng.normal(0.0, 0.4, (5, 2))
        v[0] = (-0.0, 0.0) if trial % 4 == 0 else (0.0, 0.0)
        if nb[1]:  # v_1 + v_k = 0 for a neighbour: eq 17's direction falls back to v_1's
            v[1] = -vel[nb[1][0]]
        got, want = c.resolve(obs, v), reference_resolve(c, obs, v)
        assert same_bits(got[0], want[0]) and np.array_equal(got[1], want[1])
        hits += int(want[1].sum())
    assert hits > 0
