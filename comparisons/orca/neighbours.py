"""k nearest neighbours within a radius, by a hashed cell grid (numba).

RVO2's agent query: the ``k`` nearest *other* agents with squared distance
strictly below ``max_dist**2``, nearest first; once ``k`` are found the search
radius shrinks to the farthest kept one. Points are binned into square cells of
side ``max_dist``, so the 3 x 3 block around a point's cell holds every
candidate. The cells are hashed into a table of about 2 N buckets (spatial
hashing), so the grid costs O(N) however far apart the points are (a dense
grid over the bounding box of a 10,000-agent circle of radius 8 km would need
a million cells); a bucket may hold points of other cells, which the query
skips by comparing cell coordinates. Scipy's ``cKDTree`` gives the same sets
(tested) but costs about 0.7 ms for 1000 points here, more than a whole RVO2
step (``benchmarks/bench_orca.py``).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.core.runtime.threads import kernel_threads


@numba.njit(cache=True, inline="always")
def _bucket(cx, cy, mask):  # pragma: no cover - numba
    """Hash of cell ``(cx, cy)`` into ``mask + 1`` buckets (large-prime XOR hashing)."""
    return ((cx * 73856093) ^ (cy * 19349663)) & mask


@numba.njit(cache=True)
def bin_points(pos, cell, x0, y0, mask):  # pragma: no cover - numba
    """Cells of the points and a counting sort of the points by bucket (stable)."""
    n = pos.shape[0]
    cxs = np.empty(n, np.int64)
    cys = np.empty(n, np.int64)
    key = np.empty(n, np.int64)
    start = np.zeros(mask + 2, np.int64)
    for i in range(n):
        cxs[i] = int((pos[i, 0] - x0) / cell)
        cys[i] = int((pos[i, 1] - y0) / cell)
        key[i] = _bucket(cxs[i], cys[i], mask)
        start[key[i] + 1] += 1
    for c in range(mask + 1):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    order = np.empty(n, np.int64)
    for i in range(n):
        order[fill[key[i]]] = i
        fill[key[i]] += 1
    return order, start, cxs, cys


@numba.njit(cache=True)
def knn_one(i, pos, k, max_dist, mask, order, start, cxs, cys, idx, dist_sq
            ):  # pragma: no cover - numba
    """Point ``i``'s row of :func:`knn_within` (``idx[i]``, ``dist_sq[i]``); returns its count."""
    px, py = pos[i, 0], pos[i, 1]
    cx, cy = cxs[i], cys[i]
    range_sq = max_dist * max_dist
    m = 0
    for gy in range(cy - 1, cy + 2):
        for gx in range(cx - 1, cx + 2):
            b = _bucket(gx, gy, mask)
            for s in range(start[b], start[b + 1]):
                j = order[s]
                if j == i or cxs[j] != gx or cys[j] != gy:
                    continue
                dx = px - pos[j, 0]
                dy = py - pos[j, 1]
                d = dx * dx + dy * dy
                if d >= range_sq:
                    continue
                if m < k:
                    m += 1
                slot = m - 1
                while slot > 0 and d < dist_sq[i, slot - 1]:
                    idx[i, slot] = idx[i, slot - 1]
                    dist_sq[i, slot] = dist_sq[i, slot - 1]
                    slot -= 1
                idx[i, slot] = j
                dist_sq[i, slot] = d
                if m == k:
                    range_sq = dist_sq[i, k - 1]
    return m


@numba.njit(cache=True, parallel=True)
def _query(pos, k, max_dist, mask, order, start, cxs, cys, idx, dist_sq, count
           ):  # pragma: no cover - numba
    for i in numba.prange(pos.shape[0]):
        count[i] = knn_one(i, pos, k, max_dist, mask, order, start, cxs, cys, idx, dist_sq)


def buckets(n: int) -> int:
    """The bucket mask of :func:`knn_within` for ``n`` points: >= 2 N buckets, a power of 2."""
    return (1 << max(4, math.ceil(math.log2(2 * n)))) - 1


def knn_within(pos: NDArray[np.float64], k: int, max_dist: float
               ) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The ``k`` nearest other points closer than ``max_dist``, nearest first.

    Args:
        pos: ``(N, 2)`` positions, m.
        k: Neighbours per point (>= 1).
        max_dist: Search radius, m (> 0).

    Returns:
        ``(index (N, k), count (N,))``; rows are padded with 0 past ``count``.
    """
    pos = np.ascontiguousarray(pos, dtype=np.float64)
    n = len(pos)
    idx = np.zeros((n, k), np.int64)
    count = np.zeros(n, np.int64)
    if n < 2:
        return idx, count
    lo = pos.min(axis=0)
    mask = buckets(n)
    order, start, cxs, cys = bin_points(pos, float(max_dist), lo[0], lo[1], mask)
    with kernel_threads(n):
        _query(pos, k, float(max_dist), mask, order, start, cxs, cys, idx, np.empty((n, k)),
               count)
    return idx, count
