"""Compiled scalar geometry of :mod:`comparisons.constraints.distance` (one implementation each).

The distance builders of ``cbf`` and ``nmpc`` run at every step for every robot
(``nmpc``: every stage of its horizon) against every shape of the map. As numpy
expressions over ``(points, shapes, edges)`` tables they cost tens of small
array operations per call; here each geometry is one scalar function, looped
over by a compiled kernel. The arithmetic is the same sequence of IEEE
operations as the numpy expressions they replaced (``hypot`` and the
multiply-adds of the dot products, with no fused multiply-add), so the outputs
are bit for bit those of the vectorised formulation (checked on the common
scenarios' runs; ``docs/benchmarking.md``).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from dfcoa_opt.core.scalar_kernels import clip1


@numba.njit(cache=True, inline="always")
def unit1(vx, vy, fx, fy):  # pragma: no cover - numba
    """``(v / |v|, |v|)`` as ``(ux, uy, norm)``; ``(fx, fy)`` where ``|v|`` is not > 0."""
    norm = np.hypot(vx, vy)
    if norm > 0.0:
        return vx / norm, vy / norm, norm
    return fx, fy, norm


@numba.njit(cache=True, inline="always")
def disc1(px, py, cx, cy, r):  # pragma: no cover - numba
    """Nearest boundary point, signed distance and outward normal of a disc.

    Returns ``(qx, qy, delta, nx, ny)`` (m, m, m, -, -); a point at the centre
    gets the normal ``(1, 0)``.
    """
    nx, ny, dist = unit1(px - cx, py - cy, 1.0, 0.0)
    return cx + r * nx, cy + r * ny, dist - r, nx, ny


@numba.njit(cache=True, inline="always")
def segment_point1(px, py, ax, ay, abx, aby, den):  # pragma: no cover - numba
    """The point of the segment ``a + t ab``, ``t`` in [0, 1], nearest to ``(px, py)``.

    :func:`dfcoa_opt.core.geometry.closest_point_on_segment` in scalars: ``den`` is
    ``|ab|^2``, or 1 for a zero-length segment. Returns ``(x, y)``, m.
    """
    t = clip1(((px - ax) * abx + (py - ay) * aby) / den, 0.0, 1.0)
    return ax + t * abx, ay + t * aby


@numba.njit(cache=True, inline="always")
def crossing1(px, py, ax, ay, abx, by):  # pragma: no cover - numba
    """Whether the edge from ``(ax, ay)`` to ``(ax + abx, by)`` flips the even-odd test.

    :func:`dfcoa_opt.core.geometry.points_in_polygons`' rule: a non-horizontal edge
    that straddles ``py`` and crosses it right of ``px``.
    """
    return (ay != by and (ay <= py) != (by <= py)
            and px < ax + (py - ay) * abx / (by - ay))


@numba.njit(cache=True, inline="always")
def polygon_walk1(px, py, a, b, by_norm):  # pragma: no cover - numba
    """Nearest boundary point of one polygon, its edge, and whether the point is inside.

    ``a``, ``b``: ``(V, 2)`` edge starts and ends (padded edges have ``a = b``,
    :func:`dfcoa_opt.core.geometry.polygon_edges`). Each edge's nearest point is
    :func:`segment_point1`'s; the first edge with the smallest squared distance
    (``by_norm``: distance) wins, as ``np.argmin`` picks (a NaN counting as the
    minimum); inside by the even-odd rule of :func:`crossing1`. Returns
    ``(qx, qy, edge, inside)``.
    """
    best = -1
    bv = 0.0
    qx = qy = 0.0
    inside = False
    for e in range(a.shape[0]):
        ax, ay = a[e, 0], a[e, 1]
        abx, aby = b[e, 0] - ax, b[e, 1] - ay
        den = abx * abx + aby * aby
        cx, cy = segment_point1(px, py, ax, ay, abx, aby, den if den > 0.0 else 1.0)
        rx, ry = px - cx, py - cy
        v = rx * rx + ry * ry
        if by_norm:
            v = math.sqrt(v)
        if best < 0 or (not math.isnan(bv) and (v < bv or math.isnan(v))):
            best, bv, qx, qy = e, v, cx, cy
        if crossing1(px, py, ax, ay, abx, b[e, 1]):
            inside = not inside
    return qx, qy, best, inside


@numba.njit(cache=True, inline="always")
def polygon1(px, py, a, b):  # pragma: no cover - numba
    """Nearest boundary point, signed distance and outward normal of one polygon.

    The nearest point and the inside test of :func:`polygon_walk1` (squared
    distances); ``delta < 0`` inside, and the normal then points from the
    point to ``q`` (out of the polygon). A point on the boundary gets the
    outward normal of its edge. Returns ``(qx, qy, delta, nx, ny)``.
    """
    qx, qy, best, inside = polygon_walk1(px, py, a, b, False)
    ex, ey = b[best, 0] - a[best, 0], b[best, 1] - a[best, 1]
    ox, oy, _ = unit1(ey, -ex, 1.0, 0.0)  # CCW polygon: outward is right of the edge
    nx, ny, dist = unit1(px - qx, py - qy, ox, oy)
    if inside:
        return qx, qy, -dist, -nx, -ny
    return qx, qy, dist, nx, ny


@numba.njit(cache=True)
def pairs_kernel(position, other, delta, normal):  # pragma: no cover - numba
    """Fill ``delta`` ``(N, K)`` and ``normal`` ``(N, K, 2)`` of robot pairs (``unit1``)."""
    for i in range(other.shape[0]):
        for k in range(other.shape[1]):
            nx, ny, d = unit1(position[i, 0] - other[i, k, 0], position[i, 1] - other[i, k, 1],
                              1.0, 0.0)
            delta[i, k], normal[i, k, 0], normal[i, k, 1] = d, nx, ny


@numba.njit(cache=True)
def discs_kernel(points, discs, q, delta, normal):  # pragma: no cover - numba
    """Fill ``q``, ``delta``, ``normal`` ``(P, C, ...)`` of every disc; ``discs`` ``(P, C, 3)``."""
    for i in range(points.shape[0]):
        for c in range(discs.shape[1]):
            qx, qy, d, nx, ny = disc1(points[i, 0], points[i, 1], discs[i, c, 0],
                                      discs[i, c, 1], discs[i, c, 2])
            q[i, c, 0], q[i, c, 1], delta[i, c], normal[i, c, 0], normal[i, c, 1] = (
                qx, qy, d, nx, ny)


@numba.njit(cache=True)
def polygons_kernel(points, edge_a, edge_b, q, delta, normal):  # pragma: no cover - numba
    """Fill ``q``, ``delta``, ``normal`` ``(P, Q, ...)`` of every polygon (:func:`polygon1`)."""
    for i in range(points.shape[0]):
        for j in range(edge_a.shape[0]):
            qx, qy, d, nx, ny = polygon1(points[i, 0], points[i, 1], edge_a[j], edge_b[j])
            q[i, j, 0], q[i, j, 1], delta[i, j], normal[i, j, 0], normal[i, j, 1] = (
                qx, qy, d, nx, ny)


@numba.njit(cache=True, inline="always")
def _before(d, other):  # pragma: no cover - numba
    """Whether ``d`` goes before ``other``: ascending, NaN last (``np.argsort`` order)."""
    if math.isnan(other):
        return not math.isnan(d)
    return d < other


@numba.njit(cache=True)
def nearest_kernel(points, discs, edge_a, edge_b, reach, q, delta, normal,
                   mask):  # pragma: no cover - numba
    """The ``K`` nearest shapes of every point (discs, then polygons, stably by ``delta``).

    Fills ``q`` ``(P, K, 2)``, ``delta`` ``(P, K)``, ``normal`` ``(P, K, 2)``
    and ``mask`` ``(P, K)``: slot ``j`` holds the ``j``-th smallest signed
    distance (ties: discs before polygons, each in their order); unused slots
    (fewer shapes than ``K``) get ``delta = inf``, ``q = (0, 0)``, ``n = (1, 0)``;
    a slot farther than ``reach`` is masked out and its ``delta`` set to ``inf``.
    """
    n_k = delta.shape[1]
    if n_k == 0:  # no slot to fill (max_obstacles = 0): nothing to read or write
        return
    n_disc = discs.shape[0]
    for i in range(points.shape[0]):
        px, py = points[i, 0], points[i, 1]
        found = 0
        for s in range(n_disc + edge_a.shape[0]):
            if s < n_disc:
                qx, qy, d, nx, ny = disc1(px, py, discs[s, 0], discs[s, 1], discs[s, 2])
            else:
                qx, qy, d, nx, ny = polygon1(px, py, edge_a[s - n_disc], edge_b[s - n_disc])
            j = found
            if found < n_k:
                found += 1
            elif not _before(d, delta[i, n_k - 1]):
                continue
            else:
                j = n_k - 1
            while j > 0 and _before(d, delta[i, j - 1]):
                delta[i, j] = delta[i, j - 1]
                q[i, j, 0], q[i, j, 1] = q[i, j - 1, 0], q[i, j - 1, 1]
                normal[i, j, 0], normal[i, j, 1] = normal[i, j - 1, 0], normal[i, j - 1, 1]
                j -= 1
            delta[i, j], q[i, j, 0], q[i, j, 1], normal[i, j, 0], normal[i, j, 1] = (
                d, qx, qy, nx, ny)
        for j in range(found, n_k):
            delta[i, j], q[i, j, 0], q[i, j, 1], normal[i, j, 0], normal[i, j, 1] = (
                np.inf, 0.0, 0.0, 1.0, 0.0)
        for j in range(n_k):
            mask[i, j] = delta[i, j] <= reach
            if not mask[i, j]:
                delta[i, j] = np.inf
