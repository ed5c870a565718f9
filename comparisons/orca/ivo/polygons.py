"""The improved velocity obstacle (IVO) of paper 001, section III.B (eq 8-11), for polygons.

Static discs take the closed form of :mod:`comparisons.orca.ivo.discs`, one line
per disc (see "Circular obstacles" below); :func:`ivo_lines` merges both kinds.

Each polygon edge (optionally split into pieces) is a segment ``l``; it is
enclosed by an ellipse ``O'`` (eq 8); the velocity obstacle of ``O'`` for a
horizon ``tau`` (eq 9) gives one half-plane of feasible velocities (eq 10) with
``alpha = 1``; the caller intersects the half-planes with the speed disc
``D(0, v_max)`` (eq 11) and picks the velocity nearest ``v_pref`` (eq 12) with
:func:`comparisons.orca.lp.solve_lines`, the lines being kept hard.

Decisions (the paper's words, then the reading taken here):

* **Eq 8, the ellipse.** "I is extended to an ellipse, denoted as O' ... the
  shortest distance between the expanded convex packet and the original line
  segment should be greater than r_A", ``d = min(|l - O' (+) D(p_A, r_A)|) > r_A``.
  Read literally, the formula is almost vacuous: for a convex ``O'`` holding a
  point ``q`` the distance from ``q`` to the boundary of ``O' (+) D(r)`` is
  ``r + dist(q, boundary of O')``, so ``d > r_A`` only asks ``l`` to lie inside
  ``O'``. The words ask for more: the ellipse's boundary keeps a *clearance*
  ``m`` from the segment, ``min_{q in l} dist(q, boundary of O') >= m``, i.e.
  ``O'`` contains the capsule ``l (+) D(0, m)``. The default ``m = r_A`` is the
  words' reading; ``m -> 0`` is the literal one (``O'`` shrinks to ``l``).
  The ellipse is centred at the segment midpoint with its major axis along the
  segment; with half-length ``c``, ``a = stretch (c + m)`` (``stretch >= 1``,
  default 1: the tips reach exactly ``m`` past the end points) and ``b`` is the
  smallest semi-minor axis for which the capsule fits. The capsule is the
  convex hull of the two end discs ``D(end, m)``, so it is inside the (convex)
  ellipse iff both end discs are; the distance from ``(c, 0)`` to the ellipse
  is ``b sqrt(1 - c^2 / (a^2 - b^2))`` while the nearest point is off the axis,
  and equating it to ``m`` gives ``b^2 = ((a^2 - c^2 + m^2) - sqrt(((a - m)^2 -
  c^2)((a + m)^2 - c^2))) / 2``; for ``stretch = 1`` this is ``b^2 = m (c + m)``
  (the end disc is the osculating circle at the tip, inside the ellipse by
  Blaschke's rolling theorem since ``b^2 / a`` is the ellipse's smallest
  radius of curvature). Long edges give fat ellipses (``b ~ sqrt(m c)``): split
  them with ``max_segment`` (Fig. 2's "set of line segments").
* **Eq 9, the Minkowski sum.** ``IVO = {v | exists t in [0, tau]: t v in
  O' (+) D(p_A, r_A)}``. The sum ``K = O' (+) D(r_A)`` is treated *exactly*,
  through its support function ``h_K(n) = n . c + sqrt(a^2 (n . e1)^2 +
  b^2 (n . e2)^2) + r_A`` (support functions add under Minkowski sums). Inflating
  the semi-axes to ``(a + r_A, b + r_A)`` does **not** enclose ``K`` when
  ``a != b``: its support ``sqrt((a + r)^2 n1^2 + (b + r)^2 n2^2)`` is below
  ``sqrt(a^2 n1^2 + b^2 n2^2) + r`` for every oblique ``n`` (Jensen:
  ``(a n1^2 + b n2^2)^2 < a^2 n1^2 + b^2 n2^2``). The truncated cone
  ``C = union_{s >= 1/tau} s K`` is convex with support ``h_C(n) = h_K(n) / tau``
  where ``h_K(n) <= 0`` (else ``+inf``), so the signed distance from ``v`` to
  ``C`` is ``max_{n: h_K(n) <= 0} (n . v - h_K(n) / tau)``: a 1D maximisation
  over an arc of normals whose ends are the cone's legs (tangent lines from
  ``p_A`` to ``K``, found by bisection on the sign of ``h_K``). It is solved by
  dense sampling and golden-section refinement of the best local optima, so
  ``u`` is the minimal escape to ~1e-7 m/s (the normal to ~1e-8 rad, the
  resolution of comparing values near a smooth optimum). Whatever normal
  the optimiser returns, the half-plane ``n . v >= h_K(n) / tau`` supports the
  convex ``C`` and excludes all of it: safety does not depend on optimality.
* **Eq 9, the horizon.** "tau = dist_{A|O'} / v_A^opt. It means that moving at
  the current velocity, the robot will collide within this time." Read with
  ``dist_{A|O'}`` the distance from the robot's centre ``p_A`` to ``O'``
  (``tau="center"``, default) and ``|v_A^opt|`` the speed: ``tau`` is the time
  the centre needs to reach ``O'``, so a head-on approach is inside the VO and
  the line brakes it to ``s (dist - r_A) / dist``, a speed that shrinks with
  the gap. ``tau="gap"`` uses the gap ``dist - r_A`` (the time to contact):
  then a head-on ``v_opt`` lies exactly on the cut-off and its line only
  forbids approaching faster than now; the braking is left to the floor
  ``tau_min`` and happens in the last step (documented, not the default). A
  float gives a fixed horizon. ``tau`` is clipped to ``[tau_min, tau_max]``
  (defaults 0.1 s and 10 s); a robot at rest (``|v_opt| * tau_max <= dist``)
  gets ``tau_max``. Every velocity allowed by the line stays out of ``K`` for
  ``t <= tau``, so ``tau_min >= dt`` (and a fixed ``tau >= dt``) keeps the
  centre out of ``K`` after a step of length ``dt``.
* **Eq 10, the half-plane.** ``{v | (v - (v_opt + alpha u)) . n >= 0}``, ``u``
  the smallest change of ``v_opt`` leaving the VO, ``n`` its (outward) normal,
  ``alpha = 1`` for static obstacles ("the robot ... needs to pay full
  responsibility"). As in ORCA, the same formula is used when ``v_opt`` is
  already outside the VO (``u`` then points back to the nearest VO point and
  ``v_opt`` satisfies its own line). With ``alpha = 1`` every line contains
  ``v = 0``, so the hard lines are always feasible together with the speed disc.
* **Inside ``K``** (``p_A`` in ``O' (+) D(r_A)``, every ``v`` is in the VO
  through ``t = 0``): push-out half-plane ``n . v >= push_speed`` with ``n``
  the outward normal at the boundary point of ``K`` nearest ``p_A`` (RVO2's
  obstacle-collision line for ``push_speed = 0``, the default, which keeps
  ``v = 0`` feasible; a positive value pushes out but can make opposing hard
  lines infeasible).

* **Circular obstacles** (not in the paper, whose obstacles are polygons). A
  disc ``D(c, R)`` is its own enclosing ellipse: ``O' = D(c, R + m)``, i.e.
  ``a = b = R + m`` with the clearance ``m`` above, so it is treated exactly, as
  one disc, rather than as the 32 edges of its circumscribed polygon. Its VO is
  the truncated cone of a disc and ``u`` has a closed form
  (:func:`comparisons.orca.ivo.discs.disc_pair_line`); the horizon, ``alpha``
  and the push-out line are those above, and the line equals :func:`ivo_line`'s
  for ``a = b`` to ~1e-6 (``tests/test_ivo_disc.py``).

Lines are in the convention of :mod:`comparisons.orca.lp`: a point ``p`` and a
unit direction ``d``, the allowed side on the left, ``det(d, p - v) <= 0``;
here ``d = (n_y, -n_x)`` so that the left normal of ``d`` is ``n``.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from comparisons.orca.ivo.discs import (
    TAU_CENTER,
    IvoLine,
    as_line,
    disc_distances,
    disc_pair_line,
    eq9_horizon,
    tau_rule,
)
from comparisons.orca.ivo.ellipse import Ellipse, ellipse_axes, polygon_segments
from dfcoa_opt.geometry import point_segment_distance

FloatArray = NDArray[np.float64]

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
def _pair_line(cx, cy, ex, ey, a, b, r, vx, vy, tau_rule, tau_fixed, tau_min, tau_max, alpha,
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
def _kernel(pos, vel, radius, clearance, seg, discs, order, count, stretch, tau_rule,
            tau_fixed, tau_min, tau_max, alpha, push_speed, P, D):  # pragma: no cover - numba
    """Lines of robot ``i`` against items ``order[i, :count[i]]``: segments, then discs."""
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
            _pair_line(0.5 * (x0 + x1) - pos[i, 0], 0.5 * (y0 + y1) - pos[i, 1], ex, ey, a, b,
                       radius[i], vel[i, 0], vel[i, 1], tau_rule, tau_fixed, tau_min, tau_max,
                       alpha, push_speed, buf, out)
            P[i, k, 0], P[i, k, 1] = out[0], out[1]
            D[i, k, 0], D[i, k, 1] = out[2], out[3]


# --------------------------------------------------------------------------- public API


def ivo_line(pos: ArrayLike, v_opt: ArrayLike, radius: float, ellipse: Ellipse,
             tau: float | str = "center", tau_min: float = 0.1, tau_max: float = 10.0,
             alpha: float = 1.0, push_speed: float = 0.0) -> IvoLine:
    """The IVO half-plane of one robot against one ellipse (eq 9-10).

    Args:
        pos: ``(2,)`` robot position ``p_A``, m.
        v_opt: ``(2,)`` its optimal velocity ``v_A^opt`` (usually the current one), m/s.
        radius: Robot radius ``r_A``, m.
        ellipse: The obstacle ellipse ``O'`` (e.g. from :func:`segment_ellipse`).
        tau: Horizon of eq 9: ``"center"`` (``dist(p_A, O') / |v_opt|``),
            ``"gap"`` (``(dist(p_A, O') - r_A) / |v_opt|``) or a fixed value, s.
        tau_min: Floor of the eq-9 horizon, s.
        tau_max: Cap of the eq-9 horizon (also used when ``v_opt ~ 0``), s.
        alpha: Responsibility ``alpha`` of eq 10 (1: static obstacle).
        push_speed: Outward speed required when ``p_A`` is inside ``O' (+) D(r_A)``, m/s.

    Returns:
        The line and its ingredients.
    """
    p = np.asarray(pos, dtype=float)
    v = np.asarray(v_opt, dtype=float)
    rule, fixed = tau_rule(tau)
    out = np.empty(10)
    c = ellipse.centre - p
    _pair_line(c[0], c[1], ellipse.axis[0], ellipse.axis[1], ellipse.a, ellipse.b,
               float(radius), v[0], v[1], rule, fixed, float(tau_min), float(tau_max),
               float(alpha), float(push_speed), np.empty(N_SAMPLES + 1), out)
    return as_line(out)


def ivo_lines(pos: ArrayLike, vel_opt: ArrayLike, radius: ArrayLike,
              polygons: list[ArrayLike] | FloatArray | None,
              max_range: float, tau: float | str = "center", tau_min: float = 0.1,
              tau_max: float = 10.0, clearance: float | ArrayLike | None = None,
              stretch: float = 1.0, max_segment: float | None = None,
              max_lines: int | None = None, alpha: float = 1.0, push_speed: float = 0.0,
              discs: ArrayLike | None = None
              ) -> tuple[FloatArray, FloatArray, NDArray[np.int64]]:
    """IVO half-planes (eq 10) of ``N`` robots against polygons and discs, nearest first.

    One line per segment (polygon edge or piece) and per disc whose distance to
    the robot's centre (to the segment, to the disc's boundary) is at most
    ``max_range`` (eq 11's "obstacles within the obstacle avoidance range"),
    ordered by that distance (segments before discs on ties). Use them as hard lines of
    :func:`comparisons.orca.velocities.orca_velocities` or
    :func:`comparisons.orca.lp.solve_lines` (which adds ``D(0, v_max)``, eq 11).

    Args:
        pos: ``(N, 2)`` robot positions, m.
        vel_opt: ``(N, 2)`` optimal velocities ``v_A^opt`` (usually the current ones), m/s.
        radius: ``(N,)`` or scalar robot radii ``r_A``, m.
        polygons: Obstacle vertex arrays ``(M, 2)``, m (see :func:`polygon_segments`),
            or the ``(S, 4)`` array that function returns (computed once by a
            caller that steps many times; ``max_segment`` is then not used);
            ``None``: no polygons.
        max_range: Obstacle avoidance range, m.
        tau: Horizon of eq 9: ``"center"``, ``"gap"`` or a fixed value, s (see
            :func:`ivo_line`).
        tau_min: Floor of the eq-9 horizon, s.
        tau_max: Cap of the eq-9 horizon (also used when ``v_opt ~ 0``), s.
        clearance: ``(N,)`` or scalar eq-8 clearance ``m``, m; ``None``: the radii.
        stretch: Ellipse elongation ``a / (c + m) >= 1`` (eq 8).
        max_segment: Split edges longer than this, m (``None``: whole edges).
        max_lines: Most lines per robot (the nearest kept); ``None``: all in range.
        alpha: Responsibility ``alpha`` of eq 10 (1: static obstacles).
        push_speed: Outward speed required inside ``O' (+) D(r_A)``, m/s.
        discs: ``(C, 3)`` static discs ``(cx, cy, R)``, m, each treated exactly as the
            ellipse ``O' = D(c, R + m)`` (:mod:`comparisons.orca.ivo.discs`); ``None``: none.

    Returns:
        ``(points (N, H, 2) m/s, directions (N, H, 2), count (N,))`` in the
        convention of :mod:`comparisons.orca.lp`, rows padded past ``count``
        (``H = max(count)``).

    Raises:
        ValueError: If ``stretch < 1``, a clearance or disc radius is negative or a
            fixed ``tau`` is not positive.
    """
    # fresh writable C arrays: one numba signature whatever the callers pass
    p = np.array(np.asarray(pos, dtype=float).reshape(-1, 2))
    n = len(p)
    v = np.array(np.asarray(vel_opt, dtype=float).reshape(n, 2))
    r = np.array(np.broadcast_to(np.asarray(radius, dtype=float), (n,)))
    m = np.array(np.broadcast_to(r if clearance is None else np.asarray(clearance, float), (n,)))
    disc = np.array(np.asarray([] if discs is None else discs, dtype=float).reshape(-1, 3))
    if stretch < 1.0 or np.any(m < 0.0) or np.any(disc[:, 2] < 0.0):
        raise ValueError("need stretch >= 1, clearance >= 0 and disc radii >= 0")
    rule, fixed = tau_rule(tau)
    prepared = isinstance(polygons, np.ndarray) and polygons.ndim == 2 and polygons.shape[1] == 4
    seg = np.ascontiguousarray(polygons if prepared else polygon_segments(
        [] if polygons is None else polygons, max_segment), dtype=float)
    if len(seg) + len(disc) == 0 or n == 0:
        return np.zeros((n, 0, 2)), np.zeros((n, 0, 2)), np.zeros(n, np.int64)
    dist = point_segment_distance(p[:, None, :], seg[None, :, 0:2], seg[None, :, 2:4])
    if len(disc):
        dist = np.hstack([dist.reshape(n, len(seg)), disc_distances(p, disc)])
    dist[dist > max_range] = np.inf
    order = np.argsort(dist, axis=1, kind="stable")
    count = np.isfinite(dist).sum(axis=1)
    if max_lines is not None:
        count = np.minimum(count, max_lines)
    h = int(count.max())
    order = np.ascontiguousarray(order[:, :h], dtype=np.int64)
    count = count.astype(np.int64)
    P = np.zeros((n, h, 2))
    D = np.zeros((n, h, 2))
    _kernel(p, v, r, m, seg.reshape(-1, 4), disc, order, count, float(stretch), rule, fixed,
            float(tau_min), float(tau_max), float(alpha), float(push_speed), P, D)
    return P, D, count
