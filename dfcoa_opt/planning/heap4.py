"""Indexed 4-ary min-heap on flat arrays, shared by the grid search kernels.

The heap holds ``size`` entries: keys ``hk[0:size]`` (float) and node ids
``hn[0:size]`` (int); ``pos[node]`` is the slot of ``node`` in the heap, so a
node already in it can have its key lowered in place (decrease-key) and is in
the heap at most once. The caller owns the arrays (each as long as the number
of nodes) and the ``size`` counter; these functions only move entries.
Used by :mod:`dfcoa_opt.planning.astar_kernel` and
:mod:`dfcoa_opt.planning.jps_kernel`.
"""

from __future__ import annotations

import numba


@numba.njit(cache=True)
def heap_sift_up(hk, hn, pos, i, key, node):  # pragma: no cover - numba
    """Place ``node`` with ``key`` at slot ``i`` or above, restoring the heap order.

    For a push, ``i`` is the old size (the caller increments its size); for a
    decrease-key, ``i = pos[node]`` (the new key must not be larger).
    """
    while i > 0:
        p = (i - 1) >> 2
        if key < hk[p]:
            hk[i] = hk[p]
            m = hn[p]
            hn[i] = m
            pos[m] = i
            i = p
        else:
            break
    hk[i] = key
    hn[i] = node
    pos[node] = i


@numba.njit(cache=True)
def heap_pop(hk, hn, pos, size):  # pragma: no cover - numba
    """Remove the minimum (``hn[0]``, key ``hk[0]``; read them first); returns the new size."""
    size -= 1
    if size > 0:
        lk = hk[size]
        ln = hn[size]
        i = 0
        while True:
            ch = 4 * i + 1
            if ch >= size:
                break
            best = ch
            bk = hk[ch]
            for j in range(ch + 1, min(ch + 4, size)):
                if hk[j] < bk:
                    bk = hk[j]
                    best = j
            if bk < lk:
                hk[i] = bk
                m = hn[best]
                hn[i] = m
                pos[m] = i
                i = best
            else:
                break
        hk[i] = lk
        hn[i] = ln
        pos[ln] = i
    return size
