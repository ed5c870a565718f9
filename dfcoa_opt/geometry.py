"""Planar geometry used everywhere in the toolkit (one implementation each).

Conventions: SI units, right-handed frame, angles counter-clockwise from +x and
wrapped to (-pi, pi]. Point arrays are ``(..., 2)`` float64.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]


def wrap_angle(a: ArrayLike) -> FloatArray:
    """Wrap angles to (-pi, pi].

    Args:
        a: Angles in rad, any shape.

    Returns:
        The wrapped angles in rad, same shape.
    """
    a = np.asarray(a, dtype=float)
    w = np.mod(a + np.pi, 2.0 * np.pi) - np.pi
    return np.where(w == -np.pi, np.pi, w)


def rotate(v: ArrayLike, theta: ArrayLike) -> FloatArray:
    """Rotate 2-D vectors counter-clockwise by ``theta``.

    Args:
        v: Vectors ``(..., 2)`` in m (or any unit).
        theta: Angles in rad, broadcastable to ``v[..., 0]``.

    Returns:
        Rotated vectors, ``(..., 2)``.
    """
    v = np.asarray(v, dtype=float)
    c, s = np.cos(theta), np.sin(theta)
    return np.stack((c * v[..., 0] - s * v[..., 1], s * v[..., 0] + c * v[..., 1]), axis=-1)


def body_to_world(pose: ArrayLike, offsets: ArrayLike) -> FloatArray:
    """Map points given in a body frame to the world frame.

    This is paper 000 eq 4 / eq 30, ``x = x_c + d cos(phi + theta_c)``, written
    with Cartesian body offsets ``(d cos phi, d sin phi)``. ``pose[..., :]`` and
    ``offsets[..., :]`` broadcast against each other.

    Args:
        pose: Frame pose ``(..., 3)`` as ``(x, y, theta)`` in m, m, rad.
        offsets: Points in the body frame ``(..., 2)`` in m.

    Returns:
        World points ``(..., 2)`` in m.
    """
    pose = np.asarray(pose, dtype=float)
    return pose[..., :2] + rotate(offsets, pose[..., 2])


def polygon_signed_area(vertices: ArrayLike) -> float:
    """Signed area of a simple polygon (shoelace), positive when counter-clockwise.

    Args:
        vertices: ``(V, 2)`` vertices in m, not repeating the first one.

    Returns:
        Area in m^2, positive for counter-clockwise order.
    """
    v = np.asarray(vertices, dtype=float)
    x, y = v[:, 0], v[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def points_in_polygon(points: ArrayLike, vertices: ArrayLike) -> NDArray[np.bool_]:
    """Even-odd test of which points lie inside a polygon.

    Points exactly on an edge count as inside for axis-aligned edges that bound
    the polygon from below/left (half-open rule), which makes the rasterisation
    of rectangles whose sides lie on cell boundaries exact.

    Args:
        points: ``(P, 2)`` query points in m.
        vertices: ``(V, 2)`` polygon vertices in m (either orientation).

    Returns:
        ``(P,)`` boolean mask.
    """
    p = np.asarray(points, dtype=float).reshape(-1, 2)
    v = np.asarray(vertices, dtype=float)
    px, py = p[:, 0], p[:, 1]
    inside = np.zeros(len(p), dtype=bool)
    n = len(v)
    for k in range(n):
        x1, y1 = v[k]
        x2, y2 = v[(k + 1) % n]
        if y1 == y2:
            continue
        crosses = (y1 <= py) != (y2 <= py)
        x_at = x1 + (py - y1) * (x2 - x1) / (y2 - y1)
        inside ^= crosses & (px < x_at)
    return inside


def closest_point_on_segment(points: ArrayLike, a: ArrayLike, b: ArrayLike) -> FloatArray:
    """The point of each segment ``[a, b]`` nearest to each point.

    Args:
        points: ``(..., 2)`` points in m.
        a: Segment start ``(..., 2)`` in m, broadcastable to ``points``.
        b: Segment end ``(..., 2)`` in m, broadcastable to ``points``.

    Returns:
        ``(..., 2)`` nearest points in m, the broadcast shape.
    """
    p = np.asarray(points, dtype=float)
    a = np.asarray(a, dtype=float)
    ab = np.asarray(b, dtype=float) - a
    denom = np.einsum("...i,...i->...", ab, ab)
    t = np.einsum("...i,...i->...", p - a, ab) / np.where(denom > 0.0, denom, 1.0)
    return a + np.clip(t, 0.0, 1.0)[..., None] * ab


def point_segment_distance(points: ArrayLike, a: ArrayLike, b: ArrayLike) -> FloatArray:
    """Euclidean distance from points to segments ``[a, b]``.

    Args:
        points: ``(..., 2)`` points in m.
        a: Segment start ``(..., 2)`` in m, broadcastable to ``points``.
        b: Segment end ``(..., 2)`` in m, broadcastable to ``points``.

    Returns:
        Distances in m, the broadcast shape without the last axis.
    """
    p = np.asarray(points, dtype=float)
    return np.linalg.norm(p - closest_point_on_segment(p, a, b), axis=-1)


def circle_polygon(center: ArrayLike, radius: float, n: int = 32) -> FloatArray:
    """Counter-clockwise polygon with ``n`` vertices on a circle (for plotting).

    Args:
        center: ``(2,)`` centre in m.
        radius: Radius in m.
        n: Number of vertices.

    Returns:
        ``(n, 2)`` vertices in m.
    """
    a = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    return np.asarray(center, dtype=float) + radius * np.stack((np.cos(a), np.sin(a)), axis=1)


def pairwise_distances(points: ArrayLike) -> FloatArray:
    """All pairwise distances of a small point set (vectorised, no Python loop).

    Large teams use the KD-tree in :mod:`dfcoa_opt.sim.neighbours` instead.

    Args:
        points: ``(N, 2)`` points in m.

    Returns:
        ``(N, N)`` distances in m; the diagonal is ``+inf``.
    """
    p = np.asarray(points, dtype=float)
    d = np.sqrt(((p[:, None, :] - p[None, :, :]) ** 2).sum(-1))
    np.fill_diagonal(d, np.inf)
    return d
