"""Jump point search (JPS, Harabor & Grastien 2011), numba kernel of :mod:`.astar`.

JPS is A* on a sparse graph of *jump points* whose paths are the shortest
paths of the 8-connected grid: straight moves cost 1 cell, diagonal moves
sqrt(2) cells, and a diagonal move needs both orthogonal side cells free (no
corner cutting). Among the many equal-cost (symmetric) shortest paths it keeps
the *diagonal-first* ones, so from each expanded node it scans ahead
(*jumps*) along straight lines instead of opening every neighbour.

Rules for this movement model (derived from its move costs; with corner
cutting they would differ):

- A cell ``y`` entered by a straight step from ``x`` has a *forced* neighbour
  on a side where the cell beside ``x`` is blocked and the cell beside ``y`` is
  free: that side cell (and the diagonal ahead on that side) is reached
  optimally only through ``y``, so ``y`` is a jump point.
- A diagonal step has no forced neighbours: every cell behind it is reached at
  least as cheaply from the previous cell, whose two side cells are free.
- A cell of a diagonal jump from which a straight jump along either component
  of the diagonal finds a jump point is a jump point too. It is not put in the
  open list: the straight jumps' results become successors directly and the
  diagonal goes on ("pruning intermediate jump points", Harabor & Grastien
  2014). A node's parent is therefore joined to it by the *diagonal-first*
  octile path (a straight or diagonal segment, or a diagonal then a straight
  one), whose last step is the direction the node was reached in.
- Expanding a node: after a straight arrival, straight on plus the side move
  and the side diagonal of every forced side; after a diagonal arrival, the
  diagonal and its two straight components; the start tries all eight.

The search over jump points is the A* of :mod:`.astar_kernel`: the same
indexed 4-ary min-heap with decrease-key, the same equal-f LIFO stack and the
same deeper-first tie key. Edges have exact octile lengths, and the octile and
Euclidean heuristics stay consistent on them, so closed nodes are never
reopened and the first goal pop is optimal.

The heap's pop and the jumps are closures inside the kernel rather than
shared ``njit`` functions: a call to a compiled function that takes arrays costs
atomic reference-count updates of each array argument (measured: 9 % of the
1024 x 1024 benchmark for the heap alone, 13 % in the A* kernel), which
numba does not remove in a loop. The sift-up is shared with the A* kernel as
an ``inline="always"`` function (:func:`.astar_kernel._sift_up`; measured no
slower in either kernel, 2026-11-25). The pop is not: moved into a shared
``inline="always"`` function it made the A* kernel 6-11 % slower and this one
8 % (S1, S2 and 1024 x 1024 searches, interleaved repetitions, same paths),
so each kernel keeps its own copy. Call
:func:`dfcoa_opt.planning.astar.search` with ``method="jps"``, not these
functions.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.planning.astar_kernel import (
    _BLOCKED,
    _CLOSED,
    _DEPTH,
    _FREE,
    _OPEN,
    _STACKED,
    _TIE,
    SQRT2,
    _heuristic,
    _sift_up,
    workspace,
)


def jps_kernel(st: NDArray[np.uint8], wp: int, s: int, t: int,
               kind: int) -> tuple[NDArray[np.int64], float, int]:
    """JPS on the padded flat state array ``st`` (row stride ``wp``), from ``s`` to ``t``.

    Args:
        st: Flat ``uint8`` grid with a one-cell blocked border: 1 = blocked,
            0 = free. The search marks open and closed cells in it.
        wp: Row stride (columns + 2).
        s: Start index into ``st``.
        t: Goal index into ``st``.
        kind: Heuristic, octile (0) or Euclidean (1).

    Returns:
        ``(cells, cost, expanded)``: path cells ``(P, 2)`` (row, col) of the
        unpadded grid, consecutive cells 8-neighbours (each edge written out
        cell by cell), empty when the goal is unreachable; g(goal) in cells
        (``inf`` when unreachable); the number of closed jump points.
    """
    wf, wi = workspace(st.size)
    return _jps(st, wp, s, t, kind, wf, wi)


@numba.njit(cache=True)
def _jps(st, wp, s, t, kind, wf, wi):  # pragma: no cover - numba
    """The search of :func:`jps_kernel` with its work arrays (:func:`.astar_kernel.workspace`)."""
    g = wf[0]
    hk = wf[1]
    parent = wi[0]
    pos = wi[1]
    hn = wi[2]
    stack = wi[3]
    n_rows = st.size // wp
    cand = np.empty(8 * (max(n_rows, wp) + 2), np.int64)  # successors of one expansion

    def jump_straight(x, d, side):
        # first jump point (the goal, or a cell with a forced neighbour) from x
        # by steps d; side = the perpendicular offset; -1 at a blocked cell
        while True:
            y = x + d
            if st[y] == _BLOCKED:
                return -1
            if y == t:
                return y
            if st[x + side] == _BLOCKED and st[y + side] != _BLOCKED:
                return y
            if st[x - side] == _BLOCKED and st[y - side] != _BLOCKED:
                return y
            x = y

    def add_straight(x, d, side, k):
        v = jump_straight(x, d, side)
        if v >= 0:
            cand[k] = v
            k += 1
        return k

    def jump_diagonal(x, dv, dh, k):
        # diagonal steps dv + dh (dv = +-wp, dh = +-1) while both side cells are
        # free; writes the goal and the straight jumps' results to cand[k:]
        while True:
            if st[x + dv] == _BLOCKED or st[x + dh] == _BLOCKED or st[x + dv + dh] == _BLOCKED:
                return k
            x += dv + dh
            if x == t:
                cand[k] = x
                return k + 1
            k = add_straight(x, dv, 1, k)
            k = add_straight(x, dh, wp, k)

    def heap_pop(size):
        # remove the minimum (hn[0], key hk[0]); returns the new size
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
    while sp > 0 or size > 0:
        if sp > 0:
            sp -= 1
            u = stack[sp]
        else:
            u = hn[0]
            f_cur = hk[0] + _DEPTH * g[u]
            size = heap_pop(size)
        st[u] = _CLOSED
        expanded += 1
        if u == t:
            found = True
            break
        ur = u // wp
        uc = u - ur * wp
        nc = 0
        if u == s:
            for dv in (-wp, wp):
                nc = add_straight(u, dv, 1, nc)
                for dh in (-1, 1):
                    nc = jump_diagonal(u, dv, dh, nc)
            for dh in (-1, 1):
                nc = add_straight(u, dh, wp, nc)
        else:
            p = parent[u]
            pr = p // wp
            dr = ur - pr
            dc = uc - (p - pr * wp)
            dv = 0 if dr == 0 else (wp if dr > 0 else -wp)
            dh = 0 if dc == 0 else (1 if dc > 0 else -1)
            if dr != 0 and dc != 0 and abs(dr) != abs(dc):  # diagonal, then straight
                if abs(dr) > abs(dc):
                    dh = 0
                else:
                    dv = 0
            if dv != 0 and dh != 0:  # diagonal arrival: the diagonal and its components
                nc = jump_diagonal(u, dv, dh, nc)
                nc = add_straight(u, dv, 1, nc)
                nc = add_straight(u, dh, wp, nc)
            else:  # straight arrival along d: straight on, and each forced side
                d = dv + dh
                side = 1 if dh == 0 else wp
                nc = add_straight(u, d, side, nc)
                for sd in (side, -side):
                    # forced: the cell beside the previous one blocked, the one beside u free
                    if st[u - d + sd] == _BLOCKED and st[u + sd] != _BLOCKED:
                        nc = add_straight(u, sd, wp if dh == 0 else 1, nc)
                        if dh == 0:
                            nc = jump_diagonal(u, d, sd, nc)
                        else:
                            nc = jump_diagonal(u, sd, d, nc)
        gu = g[u]
        for k in range(nc):
            v = cand[k]
            sv = st[v]
            if sv == _CLOSED or sv == _STACKED:
                continue
            vr = v // wp
            vc = v - vr * wp
            a = abs(vr - ur)
            b = abs(vc - uc)
            ng = gu + (abs(a - b) + min(a, b) * SQRT2)  # the diagonal-first path
            if sv == _OPEN and ng >= g[v]:
                continue
            g[v] = ng
            parent[v] = u
            fv = ng + _heuristic(vr, vc, gr, gc, kind)
            if sv == _FREE and fv <= f_cur + _TIE * (1.0 + f_cur):
                st[v] = _STACKED
                stack[sp] = v
                sp += 1
                continue
            if sv == _OPEN:
                i = pos[v]
            else:
                st[v] = _OPEN
                i = size
                size += 1
            _sift_up(hk, hn, pos, i, fv - _DEPTH * ng, v)
    if not found:
        return np.zeros((0, 2), np.int64), np.inf, expanded
    count = 1
    v = t
    while v != s:
        p = parent[v]
        vr = v // wp
        pr = p // wp
        count += max(abs(vr - pr), abs(v - vr * wp - (p - pr * wp)))
        v = p
    out = np.empty((count, 2), np.int64)
    i = count - 1
    v = t
    while v != s:  # the diagonal-first path parent -> v, cell by cell from v backwards
        p = parent[v]
        vr = v // wp
        pr = p // wp
        pc = p - pr * wp
        dr = vr - pr
        dc = v - vr * wp - pc
        a = abs(dr)
        b = abs(dc)
        m = min(a, b)
        sdr = 0 if dr == 0 else (1 if dr > 0 else -1)
        sdc = 0 if dc == 0 else (1 if dc > 0 else -1)
        tr = sdr if a > b else 0  # the straight part's step
        tc = sdc if b > a else 0
        for k in range(max(a, b), 0, -1):
            j = min(k, m)
            out[i, 0] = pr + j * sdr + (k - j) * tr - 1
            out[i, 1] = pc + j * sdc + (k - j) * tc - 1
            i -= 1
        v = p
    out[0, 0] = sr - 1
    out[0, 1] = s - sr * wp - 1
    return out, g[t], expanded
