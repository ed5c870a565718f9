"""Jump point search (JPS, Harabor & Grastien 2011), numba kernel of :mod:`.astar`.

JPS is A* on a sparse graph of *jump points* whose paths are the shortest
paths of the 8-connected grid: straight moves cost 1 cell, diagonal moves
sqrt(2) cells, and a diagonal move needs both orthogonal side cells free (no
corner cutting). Among the many equal-cost (symmetric) shortest paths it keeps
the *diagonal-first* ones, so from each expanded node it scans ahead
(``jumps``) along straight lines instead of opening every neighbour.

Rules for this movement model (derived from its move costs; with corner
cutting the rules would differ):

- A cell ``y`` reached by a straight step from ``x`` has a *forced* neighbour on
  a side where the cell beside ``x`` is blocked and the cell beside ``y`` is
  free: the side cell (and the diagonal ahead on that side) can then only be
  reached optimally through ``y``, so ``y`` is a jump point.
- A diagonal step has no forced neighbours: every cell behind it is reached at
  least as cheaply from the previous cell, whose two side cells are free.
- A diagonal jump stops at a cell from which a straight jump along either of
  its two components finds a jump point (or the goal).
- Expanding a jump point: after a straight arrival, continue straight plus the
  side move and side diagonal of every forced side; after a diagonal arrival,
  the diagonal and its two straight components; the start tries all eight.

The search over jump points is the A* of :mod:`.astar_kernel` (same indexed
4-ary heap, same equal-f LIFO stack, same deeper-first tie key). Edges are
straight or diagonal segments of exact octile length, and the octile and
Euclidean heuristics stay consistent on them, so closed jump points are never
reopened and the first goal pop is optimal. Call
:func:`dfcoa_opt.planning.astar.search` with ``method="jps"``, not this kernel.
"""

from __future__ import annotations

import numba
import numpy as np

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
)
from dfcoa_opt.planning.heap4 import heap_pop, heap_sift_up


@numba.njit(cache=True)
def _jump_straight(st, x, d, side, t):  # pragma: no cover - numba
    """Straight jump from ``x`` by offset ``d``; ``side`` = the perpendicular offset.

    Returns the first jump point (the goal ``t``, or a cell with a forced
    neighbour) or -1 at a blocked cell (the padded border included).
    """
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


@numba.njit(cache=True)
def _jump_diagonal(st, wp, x, dv, dh, t, out, k):  # pragma: no cover - numba
    """Diagonal jump from ``x`` by ``dv + dh`` (``dv = +-wp`` rows, ``dh = +-1`` columns).

    Each step needs both side cells free. A cell of the diagonal from which a
    straight jump along ``dv`` or ``dh`` finds a jump point is a jump point
    itself, but it is not returned: its straight jumps' results are written to
    ``out[k:]`` instead and the diagonal goes on (intermediate jump points
    pruned, Harabor & Grastien 2014), so they become successors of ``x``
    directly, joined to it by the diagonal-first path. Stops at a blocked step
    or at the goal ``t`` (written too). Returns the new ``k``.
    """
    while True:
        if st[x + dv] == _BLOCKED or st[x + dh] == _BLOCKED or st[x + dv + dh] == _BLOCKED:
            return k
        x += dv + dh
        if x == t:
            out[k] = x
            return k + 1
        z = _jump_straight(st, x, dv, 1, t)
        if z >= 0:
            out[k] = z
            k += 1
        z = _jump_straight(st, x, dh, wp, t)
        if z >= 0:
            out[k] = z
            k += 1


@numba.njit(cache=True)
def jps_kernel(st, wp, s, t, kind):  # pragma: no cover - numba
    """JPS on the padded flat state array ``st`` (row stride ``wp``), s -> t.

    ``st`` is 1 on blocked cells (its one-cell border included) and 0 elsewhere;
    the kernel marks open and closed cells in it. ``kind``: heuristic, octile
    (0) or Euclidean (1). A node's parent is joined to it by the diagonal-first
    octile path (a straight or diagonal segment, or a diagonal then a straight
    one); the direction of that path's last step is the node's arrival
    direction.

    Returns ``(path cells (P, 2) (row, col) unpadded, g(goal) in cells,
    expanded)``: consecutive path cells are 8-neighbours (each edge is written
    out cell by cell) and ``expanded`` counts closed jump points.
    """
    n = st.size
    n_rows = n // wp
    g = np.empty(n)
    parent = np.empty(n, np.int32)
    pos = np.empty(n, np.int32)
    hk = np.empty(n)
    hn = np.empty(n, np.int32)
    stack = np.empty(n, np.int32)
    cand = np.empty(8 * (max(n_rows, wp) + 2), np.int64)  # successors of one expansion
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
            size = heap_pop(hk, hn, pos, size)
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
                v = _jump_straight(st, u, dv, 1, t)
                if v >= 0:
                    cand[nc] = v
                    nc += 1
                for dh in (-1, 1):
                    nc = _jump_diagonal(st, wp, u, dv, dh, t, cand, nc)
            for dh in (-1, 1):
                v = _jump_straight(st, u, dh, wp, t)
                if v >= 0:
                    cand[nc] = v
                    nc += 1
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
                nc = _jump_diagonal(st, wp, u, dv, dh, t, cand, nc)
                v = _jump_straight(st, u, dv, 1, t)
                if v >= 0:
                    cand[nc] = v
                    nc += 1
                v = _jump_straight(st, u, dh, wp, t)
                if v >= 0:
                    cand[nc] = v
                    nc += 1
            else:  # straight arrival along d: straight on, and each forced side
                d = dv + dh
                side = 1 if dh == 0 else wp
                v = _jump_straight(st, u, d, side, t)
                if v >= 0:
                    cand[nc] = v
                    nc += 1
                for sd in (side, -side):
                    # forced: the cell beside the previous one blocked, the one beside u free
                    if st[u - d + sd] == _BLOCKED and st[u + sd] != _BLOCKED:
                        v = _jump_straight(st, u, sd, wp if dh == 0 else 1, t)
                        if v >= 0:
                            cand[nc] = v
                            nc += 1
                        nc = _jump_diagonal(st, wp, u, d if dh == 0 else sd,
                                            sd if dh == 0 else d, t, cand, nc)
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
            ng = gu + (abs(a - b) + min(a, b) * SQRT2)
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
            heap_sift_up(hk, hn, pos, i, fv - _DEPTH * ng, v)
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
