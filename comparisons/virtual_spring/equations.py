"""Equations of paper 004 used by the ``virtual_spring`` controller (pure, vectorised numpy).

Shapes: ``N`` robots (rows), ``K`` neighbours or sources per robot. Every
function works row by row: row ``i`` of each output depends on row ``i`` of the
inputs only. Equation numbers are the paper's (``docs/methods/virtual_spring.md``).

* :func:`fig1_adjacency`, :func:`laplacian` -- eq 1-2 with Fig 1's topology.
* :func:`consensus_input` -- eq 4.
* :func:`leader_velocity` -- eq 6.
* :func:`spring_force` (weights: :func:`inverse_cube`) -- eq 7; :func:`disc_normals`
  and :func:`polygon_normals` turn discs and polygons into eq 7's source points
  (:func:`polygon_edge_table`: the polygons' edges, built once per scenario); the
  controller's compiled twin is :mod:`comparisons.virtual_spring.kernels`.
* :func:`leader_avoidance_velocity`, :func:`follower_avoidance_velocity` -- eq 8, eq 9.
* :func:`consistency_velocity` -- eq 10-11.
* :func:`error_trend` and :func:`dynamic_speed_limit` -- eq 12-13.
* eq 14 (the error to the ideal position): :func:`dfcoa_opt.metrics.robots.mse_per_robot`.
* eq 15-17 (conflict resolution): :mod:`comparisons.virtual_spring.conflict`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dfcoa_opt.core.geometry import polygon_edges

FloatArray = NDArray[np.float64]

#: Below this norm a vector has no direction (m or m/s).
TINY = 1e-12


def norm2(v: FloatArray) -> FloatArray:
    """``np.linalg.norm(v, axis=-1)`` of ``(..., 2)`` ``v``, bit for bit, with fewer calls."""
    x, y = v[..., 0], v[..., 1]
    return np.sqrt(x * x + y * y)


def unit_vectors(v: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Unit vectors of ``(..., 2)`` ``v`` (0 where ``|v| <= TINY``) and the norms (same unit)."""
    norm = norm2(v)
    big = norm > TINY
    return np.where(big[..., None], v / np.where(big, norm, 1.0)[..., None], 0.0), norm


def fig1_adjacency(n: int, leader_index: int) -> FloatArray:
    """Eq 1 for Fig 1's topology: every follower hears the leader and its adjacent followers.

    The followers are the robots other than ``leader_index`` in index order;
    follower ``f_k`` has ``a = 1`` towards the leader, ``f_{k-1}`` and
    ``f_{k+1}``. The leader's row is zero (it does not follow anybody).

    Args:
        n: Number of robots.
        leader_index: Index of the leader robot.

    Returns:
        ``(n, n)`` adjacency matrix ``A`` (``a_ij = 1`` when i uses j's state).
    """
    a = np.zeros((n, n))
    followers = [i for i in range(n) if i != leader_index]
    for k, f in enumerate(followers):
        a[f, leader_index] = 1.0
        if k > 0:
            a[f, followers[k - 1]] = 1.0
        if k + 1 < len(followers):
            a[f, followers[k + 1]] = 1.0
    return a


def laplacian(a: ArrayLike) -> FloatArray:
    """Eq 2: ``L = D - A`` with ``l_ii = sum_j a_ij`` (row sums) and ``l_ij = -a_ij``.

    Args:
        a: ``(n, n)`` adjacency matrix.

    Returns:
        ``(n, n)`` Laplacian; ``(L x)_i = sum_j a_ij (x_i - x_j)``.
    """
    a = np.asarray(a, dtype=float)
    return np.diag(a.sum(axis=1)) - a


def consensus_input(p_i: ArrayLike, v_i: ArrayLike, e_i: ArrayLike, p_j: ArrayLike,
                    v_j: ArrayLike, e_j: ArrayLike, a: ArrayLike,
                    velocity_weight: float = 1.0) -> FloatArray:
    """Eq 4: ``u_i = -sum_j a_ij [(p_i - p_j) - (E_i - E_j) + k_v (v_i - v_j)]``.

    Row i of ``-(L (x) I_2)`` applied to the stacked positions and velocities;
    the paper prints ``k_v = 1`` (position and velocity differences added as
    they are).

    Args:
        p_i: ``(N, 2)`` own positions, m.
        v_i: ``(N, 2)`` own velocities, m/s.
        e_i: ``(N, 2)`` own desired offsets from the leader E_i, m.
        p_j: ``(N, K, 2)`` neighbours' positions, m.
        v_j: ``(N, K, 2)`` neighbours' velocities, m/s.
        e_j: ``(N, K, 2)`` neighbours' desired offsets E_j, m.
        a: ``(N, K)`` weights a_ij (0 for padding).
        velocity_weight: ``k_v``, s.

    Returns:
        ``(N, 2)`` consensus inputs ``u_i`` (m, with velocities weighted by k_v).
    """
    p_i, v_i, e_i = (np.asarray(x, dtype=float)[:, None, :] for x in (p_i, v_i, e_i))
    diff = (p_i - np.asarray(p_j, dtype=float)) - (e_i - np.asarray(e_j, dtype=float)) \
        + velocity_weight * (v_i - np.asarray(v_j, dtype=float))
    return -(np.asarray(a, dtype=float)[..., None] * diff).sum(axis=1)


def leader_velocity(p: ArrayLike, target: ArrayLike, alpha: float, v_max: float) -> FloatArray:
    """Eq 6: ``v = alpha d (cos theta, sin theta)`` towards the target, capped at ``v_max``.

    ``d`` is the distance to the target and ``theta`` its direction; the speed
    is ``min(alpha d, v_max)`` (at the start, far from the target, it is
    ``v_max``: "v_l(0) = v_max").

    Args:
        p: ``(N, 2)`` positions, m.
        target: ``(2,)`` or ``(N, 2)`` target, m.
        alpha: Coefficient alpha, 1/s.
        v_max: Largest speed, m/s.

    Returns:
        ``(N, 2)`` velocities, m/s (0 at the target).
    """
    vec = np.asarray(target, dtype=float) - np.asarray(p, dtype=float)
    d = np.hypot(vec[..., 0], vec[..., 1])
    theta = np.arctan2(vec[..., 1], vec[..., 0])
    speed = np.minimum(alpha * d, v_max)
    return np.stack((speed * np.cos(theta), speed * np.sin(theta)), axis=-1)


def spring_force(delta: ArrayLike, mask: ArrayLike, gain: float = 1.0) -> FloatArray:
    """Eq 7: ``f = gain sum_k (p_i - p_k) / d_k^3`` (inverse cube, pointing away from k).

    ``delta[i, k] = p_i - p_k`` is the vector from source k (an obstacle point
    or another robot) to robot i and ``d_k = |delta|``, so each term has the
    magnitude ``gain / d_k^2``.

    Args:
        delta: ``(N, K, 2)`` vectors from the sources to the robot, m.
        mask: ``(N, K)`` True where the source counts.
        gain: Spring gain (the paper's 1), m^3/s so that ``f`` is a velocity.

    Returns:
        ``(N, 2)`` spring force ``(f^x, f^y)``, m/s.
    """
    delta = np.asarray(delta, dtype=float)
    d = norm2(delta)
    w = inverse_cube(d, np.asarray(mask, dtype=bool) & (d > TINY))
    return gain * (w[..., None] * delta).sum(axis=1)


def inverse_cube(d: FloatArray, use: NDArray[np.bool_]) -> FloatArray:
    """Eq 7's weights ``1 / d^3`` where ``use``, 0 elsewhere (``d`` in m, weights in m^-3).

    Only the entries used are computed (numpy's array ``power``, the same bits
    wherever an entry sits; ``d`` and ``use`` have one shape).
    """
    out = np.zeros(np.shape(d))
    out[use] = 1.0 / d[use] ** 3
    return out


def disc_normals(p: ArrayLike, centres: ArrayLike,
                 radii: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Outward unit normals and surface distances from discs to robots.

    Args:
        p: ``(N, 2)`` robot positions, m.
        centres: ``(N, K, 2)`` or ``(K, 2)`` disc centres, m.
        radii: ``(N, K)`` or ``(K,)`` disc radii, m.

    Returns:
        ``(n_hat (N, K, 2), s (N, K))``: the direction from the disc to the robot
        and the signed distance from the robot's centre to the disc's surface, m
        (negative inside).
    """
    rel = np.asarray(p, dtype=float)[:, None, :] - np.asarray(centres, dtype=float)
    n_hat, dist = unit_vectors(rel)
    return n_hat, dist - np.asarray(radii, dtype=float)


class PolygonEdges(NamedTuple):
    """Padded edges of ``Q`` static polygons (:func:`polygon_edge_table`), m.

    ``a``, ``b``: ``(Q, V, 2)`` starts and ends (:func:`dfcoa_opt.core.geometry.polygon_edges`);
    ``ab = b - a``; ``den``: ``(Q, V)`` ``|ab|^2`` (1 for zero-length edges, m^2);
    ``flat``: horizontal (and padding) edges; ``dy``: ``y_b - y_a`` (1 for flat edges).
    """

    a: FloatArray
    b: FloatArray
    ab: FloatArray
    den: FloatArray
    flat: NDArray[np.bool_]
    dy: FloatArray


def polygon_edge_table(polygons: list[ArrayLike]) -> PolygonEdges:
    """Edges of ``Q`` polygons (vertex arrays ``(V_q, 2)``, m), built once per scenario.

    The constants are those :func:`dfcoa_opt.core.geometry.closest_point_on_segment`
    and :func:`dfcoa_opt.core.geometry.points_in_polygons` compute on every call.
    """
    a, b = polygon_edges(polygons)
    ab = b - a
    den = np.einsum("...i,...i->...", ab, ab)
    flat = a[..., 1] == b[..., 1]
    return PolygonEdges(a, b, ab, np.where(den > 0.0, den, 1.0), flat,
                        np.where(flat, 1.0, b[..., 1] - a[..., 1]))


def polygon_normals(p: ArrayLike,
                    polygons: list[FloatArray] | PolygonEdges) -> tuple[FloatArray, FloatArray]:
    """Outward unit normals and signed distances from polygons to robots.

    The normal points from the polygon's nearest boundary point to the robot
    (away from the polygon when the robot is inside). Nearest points and the
    inside test are bit for bit :func:`dfcoa_opt.core.geometry.closest_point_on_segment`
    (the first nearest edge wins) and :func:`dfcoa_opt.core.geometry.points_in_polygons`.

    Args:
        p: ``(N, 2)`` robot positions, m.
        polygons: ``Q`` vertex arrays ``(V, 2)``, m, or their edges
            (:func:`polygon_edge_table`, faster when the polygons do not change).

    Returns:
        ``(n_hat (N, Q, 2), s (N, Q))``, s in m, negative inside a polygon.
    """
    p = np.asarray(p, dtype=float)
    e = polygons if isinstance(polygons, PolygonEdges) else polygon_edge_table(polygons)
    if not len(e.a):
        return np.zeros((len(p), 0, 2)), np.zeros((len(p), 0))
    pt = p[:, None, None, :]
    t = np.einsum("...i,...i->...", pt - e.a, e.ab) / e.den
    closest = e.a + np.clip(t, 0.0, 1.0)[..., None] * e.ab  # (N, Q, V, 2)
    k = np.argmin(norm2(pt - closest), axis=-1)  # (N, Q)
    nearest = closest[np.arange(len(p))[:, None], np.arange(len(e.a)), k]
    px, py, y1 = pt[..., 0], pt[..., 1], e.a[..., 1]  # even-odd rule, all edges at once
    crosses = ((y1 <= py) != (e.b[..., 1] <= py)) & ~e.flat
    inside = np.logical_xor.reduce(crosses & (px < e.a[..., 0] + (py - y1) * e.ab[..., 0] / e.dy),
                                   axis=-1)
    unit, d = unit_vectors(p[:, None, :] - nearest)
    return np.where(inside[..., None], -unit, unit), np.where(inside, -d, d)


def leader_avoidance_velocity(v_l: ArrayLike, f: ArrayLike) -> FloatArray:
    """Eq 8: ``v_l_a(t+1) = v_l + f``: the leader's eq 6 velocity plus its spring force, m/s."""
    return np.asarray(v_l, dtype=float) + np.asarray(f, dtype=float)


def follower_avoidance_velocity(v_l_a: ArrayLike, v_f: ArrayLike, f: ArrayLike) -> FloatArray:
    """Eq 9: ``v_fi_a(t+1) = v_l_a(t+1) + v_fi(t+1) + f``, m/s.

    Args:
        v_l_a: ``(N, 2)`` the leader's avoidance velocity (eq 8) as the follower knows it.
        v_f: ``(N, 2)`` the follower's consistency velocity (eq 10).
        f: ``(N, 2)`` the follower's spring force (eq 7).
    """
    return np.asarray(v_l_a, dtype=float) + np.asarray(v_f, dtype=float) \
        + np.asarray(f, dtype=float)


def consistency_velocity(u: ArrayLike, beta: float) -> FloatArray:
    """Eq 10-11: ``v_fi = beta E_s (cos phi, sin phi)``.

    ``E_s = sqrt((sum u_x)^2 + (sum u_y)^2)`` (eq 11) is the norm of the eq 4
    input ``u_i`` (whose sum over the neighbours is already taken) and ``phi`` is
    its direction, so ``v_fi = beta u_i``.

    Args:
        u: ``(N, 2)`` eq 4 inputs, m.
        beta: Adjustment coefficient beta, 1/s.

    Returns:
        ``(N, 2)`` consistency velocities, m/s.
    """
    u = np.asarray(u, dtype=float)
    e_s = np.hypot(u[..., 0], u[..., 1])
    phi = np.arctan2(u[..., 1], u[..., 0])
    return beta * e_s[..., None] * np.stack((np.cos(phi), np.sin(phi)), axis=-1)


def error_trend(e_now: ArrayLike, e_prev: ArrayLike, floor: float = 0.0) -> FloatArray:
    """Eq 12's ``epsilon = (E_i(t) - E_i(t-1)) / E_i(t)``.

    Args:
        e_now: ``(N,)`` distance errors from the ideal position now, m.
        e_prev: ``(N,)`` the same one step earlier, m.
        floor: The denominator is ``max(E_i(t), floor)`` (0: as printed), m.

    Returns:
        ``(N,)`` epsilon (0 where the denominator is 0).
    """
    e_now = np.asarray(e_now, dtype=float)
    den = np.maximum(e_now, floor)
    return np.where(den > 0.0, (e_now - np.asarray(e_prev, dtype=float))
                    / np.where(den > 0.0, den, 1.0), 0.0)


def dynamic_speed_limit(speed: ArrayLike, epsilon: ArrayLike, v_max: float,
                        floor: float = 0.0) -> FloatArray:
    """Eq 12-13: ``v(t+1) = min(v(t) + epsilon v_max, v_max)``, at least ``floor``.

    Args:
        speed: ``(N,)`` current speeds ``|v_i(t)|``, m/s.
        epsilon: ``(N,)`` eq 12's error trend.
        v_max: Largest speed, m/s.
        floor: Smallest limit (0 = a speed cannot be negative), m/s.

    Returns:
        ``(N,)`` speed limits, m/s.
    """
    raw = np.asarray(speed, dtype=float) + np.asarray(epsilon, dtype=float) * v_max
    return np.clip(raw, min(floor, v_max), v_max)


def cap_speed(v: ArrayLike, limit: ArrayLike) -> FloatArray:
    """Scale ``(N, 2)`` velocities down to ``|v| <= limit`` (``(N,)``, m/s), keeping directions."""
    v = np.asarray(v, dtype=float)
    norm = np.hypot(v[:, 0], v[:, 1])
    lim = np.asarray(limit, dtype=float)
    return v * np.where(norm > lim, lim / np.where(norm > 0.0, norm, 1.0), 1.0)[:, None]
