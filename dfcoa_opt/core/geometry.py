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
    w = wrap_angle_fast(a)
    return np.where(w == -np.pi, np.pi, w)


def wrap_angle_fast(a: ArrayLike) -> FloatArray:
    """Wrap angles to [-pi, pi) (:func:`wrap_angle` without moving -pi to pi).

    Args:
        a: Angles in rad, any shape.

    Returns:
        The wrapped angles in rad, same shape.
    """
    return np.mod(np.asarray(a, dtype=float) + np.pi, 2.0 * np.pi) - np.pi


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
    v = np.asarray(vertices, dtype=float)
    return points_in_polygons(points, v[None], np.roll(v, -1, axis=0)[None])[:, 0]


def polygon_edges(polygons: list[ArrayLike]) -> tuple[FloatArray, FloatArray]:
    """Edges of several polygons as padded ``(Q, V, 2)`` start and end arrays.

    Polygon ``q``'s edge ``k`` runs from vertex ``k`` to vertex ``k + 1``
    (closing edge last). Shorter polygons are padded with zero-length edges
    at their last vertex, which change neither nearest points nor the even-odd
    test.

    Args:
        polygons: ``Q`` vertex arrays ``(V_q, 2)`` in m.

    Returns:
        ``(a, b)``, each ``(Q, max V_q, 2)`` in m.
    """
    verts = [np.asarray(v, dtype=float).reshape(-1, 2) for v in polygons]
    width = max((len(v) for v in verts), default=0)
    a = np.zeros((len(verts), width, 2))
    b = np.zeros((len(verts), width, 2))
    for q, v in enumerate(verts):
        a[q, :len(v)], b[q, :len(v)] = v, np.roll(v, -1, axis=0)
        a[q, len(v):] = b[q, len(v):] = v[-1]
    return a, b


def points_in_polygons(points: ArrayLike, a: ArrayLike, b: ArrayLike) -> NDArray[np.bool_]:
    """Even-odd test of points against several polygons (the rule of :func:`points_in_polygon`).

    Args:
        points: ``(P, 2)`` query points in m.
        a: ``(Q, V, 2)`` edge starts in m (:func:`polygon_edges`).
        b: ``(Q, V, 2)`` edge ends in m.

    Returns:
        ``(P, Q)`` boolean mask.
    """
    p = np.asarray(points, dtype=float).reshape(-1, 2)
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    px, py = p[:, :1], p[:, 1:]
    inside = np.zeros((len(p), a.shape[0]), dtype=bool)
    for k in range(a.shape[1]):  # per edge: (P, Q) at once, memory-light for large P
        x1, y1, x2, y2 = a[:, k, 0], a[:, k, 1], b[:, k, 0], b[:, k, 1]
        flat = y1 == y2  # horizontal (or padding) edges never cross
        crosses = ((y1 <= py) != (y2 <= py)) & ~flat
        x_at = x1 + (py - y1) * (x2 - x1) / np.where(flat, 1.0, y2 - y1)
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


def clip_segments_to_box(a: ArrayLike, b: ArrayLike, box: tuple[float, float, float, float]
                         ) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
    """The parts of segments ``[a_k, b_k]`` inside an axis-aligned box (Liang-Barsky).

    Args:
        a: ``(K, 2)`` segment starts, m.
        b: ``(K, 2)`` segment ends, m.
        box: ``(xmin, ymin, xmax, ymax)``, m.

    Returns:
        ``(a', b', hit)``: the clipped ends (a segment inside the box keeps its
        ends exactly) and whether each segment meets the (closed) box at all; rows
        with ``hit`` False hold their input ends.
    """
    a, b = np.asarray(a, dtype=float).reshape(-1, 2), np.asarray(b, dtype=float).reshape(-1, 2)
    d = b - a
    lo, hi = np.zeros(len(a)), np.ones(len(a))
    hit = np.ones(len(a), dtype=bool)
    for axis, (low, high) in enumerate(((box[0], box[2]), (box[1], box[3]))):
        for p, q in ((-d[:, axis], a[:, axis] - low), (d[:, axis], high - a[:, axis])):
            parallel = p == 0.0
            hit &= ~(parallel & (q < 0.0))
            with np.errstate(divide="ignore", invalid="ignore"):
                t = np.where(parallel, 0.0, q / np.where(parallel, 1.0, p))
            lo = np.where(~parallel & (p < 0.0), np.maximum(lo, t), lo)
            hi = np.where(~parallel & (p > 0.0), np.minimum(hi, t), hi)
    hit &= lo <= hi
    start = np.where((hit & (lo > 0.0))[:, None], a + lo[:, None] * d, a)
    end = np.where((hit & (hi < 1.0))[:, None], a + hi[:, None] * d, b)
    return start, end, hit


def circle_polygon(center: ArrayLike, radius: ArrayLike, n: int = 32) -> FloatArray:
    """Counter-clockwise polygons with ``n`` vertices on circles.

    Args:
        center: ``(2,)`` centre, or ``(..., 2)`` centres, in m.
        radius: Radius (or ``(...)`` radii) in m.
        n: Number of vertices.

    Returns:
        ``(n, 2)`` vertices (``(..., n, 2)`` for several circles) in m.
    """
    a = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    unit = np.stack((np.cos(a), np.sin(a)), axis=1)
    c, r = np.asarray(center, dtype=float), np.asarray(radius, dtype=float)
    return c[..., None, :] + r[..., None, None] * unit


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


def take_rows(values: NDArray, index: NDArray[np.intp]) -> NDArray:
    """Per-row gather along axis 1: ``out[i, j, ...] = values[i, index[i, j], ...]``.

    The entries numpy's ``take_along_axis`` picks on axis 1 (with ``index``
    extended over the trailing axes), bit for bit since both only gather, without
    its argument handling (~2 against ~6 us on the small tables of the per-step
    constraint builders).

    Args:
        values: ``(P, K, ...)`` array.
        index: ``(P, J)`` integer indices into axis 1.

    Returns:
        ``(P, J, ...)`` array.
    """
    return values[np.arange(len(index))[:, None], index]
