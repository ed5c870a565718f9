"""The numba search kernel shared by traditional and improved A* (:mod:`.astar`).

An array-based, indexed 4-ary min-heap with decrease-key, an equal-f LIFO
stack, and the eq 13 terms of improved A* (zero for traditional A*). The
wrapper :func:`dfcoa_opt.planning.astar.search` pads the grid and converts
the result; call it, not this kernel.
"""

from __future__ import annotations

import math
import threading

import numba
import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.planning.postprocess import los_flat as _los_flat

SQRT2 = math.sqrt(2.0)

# Cell states in the kernel's padded flat array (a one-cell blocked border spares
# the bounds checks): FREE unseen, BLOCKED, CLOSED, OPEN (in the heap), STACKED.
_FREE, _BLOCKED, _CLOSED, _OPEN, _STACKED = 0, 1, 2, 3, 4
#: f values within this many cells of the current minimum are ties (float noise);
#: distinct path costs a + b sqrt(2) differ by far more on any practical grid.
_TIE = 1e-7
#: Heap key = f - _DEPTH g: among equal f, deeper nodes first.
_DEPTH = 1e-9


_WORK = threading.local()


def workspace(n: int) -> tuple[NDArray[np.float64], NDArray[np.int32]]:
    """Per-thread work arrays for ``n`` cells, kept between searches.

    Fresh arrays cost a page fault per 4 KiB page touched (about 2.5 ms, 10 %,
    on the 1024 x 1024 benchmark). Their contents are never read before the
    kernel writes them. Returns ``(2, n)`` float64 (g, heap keys) and ``(4, n)``
    int32 (parent, heap slot, heap nodes, stack); the arrays of the largest grid
    searched so far stay allocated (32 bytes a cell).
    """
    last = getattr(_WORK, "last", None)
    if last is not None and last[0] == n:
        return last[1]
    full = getattr(_WORK, "full", None)
    if full is None or full[0].size < 2 * n:
        full = (np.empty(2 * n), np.empty(4 * n, np.int32))
        _WORK.full = full
    views = (full[0][:2 * n].reshape(2, n), full[1][:4 * n].reshape(4, n))  # C-contiguous
    _WORK.last = (n, views)
    return views


@numba.njit(cache=True)
def _heuristic(r, c, gr, gc, kind):  # pragma: no cover - numba
    """h(n) in cells: octile (kind 0) or Euclidean (kind 1)."""
    dr = abs(r - gr)
    dc = abs(c - gc)
    if kind == 0:
        return max(dr, dc) + (SQRT2 - 1.0) * min(dr, dc)
    return math.sqrt(dr * dr + dc * dc)


@numba.njit(cache=True, inline="always")
def _sift_up(hk, hn, pos, i, key, v):  # pragma: no cover - numba
    """Place node ``v`` with ``key`` at heap slot ``i`` and sift it up (4-ary)."""
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
    hn[i] = v
    pos[v] = i


@numba.njit(cache=True)
def astar_kernel(st, wp, s, t, kind, corner_cutting, h_gain, big_r, o_gain, obst,
                 shortcut, wf, wi):  # pragma: no cover - numba
    """A* on the padded flat state array ``st`` (row stride ``wp``), s -> t.

    Returns ``(path cells (P, 2) (row, col) unpadded, g(goal), expanded)``.
    Priority (eq 12-13, cells): f = g + h - h_gain h (R - r) / R + o_gain obst[row, col],
    ``obst`` = the ``(H, W)`` eq 13 obstacle sums of the unpadded grid
    (:func:`dfcoa_opt.planning.astar.obstacle_term`; one read per node). The
    traditional search has h_gain = o_gain = 0 and then pushes
    successors whose f equals the current minimum on a LIFO stack instead of the
    heap (valid for a consistent h: nothing open has a smaller f). The heap is
    an indexed 4-ary min-heap (decrease-key), so each node is in it at most once.
    Without the stack, the new successor with the smallest key is held out of the
    heap and expanded next when its key is below the heap's minimum -- the node
    the heap would have popped, without its push and pop (eq 13 searches 2.5-5 %
    faster, the same order: a tie with the heap's minimum goes through the heap).
    ``wf``, ``wi``: the work arrays of :func:`workspace` (g, heap keys; parent,
    heap slot, heap nodes, stack), never read before written.
    """
    g = wf[0]
    hk = wf[1]
    parent = wi[0]
    pos = wi[1]
    hn = wi[2]
    stack = wi[3]
    use_stack = h_gain == 0.0 and o_gain == 0.0 and not shortcut
    offs = (wp, -wp, 1, -1, wp + 1, wp - 1, -wp + 1, -wp - 1)
    drs = (1, -1, 0, 0, 1, 1, -1, -1)
    dcs = (0, 0, 1, -1, 1, -1, 1, -1)
    side_r = (wp, wp, -wp, -wp)
    side_c = (1, -1, 1, -1)
    gr = t // wp
    gc = t - gr * wp
    sr = s // wp
    g[s] = 0.0
    parent[s] = s
    f_cur = _heuristic(sr, s - sr * wp, gr, gc, kind)
    stack[0] = s
    sp = 1
    st[s] = _STACKED
    size = 0
    expanded = 0
    found = False
    best_r = np.inf
    nxt = -1  # the next node, held out of the heap (see the docstring)
    nxt_key = 0.0
    while sp > 0 or size > 0 or nxt >= 0:
        if sp > 0:
            sp -= 1
            u = stack[sp]
        elif nxt >= 0:
            u = nxt
            nxt = -1
        else:  # pop the heap minimum
            u = hn[0]
            f_cur = hk[0] + _DEPTH * g[u]
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
        st[u] = _CLOSED
        expanded += 1
        if u == t:
            found = True
            break
        ur = u // wp
        uc = u - ur * wp
        gu = g[u]
        if shortcut:
            ru = math.sqrt((ur - gr) ** 2 + (uc - gc) ** 2)
            if ru < best_r:
                best_r = ru
                if _los_flat(st, wp, ur, uc, gr, gc, corner_cutting):
                    parent[t] = u
                    g[t] = gu + ru
                    found = True
                    break
        for k in range(8):
            v = u + offs[k]
            sv = st[v]
            if sv == _BLOCKED or sv == _CLOSED or sv == _STACKED:
                continue
            step = 1.0
            if k >= 4:
                a = st[u + side_r[k - 4]] == _BLOCKED
                b = st[u + side_c[k - 4]] == _BLOCKED
                if corner_cutting:
                    if a and b:
                        continue
                elif a or b:
                    continue
                step = SQRT2
            ng = gu + step
            if sv == _OPEN and ng >= g[v]:
                continue
            vr = ur + drs[k]
            vc = uc + dcs[k]
            g[v] = ng
            parent[v] = u
            h = _heuristic(vr, vc, gr, gc, kind)
            fv = ng + h
            if h_gain != 0.0 and big_r > 0.0:
                fv -= h_gain * h * (big_r - math.sqrt((vr - gr) ** 2 + (vc - gc) ** 2)) / big_r
            if o_gain > 0.0:
                fv += o_gain * obst[vr - 1, vc - 1]
            if use_stack and sv == _FREE and fv <= f_cur + _TIE * (1.0 + f_cur):
                st[v] = _STACKED
                stack[sp] = v
                sp += 1
                continue
            key = fv - _DEPTH * ng
            if sv == _OPEN:
                _sift_up(hk, hn, pos, pos[v], key, v)
                continue
            st[v] = _OPEN
            if not use_stack:  # keep the smallest new successor out of the heap
                if nxt < 0:
                    nxt = v
                    nxt_key = key
                    continue
                if key < nxt_key:
                    v, nxt = nxt, v
                    key, nxt_key = nxt_key, key
            _sift_up(hk, hn, pos, size, key, v)
            size += 1
        if nxt >= 0 and size > 0 and not nxt_key < hk[0]:
            _sift_up(hk, hn, pos, size, nxt_key, nxt)
            size += 1
            nxt = -1
    if not found:
        return np.zeros((0, 2), np.int64), np.inf, expanded
    return trace_path(parent, s, t, wp, 1), g[t], expanded


@numba.njit(cache=True)
def trace_path(parent, s, t, stride, pad):  # pragma: no cover - numba
    """The cells from ``s`` to ``t``, following ``parent`` back from ``t``: ``(P, 2)``.

    Node ``v`` is cell ``(v // stride - pad, v % stride - pad)`` (``pad``: the
    width of a border the search added around the grid).
    """
    count = 1
    v = t
    while v != s:
        v = parent[v]
        count += 1
    out = np.empty((count, 2), np.int64)
    v = t
    for i in range(count - 1, -1, -1):
        r = v // stride
        out[i, 0] = r - pad
        out[i, 1] = v - r * stride - pad
        v = parent[v]
    return out
