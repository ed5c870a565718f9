"""Simple polygons: segment intersection and the defects that make a ring not simple.

One implementation each, used by the obstacle shapes and the loader's checks.
Points are ``(..., 2)`` float64 arrays in m.
"""

from __future__ import annotations

import functools
from collections.abc import Iterator

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dfcoa_opt.core.geometry import FloatArray


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
    d1, d2, d3, d4 = _orientations(p1, q1, p2, q2)
    touch = (((d1 == 0) & _in_box(p2, q2, p1)) | ((d2 == 0) & _in_box(p2, q2, q1))
             | ((d3 == 0) & _in_box(p1, q1, p2)) | ((d4 == 0) & _in_box(p1, q1, q2)))
    return _proper(d1, d2, d3, d4) | touch


def segments_cross(p1: ArrayLike, q1: ArrayLike, p2: ArrayLike,
                   q2: ArrayLike) -> NDArray[np.bool_]:
    """Whether segments ``[p1, q1]`` and ``[p2, q2]`` cross properly.

    Each segment's ends lie strictly on opposite sides of the other's line:
    touching and collinear overlap do not count (:func:`segments_intersect`
    counts them). Arguments broadcast as there, ``(..., 2)`` in m.
    """
    p1, q1, p2, q2 = (np.asarray(x, dtype=float) for x in (p1, q1, p2, q2))
    return _proper(*_orientations(p1, q1, p2, q2))


def _orientations(p1: FloatArray, q1: FloatArray, p2: FloatArray, q2: FloatArray
                  ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """The four orientation tests of two segments: each end against the other's line."""
    return (_orient(p2, q2, p1), _orient(p2, q2, q1), _orient(p1, q1, p2),
            _orient(p1, q1, q2))


def _proper(d1: FloatArray, d2: FloatArray, d3: FloatArray,
            d4: FloatArray) -> NDArray[np.bool_]:
    """Strictly opposite signs in both pairs (no product: nothing to overflow)."""
    return ((((d1 > 0) & (d2 < 0)) | ((d1 < 0) & (d2 > 0)))
            & (((d3 > 0) & (d4 < 0)) | ((d3 < 0) & (d4 > 0))))


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
