"""k nearest neighbours within a radius, by a uniform cell grid (numba).

RVO2's agent query: the ``k`` nearest *other* agents with squared distance
strictly below ``max_dist**2``, nearest first; once ``k`` are found the search
radius shrinks to the farthest kept one. Points are binned into square cells of
side ``max_dist`` (grown when the bounding box would need more than ``4 N + 64``
cells), so the 3 x 3 block around a point's cell holds every candidate.
Scipy's ``cKDTree`` gives the same sets (tested) but costs about 0.7 ms for
1000 points here, more than a whole RVO2 step (``benchmarks/bench_orca.py``).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray


@numba.njit(cache=True)
def _bin(pos, cell, x0, y0, nx, ny):  # pragma: no cover - numba
    n = pos.shape[0]
    key = np.empty(n, np.int64)
    for i in range(n):
        cx = min(int((pos[i, 0] - x0) / cell), nx - 1)
        cy = min(int((pos[i, 1] - y0) / cell), ny - 1)
        key[i] = cy * nx + cx
    order = np.argsort(key, kind="mergesort")
    start = np.zeros(nx * ny + 1, np.int64)
    for i in range(n):
        start[key[i] + 1] += 1
    for c in range(nx * ny):
        start[c + 1] += start[c]
    return order, start


@numba.njit(cache=True, parallel=True)
def _query(pos, k, max_dist, cell, x0, y0, nx, ny, order, start, idx, dist_sq, count
           ):  # pragma: no cover - numba
    for i in numba.prange(pos.shape[0]):
        px, py = pos[i, 0], pos[i, 1]
        cx = min(int((px - x0) / cell), nx - 1)
        cy = min(int((py - y0) / cell), ny - 1)
        range_sq = max_dist * max_dist
        m = 0
        for gy in range(max(cy - 1, 0), min(cy + 2, ny)):
            for gx in range(max(cx - 1, 0), min(cx + 2, nx)):
                c = gy * nx + gx
                for s in range(start[c], start[c + 1]):
                    j = order[s]
                    if j == i:
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
        count[i] = m


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
    span = np.maximum(pos.max(axis=0) - lo, 1e-9)
    cell = float(max_dist)
    while math.ceil(span[0] / cell) * math.ceil(span[1] / cell) > 4 * n + 64:
        cell *= 2.0
    nx, ny = (max(1, math.ceil(s / cell)) for s in span)
    order, start = _bin(pos, cell, lo[0], lo[1], nx, ny)
    _query(pos, k, float(max_dist), cell, lo[0], lo[1], nx, ny, order, start, idx,
           np.empty((n, k)), count)
    return idx, count
