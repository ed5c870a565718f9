"""Numba core of the improved VO of polygon edges (paper 001 eq 9-10).

The method and its decisions are described in :mod:`comparisons.orca.ivo.polygons`.
:func:`pair_line` is one robot's IVO line against one ellipse (robot at the
origin): the smallest escape from the truncated cone of ``O' (+) D(r_A)``,
found by sampling the arc of normals and golden-section refinement, with eq 9's
horizon. :func:`lines_kernel` writes every robot's lines against the items of
its order table, segments (ellipses) and discs (closed form of
:mod:`comparisons.orca.ivo.discs`), one robot per ``prange`` iteration.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from comparisons.orca.ivo.discs import TAU_CENTER, disc_pair_line, eq9_horizon
from comparisons.orca.ivo.ellipse import ellipse_axes

#: Angular samples of the 1D searches over normals (then golden-section refinement).
N_SAMPLES = 128
#: Local optima of the samples that are refined.
N_REFINE = 3
#: Golden-section iterations (bracket of two samples shrinks by 0.618 each).
GOLDEN_ITERS = 60
#: Bisection iterations for the legs of the cone (pi * 2^-60 rad).
BISECT_ITERS = 60

_GOLD = 0.6180339887498949
_TWO_PI = 2.0 * math.pi


# --------------------------------------------------------------------------- numba core


@numba.njit(cache=True, inline="always")
def _phi(th, cx, cy, ex, ey, a, b, r, w, vx, vy):  # pragma: no cover - numba
    """``w h_K(n) - n . v`` at ``n = (cos th, sin th)``; ``h_K`` is the support of eq 9's sum."""
    nx = math.cos(th)
    ny = math.sin(th)
    p = nx * ex + ny * ey
    q = ny * ex - nx * ey
    h = nx * cx + ny * cy + math.sqrt(a * a * p * p + b * b * q * q) + r
    return w * h - (nx * vx + ny * vy)


@numba.njit(cache=True)
def _golden(lo, hi, cx, cy, ex, ey, a, b, r, w, vx, vy):  # pragma: no cover - numba
    """Golden-section minimum of ``_phi`` on ``[lo, hi]`` (end points included)."""
    best_x, best_f = lo, _phi(lo, cx, cy, ex, ey, a, b, r, w, vx, vy)
    f_hi = _phi(hi, cx, cy, ex, ey, a, b, r, w, vx, vy)
    if f_hi < best_f:
        best_x, best_f = hi, f_hi
    x1 = hi - _GOLD * (hi - lo)
    x2 = lo + _GOLD * (hi - lo)
    f1 = _phi(x1, cx, cy, ex, ey, a, b, r, w, vx, vy)
    f2 = _phi(x2, cx, cy, ex, ey, a, b, r, w, vx, vy)
    for _ in range(GOLDEN_ITERS):
        if f1 <= f2:
            hi, x2, f2 = x2, x1, f1
            x1 = hi - _GOLD * (hi - lo)
            f1 = _phi(x1, cx, cy, ex, ey, a, b, r, w, vx, vy)
        else:
            lo, x1, f1 = x1, x2, f2
            x2 = lo + _GOLD * (hi - lo)
            f2 = _phi(x2, cx, cy, ex, ey, a, b, r, w, vx, vy)
    if f1 < best_f:
        best_x, best_f = x1, f1
    if f2 < best_f:
        best_x, best_f = x2, f2
    return best_x, best_f


@numba.njit(cache=True)
def _argmin(lo, hi, periodic, cx, cy, ex, ey, a, b, r, w, vx, vy, buf):  # pragma: no cover
    """Global minimum of ``_phi`` over ``[lo, hi]`` (the whole circle if ``periodic``).

    ``N_SAMPLES`` samples, then golden-section refinement of the ``N_REFINE``
    lowest sampled local minima (bracket: the two neighbouring samples).
    """
    n = N_SAMPLES if periodic else N_SAMPLES + 1
    step = (hi - lo) / N_SAMPLES
    for i in range(n):
        buf[i] = _phi(lo + i * step, cx, cy, ex, ey, a, b, r, w, vx, vy)
    best_x, best_f = lo, buf[0]
    for i in range(n):
        if buf[i] < best_f:
            best_x, best_f = lo + i * step, buf[i]
    done = np.zeros(n, np.bool_)
    for _ in range(N_REFINE):
        pick, pick_f = -1, np.inf
        for i in range(n):
            if done[i]:
                continue
            if periodic:
                left, right = buf[(i - 1) % n], buf[(i + 1) % n]
            else:
                left = buf[i - 1] if i > 0 else np.inf
                right = buf[i + 1] if i < n - 1 else np.inf
            if buf[i] <= left and buf[i] <= right and buf[i] < pick_f:
                pick, pick_f = i, buf[i]
        if pick < 0:
            break
        done[pick] = True
        x_lo = lo + (pick - 1) * step
        x_hi = lo + (pick + 1) * step
        if not periodic:
            x_lo = max(x_lo, lo)
            x_hi = min(x_hi, hi)
        x, f = _golden(x_lo, x_hi, cx, cy, ex, ey, a, b, r, w, vx, vy)
        if f < best_f:
            best_x, best_f = x, f
    return best_x, best_f


@numba.njit(cache=True)
def _arc_end(th_in, th_out, cx, cy, ex, ey, a, b, r):  # pragma: no cover - numba
    """Last normal angle with ``h_K <= 0`` between ``th_in`` (<= 0) and ``th_out`` (> 0)."""
    for _ in range(BISECT_ITERS):
        mid = 0.5 * (th_in + th_out)
        if _phi(mid, cx, cy, ex, ey, a, b, r, 1.0, 0.0, 0.0) <= 0.0:
            th_in = mid
        else:
            th_out = mid
    return th_in


@numba.njit(cache=True)
def pair_line(cx, cy, ex, ey, a, b, r, vx, vy, tau_rule, tau_fixed, tau_min, tau_max, alpha,
              push_speed, buf, out):  # pragma: no cover - numba
    """One IVO line (eq 9-10), robot at the origin, ellipse centre ``(cx, cy)`` relative.

    ``out``: point (2), direction (2), tau, inside flag, u (2), normal (2).
    """
    th0, h_min = _argmin(0.0, _TWO_PI, True, cx, cy, ex, ey, a, b, r, 1.0, 0.0, 0.0, buf)
    if h_min >= 0.0:  # p_A in O' (+) D(r_A): push out along the nearest normal
        nx, ny = math.cos(th0), math.sin(th0)
        offset = push_speed
        tau = 0.0
        inside = 1.0
    else:
        dist = -h_min + (r if tau_rule == TAU_CENTER else 0.0)  # eq 9's dist_{A|O'}
        tau = eq9_horizon(tau_rule, tau_fixed, dist, vx, vy, tau_min, tau_max)
        lo = _arc_end(th0, th0 - math.pi, cx, cy, ex, ey, a, b, r)  # the legs
        hi = _arc_end(th0, th0 + math.pi, cx, cy, ex, ey, a, b, r)
        th, _ = _argmin(lo, hi, False, cx, cy, ex, ey, a, b, r, 1.0 / tau, vx, vy, buf)
        nx, ny = math.cos(th), math.sin(th)
        h = _phi(th, cx, cy, ex, ey, a, b, r, 1.0, 0.0, 0.0)
        offset = min(h, 0.0) / tau  # h_C(n) = h_K(n) / tau on the arc
        inside = 0.0
    gap = offset - (nx * vx + ny * vy)  # u = gap n (eq 10)
    out[0] = vx + alpha * gap * nx
    out[1] = vy + alpha * gap * ny
    out[2] = ny
    out[3] = -nx
    out[4] = tau
    out[5] = inside
    out[6] = gap * nx
    out[7] = gap * ny
    out[8] = nx
    out[9] = ny


@numba.njit(cache=True, parallel=True)
def lines_kernel(pos, vel, radius, clearance, seg, discs, order, count, stretch, tau_rule,
                 tau_fixed, tau_min, tau_max, alpha, push_speed, P, D):  # pragma: no cover
    """Lines of robot ``i`` against items ``order[i, :count[i]]``: segments, then discs.

    An item ``s < len(seg)`` is segment ``s`` (its eq-8 ellipse), any other the
    disc ``s - len(seg)``.
    """
    n_seg = seg.shape[0]
    for i in numba.prange(pos.shape[0]):
        buf = np.empty(N_SAMPLES + 1)
        out = np.empty(10)
        for k in range(count[i]):
            s = order[i, k]
            if s >= n_seg:  # a disc: closed form (ivo_disc)
                c = s - n_seg
                disc_pair_line(discs[c, 0] - pos[i, 0], discs[c, 1] - pos[i, 1],
                               discs[c, 2] + clearance[i], radius[i], vel[i, 0], vel[i, 1],
                               tau_rule, tau_fixed, tau_min, tau_max, alpha, push_speed, out)
                P[i, k, 0], P[i, k, 1] = out[0], out[1]
                D[i, k, 0], D[i, k, 1] = out[2], out[3]
                continue
            x0, y0, x1, y1 = seg[s, 0], seg[s, 1], seg[s, 2], seg[s, 3]
            length = math.sqrt((x1 - x0) ** 2 + (y1 - y0) ** 2)
            ex, ey = (x1 - x0) / length, (y1 - y0) / length
            a, b = ellipse_axes(0.5 * length, clearance[i], stretch)
            pair_line(0.5 * (x0 + x1) - pos[i, 0], 0.5 * (y0 + y1) - pos[i, 1], ex, ey, a, b,
                      radius[i], vel[i, 0], vel[i, 1], tau_rule, tau_fixed, tau_min, tau_max,
                      alpha, push_speed, buf, out)
            P[i, k, 0], P[i, k, 1] = out[0], out[1]
            D[i, k, 0], D[i, k, 1] = out[2], out[3]
