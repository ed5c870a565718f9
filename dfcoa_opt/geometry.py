"""Planar geometry used everywhere in the toolkit (one implementation each).

Conventions: SI units, right-handed frame, angles counter-clockwise from +x and
wrapped to (-pi, pi]. Point arrays are ``(..., 2)`` float64.
"""

from __future__ import annotations

import functools
from collections.abc import Iterator

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


def _orient(a: FloatArray, b: FloatArray, c: FloatArray) -> FloatArray:
    """Twice the signed area of the triangles ``(a, b, c)``: > 0 when counter-clockwise."""
    return ((b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1])
            - (b[..., 1] - a[..., 1]) * (c[..., 0] - a[..., 0]))


def _in_box(a: FloatArray, b: FloatArray, c: FloatArray) -> NDArray[np.bool_]:
    """Whether ``c`` lies in the bounding box of the segments ``[a, b]`` (closed)."""
    return np.all((np.minimum(a, b) <= c) & (c <= np.maximum(a, b)), axis=-1)


def segments_intersect(p1: ArrayLike, q1: ArrayLike, p2: ArrayLike,
                       q2: ArrayLike) -> NDArray[np.bool_]:
    """Whether the closed segments ``[p1, q1]`` and ``[p2, q2]`` share a point.

    Orientation tests: a proper crossing, or an end point of one segment on
    the other (touching, collinear overlap). Exact for coordinates whose
    differences and products are exact in float64 (small integers, grid
    values); otherwise as good as the rounding of two products.

    Args:
        p1: First segments' starts ``(..., 2)``, m (all four arguments broadcast).
        q1: First segments' ends ``(..., 2)``, m.
        p2: Second segments' starts ``(..., 2)``, m.
        q2: Second segments' ends ``(..., 2)``, m.

    Returns:
        Boolean mask, the broadcast shape without the last axis.
    """
    p1, q1, p2, q2 = (np.asarray(x, dtype=float) for x in (p1, q1, p2, q2))
    d1, d2 = _orient(p2, q2, p1), _orient(p2, q2, q1)
    d3, d4 = _orient(p1, q1, p2), _orient(p1, q1, q2)
    proper = (((d1 > 0) & (d2 < 0)) | ((d1 < 0) & (d2 > 0))) & \
             (((d3 > 0) & (d4 < 0)) | ((d3 < 0) & (d4 > 0)))
    touch = (((d1 == 0) & _in_box(p2, q2, p1)) | ((d2 == 0) & _in_box(p2, q2, q1))
             | ((d3 == 0) & _in_box(p1, q1, p2)) | ((d4 == 0) & _in_box(p1, q1, q2)))
    return proper | touch


#: Edge pairs tested at once by :func:`polygon_defect` (bounds its memory on long polygons).
_PAIR_BLOCK = 1 << 18
#: Polygons up to this many vertices test every pair of edges (index arrays kept per size).
_SMALL_RING = 64


def polygon_defect(vertices: ArrayLike) -> tuple[int, int] | None:
    """Why a closed polygon is not simple, as a pair of edge indices; None when it is simple.

    Edge ``k`` runs from vertex ``k`` to vertex ``k + 1`` (the last closes the
    ring). A polygon is simple when no edge has zero length and its edges
    meet only where neighbours share a vertex. The answer is the first
    (lowest) pair that breaks this:

    - ``(k, k)``: edge ``k`` has zero length (vertex ``k + 1`` repeats vertex ``k``);
    - ``(k, k + 1)`` (or ``(0, V - 1)``): neighbouring edges fold back onto
      each other (collinear, overlapping beyond their shared vertex);
    - ``(i, j)``, not neighbours: the edges cross or touch (a vertex repeated
      further on, a vertex on another edge, a figure eight).

    Vectorised over the pairs of edges (:func:`segments_intersect`): all
    ``V (V - 1) / 2`` of them up to :data:`_SMALL_RING` vertices; for longer
    polygons only the pairs whose x-ranges overlap (edges sorted by their
    lowest x), in blocks of :data:`_PAIR_BLOCK` pairs. Orientation does not
    matter; the area's sign is :func:`polygon_signed_area`.

    Args:
        vertices: ``(V, 2)`` vertices in m, V >= 3, not repeating the first one.

    Returns:
        ``(i, j)`` with ``i <= j``, or None.
    """
    a = np.asarray(vertices, dtype=float).reshape(-1, 2)
    v = len(a)
    nxt = (np.arange(v) + 1) % v
    b = a[nxt]
    zero = np.flatnonzero((a[:, 0] == b[:, 0]) & (a[:, 1] == b[:, 1]))
    if len(zero):
        return int(zero[0]), int(zero[0])
    # neighbours k, k + 1 share vertex k + 1: they overlap iff collinear and folding back
    c = b[nxt]
    fold = np.flatnonzero((_orient(a, b, c) == 0) & (((a - b) * (c - b)).sum(axis=1) > 0))
    found = [(int(min(k, nxt[k])), int(max(k, nxt[k]))) for k in fold]
    for i, j in _edge_pairs(a, b):
        hit = np.flatnonzero(segments_intersect(a[i], b[i], a[j], b[j]))
        if len(hit):
            first = np.lexsort((j[hit], i[hit]))[0]
            found.append((int(i[hit[first]]), int(j[hit[first]])))
    return min(found) if found else None


def _edge_pairs(a: FloatArray, b: FloatArray
                ) -> Iterator[tuple[NDArray[np.intp], NDArray[np.intp]]]:
    """Blocks ``(i, j)``, ``i < j``, of the pairs of edges ``[a, b]`` that share no vertex.

    Every such pair up to :data:`_SMALL_RING` edges, else those whose closed
    x-ranges overlap (the others cannot meet).
    """
    v = len(a)
    if v <= _SMALL_RING:
        yield _ring_pairs(v)
        return
    lo, hi = np.minimum(a[:, 0], b[:, 0]), np.maximum(a[:, 0], b[:, 0])
    order = np.argsort(lo, kind="stable")
    # in lo order, edge k's candidates are k + 1 .. ends[k] - 1 (their lo <= its hi)
    ends = np.searchsorted(lo[order], hi[order], side="right")
    count = np.maximum(ends - np.arange(v) - 1, 0)
    done = np.concatenate(([0], np.cumsum(count)))
    k0 = 0
    while k0 < v:
        k1 = max(k0 + 1, int(np.searchsorted(done, done[k0] + _PAIR_BLOCK, side="right")) - 1)
        ks = np.arange(k0, min(k1, v))
        n = count[ks]
        first = np.repeat(ks, n)
        second = first + 1 + np.arange(int(n.sum())) - np.repeat(done[ks] - done[k0], n)
        i, j = order[first], order[second]
        i, j = np.minimum(i, j), np.maximum(i, j)
        keep = (j - i >= 2) & ~((i == 0) & (j == v - 1))  # edges 0 and V - 1 are neighbours
        yield i[keep], j[keep]
        k0 = int(ks[-1]) + 1


@functools.cache  # called for v <= _SMALL_RING only
def _ring_pairs(v: int) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Every pair ``(i, j)``, ``i < j``, of edges of a ring of ``v`` that share no vertex.

    Lexicographic order; kept per ``v`` (read-only arrays).
    """
    i, j = np.triu_indices(v, k=2)
    keep = ~((i == 0) & (j == v - 1))  # the closing edge and edge 0 are neighbours
    out = (i[keep], j[keep])
    for arr in out:
        arr.flags.writeable = False
    return out


def is_simple_polygon(vertices: ArrayLike) -> bool:
    """Whether a closed polygon is simple (:func:`polygon_defect` finds nothing).

    Args:
        vertices: ``(V, 2)`` vertices in m, V >= 3, not repeating the first one.
    """
    return polygon_defect(vertices) is None


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
