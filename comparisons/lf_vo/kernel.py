"""Fast sampled velocity obstacle of ``lf_vo``: rollout, clearance and choice in numba kernels.

:func:`vo_clearance` returns the same ``(N, S)`` clearances as
``path_clearance(rollout(...), ...)`` of :mod:`comparisons.lf_vo.equations` (the
numpy reference), without the dense ``(N, S, H, Q)`` arrays. Per robot:

1. **Rollout.** Every sample's path is integrated with the same floating-point
   operations as :func:`comparisons.lf_vo.equations.rollout` (heading
   ``theta + w * t_mid``, increments ``(v * step) * cos``, sequential sums).
   ``cos``/``sin`` are reused where the heading is bitwise the same: samples
   with the same ``w`` (the grid repeats the ``w`` values for every ``v``,
   ``w_stride`` apart) and steps after ``turn_time``. The rollout is extended
   lazily, only as far as the obstacles still checked need it.
2. **Per-obstacle horizon.** Obstacle ``q`` is checked over its first
   ``limit_q`` steps (``lf_vo``: the other robots over ``robot_horizon``, the
   humans and static discs over ``horizon``), so one call gives
   ``min(path_clearance(pts, ...), path_clearance(pts[:, :, :limit], ...))``.
3. **Exact minimum with culling.** The minimum over steps of ``|p_k - f_k| - r``
   is ``sqrt(min_k |p_k - f_k|^2) - r``: ``sqrt`` and ``- r`` are correctly
   rounded, hence monotone, so taking the square root once per obstacle gives
   bit for bit the reference's minimum. A sample moves at most ``|v| t_k`` and
   an obstacle ``|u| t_k`` by the instant ``t_k = step * (k + 1)``, so every
   gap of obstacle ``q`` at step ``k`` is at least
   ``lb_k = d_q - (v_max + |u_q|) t_k - r_q`` (``d_q``: distance now,
   ``v_max``: the robot's largest ``|v|``). Obstacles are visited by
   increasing ``lb`` at their last step, the first one alone and then
   :data:`CHUNK` at a time in one pass over the rollout. Before each batch,
   once that bound of the next obstacle is at least the largest current
   clearance of the robot's samples, neither it nor any later obstacle can
   lower any sample's minimum, and the loop stops. Within a batch, an
   obstacle's first steps whose ``lb_k`` is at least that largest clearance are
   skipped for the same reason. Skipped gaps are never below the minimum kept,
   so the result is the exact minimum over all obstacles and steps (``inf``
   when a robot has no real obstacle, as in the reference). The bounds are
   lowered by :data:`SLACK` to absorb rounding.

:func:`vo_choose` picks each robot's sample as ``lf_vo`` does with the numpy
reference (:func:`comparisons.lf_vo.equations.vo_cost`, ``argmin`` over the safe
samples, ``argmax`` of the clearance when none is safe), with the same
floating-point operations per cost, computed for the safe samples only.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: Margin subtracted from every culling bound (covers rounding of the gaps), m.
SLACK = 1e-6

#: Obstacles checked together in one pass over the rollout (after the first one).
CHUNK = 8


@numba.njit(cache=True)
def _roots(w, w_stride):  # pragma: no cover - numba
    """For each sample, the first sample ``w_stride`` steps back with the bitwise same ``w``."""
    n_s = w.shape[0]
    root = np.empty(n_s, np.int64)
    for s in range(n_s):
        root[s] = s
        if w_stride > 0 and s >= w_stride and w[s - w_stride] == w[s]:
            root[s] = root[s - w_stride]
    return root


@numba.njit(cache=True)
def _extend(x, y, theta, w, t_mid, root, vs, cs, sn, ax, ay, px, py, k_from,
            k_to):  # pragma: no cover - numba
    """Fill rows ``k_from..k_to - 1`` of ``px, py`` ``(H, S)``, continuing the sums ``ax, ay``.

    ``cs, sn`` hold the cos/sin of the headings of step ``k_from - 1``.
    """
    n_s = vs.shape[0]
    for k in range(k_from, k_to):
        if k == 0 or t_mid[k] != t_mid[k - 1]:  # else: same heading as the step before
            for s in range(n_s):
                r = root[s]
                if r == s:
                    h = theta + w[s] * t_mid[k]
                    cs[s] = math.cos(h)
                    sn[s] = math.sin(h)
                else:
                    cs[s] = cs[r]
                    sn[s] = sn[r]
        if k == 0:
            for s in range(n_s):
                ax[s] = vs[s] * cs[s]
                ay[s] = vs[s] * sn[s]
        else:
            for s in range(n_s):
                ax[s] = ax[s] + vs[s] * cs[s]
                ay[s] = ay[s] + vs[s] * sn[s]
        for s in range(n_s):
            px[k, s] = x + ax[s]
            py[k, s] = y + ay[s]


@numba.njit(cache=True)
def _robot(x, y, theta, v, w, step, t_mid, w_stride, obst, lim, n_obst,
           clear):  # pragma: no cover - numba
    """Exact min clearance of one robot's samples against ``obst[:n_obst]`` (cx, cy, ux, uy, r).

    Obstacle ``q`` is checked over the steps ``0..lim[q] - 1``.
    """
    n_s, n_h = v.shape[0], t_mid.shape[0]
    for s in range(n_s):
        clear[s] = np.inf
    if n_obst == 0:
        return
    v_max = 0.0
    for s in range(n_s):
        v_max = max(v_max, abs(v[s]))
    d_now = np.empty(n_obst)
    speed = np.empty(n_obst)
    bound = np.empty(n_obst)
    for q in range(n_obst):
        d_now[q] = math.sqrt((x - obst[q, 0]) ** 2 + (y - obst[q, 1]) ** 2)
        speed[q] = math.sqrt(obst[q, 2] ** 2 + obst[q, 3] ** 2)
        bound[q] = d_now[q] - (v_max + speed[q]) * (step * lim[q]) - obst[q, 4] - SLACK
    order = np.argsort(bound)
    # the rollout, filled up to row k_done - 1 as the obstacles need it
    root = _roots(w, w_stride)
    vs = np.empty(n_s)
    for s in range(n_s):
        vs[s] = v[s] * step
    cs, sn, ax, ay = np.empty(n_s), np.empty(n_s), np.empty(n_s), np.empty(n_s)
    px = np.empty((n_h, n_s))
    py = np.empty((n_h, n_s))
    k_done = 0
    chunk = np.empty(CHUNK, np.int64)
    k_first = np.empty(CHUNK, np.int64)
    d2min = np.empty((CHUNK, n_s))
    worst = np.inf  # largest clearance over the samples so far
    j = 0
    while j < n_obst:
        # the next obstacles by increasing bound (one first, to get a finite `worst`)
        m = 0
        size = 1 if j == 0 else CHUNK
        while j < n_obst and m < size:
            q = order[j]
            if bound[q] >= worst:
                j = n_obst  # this and every later one: gap >= bound >= worst >= clear[s]
                break
            j += 1
            k0 = 0
            rate = v_max + speed[q]
            if worst < np.inf and rate > 0.0:
                # steps with step * (k + 1) <= t_free have lb_k >= worst: skip (one less, safe)
                t_free = (d_now[q] - obst[q, 4] - SLACK - worst) / rate
                k0 = min(max(int(math.floor(t_free / step)) - 1, 0), lim[q])
            if k0 >= lim[q]:
                continue  # no step left to check
            chunk[m] = q
            k_first[m] = k0
            m += 1
        if m == 0:
            continue
        k_lo, k_hi = n_h, 0
        for c in range(m):
            k_lo = min(k_lo, k_first[c])
            k_hi = max(k_hi, lim[chunk[c]])
            for s in range(n_s):
                d2min[c, s] = np.inf
        if k_hi > k_done:
            _extend(x, y, theta, w, t_mid, root, vs, cs, sn, ax, ay, px, py, k_done, k_hi)
            k_done = k_hi
        for k in range(k_lo, k_hi):
            t = step * (k + 1.0)
            for c in range(m):
                q = chunk[c]
                if k < k_first[c] or k >= lim[q]:
                    continue
                fx = obst[q, 0] + t * obst[q, 2]
                fy = obst[q, 1] + t * obst[q, 3]
                for s in range(n_s):
                    dx = px[k, s] - fx
                    dy = py[k, s] - fy
                    d2 = dx * dx + dy * dy
                    if d2 < d2min[c, s]:
                        d2min[c, s] = d2
        for c in range(m):
            reach = obst[chunk[c], 4]
            for s in range(n_s):
                g = math.sqrt(d2min[c, s]) - reach
                if g < clear[s]:
                    clear[s] = g
        worst = -np.inf
        for s in range(n_s):
            worst = max(worst, clear[s])


@numba.njit(cache=True, parallel=True)
def _batch(pose, v, w, step, t_mid, w_stride, static, pos, vel, reach, mask, limit,
           clear):  # pragma: no cover - numba
    """Fill ``clear`` ``(N, S)``: every robot's static discs and real per-robot obstacles."""
    n, n_stat, n_dyn = pose.shape[0], static.shape[0], pos.shape[1]
    n_h = t_mid.shape[0]
    for i in numba.prange(n):
        obst = np.empty((n_stat + n_dyn, 5))
        lim = np.empty(n_stat + n_dyn, np.int64)
        m = 0
        for q in range(n_stat):
            for c in range(5):
                obst[m, c] = static[q, c]
            lim[m] = n_h
            m += 1
        for q in range(n_dyn):
            if mask[i, q] and limit[q] > 0:
                obst[m, 0] = pos[i, q, 0]
                obst[m, 1] = pos[i, q, 1]
                obst[m, 2] = vel[i, q, 0]
                obst[m, 3] = vel[i, q, 1]
                obst[m, 4] = reach[i, q]
                lim[m] = limit[q]
                m += 1
        _robot(pose[i, 0], pose[i, 1], pose[i, 2], v[i], w[i], step, t_mid, w_stride, obst, lim,
               m, clear[i])


def vo_clearance(pose: ArrayLike, v: ArrayLike, w: ArrayLike, step: float, steps: int,
                 turn_time: float, centres: ArrayLike, velocities: ArrayLike, reach: ArrayLike,
                 mask: ArrayLike, static_centres: ArrayLike | None = None,
                 static_reach: ArrayLike | None = None, w_stride: int = 0,
                 limit: ArrayLike | None = None) -> FloatArray:
    """``path_clearance(rollout(pose, v, w, step, steps, turn_time), step, ...)``, fast.

    Args:
        pose: ``(N, 3)`` current poses (x m, y m, theta rad).
        v: ``(N, S)`` sampled speeds, m/s.
        w: ``(N, S)`` sampled turn rates, rad/s.
        step: Prediction step, s.
        steps: Number of prediction steps H.
        turn_time: How long the sample's turn rate is held, s.
        centres: ``(N, Q, 2)`` per-robot obstacle centres now, m.
        velocities: ``(N, Q, 2)`` obstacle velocities, m/s.
        reach: ``(N, Q)`` collision distance between centres, m.
        mask: ``(N, Q)`` True where obstacle q is real (False = padding).
        static_centres: ``(C, 2)`` static discs seen by every robot, m (optional).
        static_reach: ``(C,)`` their collision distances, m.
        w_stride: Samples ``s`` and ``s - w_stride`` often share ``w`` (a speed-major
            grid with ``w_stride`` turn rates); only a speed-up, any value is exact.
        limit: ``(Q,)`` number of prediction steps checked against column ``q`` of the
            per-robot obstacles (clipped to ``0..steps``; default ``steps``): the
            result is then the minimum of the reference over the columns' own
            first ``limit_q`` steps (static discs: all ``steps``).

    Returns:
        ``(N, S)`` clearance in m (``inf`` when the robot has no obstacle), equal
        to the reference's.
    """
    p = np.ascontiguousarray(pose, dtype=np.float64)
    vv = np.ascontiguousarray(v, dtype=np.float64)
    ww = np.ascontiguousarray(w, dtype=np.float64)
    pos = np.ascontiguousarray(centres, dtype=np.float64)
    vel = np.ascontiguousarray(velocities, dtype=np.float64)
    rch = np.ascontiguousarray(reach, dtype=np.float64)
    msk = np.ascontiguousarray(mask, dtype=np.bool_)
    lim = np.full(pos.shape[1], steps, dtype=np.int64)
    if limit is not None:
        lim[:] = np.clip(np.asarray(limit, dtype=np.int64), 0, steps)
    static = np.zeros((0, 5))
    if static_centres is not None:
        sc = np.asarray(static_centres, dtype=np.float64).reshape(-1, 2)
        static = np.zeros((len(sc), 5))
        static[:, :2] = sc
        static[:, 4] = np.asarray(static_reach, dtype=np.float64).reshape(-1)
    t_mid = np.minimum((np.arange(steps, dtype=float) + 0.5) * step, turn_time)
    clear = np.empty(vv.shape)
    _batch(p, vv, ww, float(step), t_mid, int(w_stride), static, pos, vel, rch, msk, lim, clear)
    return clear


@numba.njit(cache=True)
def _choose(theta, v, w, v_ref, w_ref, theta_t, clear, tau, pref_weight, heading_weight,
            turn_weight, w_stride, best, fell):  # pragma: no cover - numba
    """Fill ``best`` and ``fell`` ``(N,)`` (see :func:`vo_choose`)."""
    n, n_s = v.shape
    cp, sp, cg = np.empty(n_s), np.empty(n_s), np.empty(n_s)
    done = np.zeros(n_s, np.bool_)
    for i in range(n):
        th = theta[i]
        psi_ref = th + w_ref[i] * tau
        vr = v_ref[i]
        rx = vr * math.cos(psi_ref)
        ry = vr * math.sin(psi_ref)
        root = _roots(w[i], w_stride)
        done[:] = False
        k = -1
        low = np.inf
        for s in range(n_s):
            if not clear[i, s] >= 0.0:
                continue
            r = root[s]
            if not done[r]:  # the heading aimed for, once per distinct w
                psi = th + w[i, r] * tau
                cp[r] = math.cos(psi)
                sp[r] = math.sin(psi)
                cg[r] = math.cos(psi - theta_t[i])
                done[r] = True
            dvx = v[i, s] * cp[r] - rx
            dvy = v[i, s] * sp[r] - ry
            short = vr - v[i, s] * cg[r]
            if not (short >= 0.0 or short != short):  # np.maximum(short, 0.0)
                short = 0.0
            cost = (pref_weight * math.hypot(dvx, dvy) + heading_weight * short
                    + turn_weight * abs(w[i, s] - w_ref[i]))
            if cost != cost:  # np.argmin: the first NaN
                k = s
                break
            if k < 0 or cost < low:
                k, low = s, cost
        fell[i] = k < 0
        if k < 0:  # np.argmax of the clearance: the first maximum (or NaN)
            k, high = 0, clear[i, 0]
            for s in range(n_s):
                c = clear[i, s]
                if c != c:
                    k = s
                    break
                if c > high:
                    k, high = s, c
        best[i] = k


def vo_choose(theta: ArrayLike, v: ArrayLike, w: ArrayLike, v_ref: ArrayLike, w_ref: ArrayLike,
              theta_t: ArrayLike, clear: ArrayLike, tau: float, pref_weight: float,
              heading_weight: float, turn_weight: float = 0.0,
              w_stride: int = 0) -> tuple[IntArray, NDArray[np.bool_]]:
    """Each robot's sample: the cheapest safe one, else the one with the largest clearance.

    The same choice as ``np.argmin(np.where(clear >= 0, vo_cost(...), inf), axis=1)``
    with :func:`comparisons.lf_vo.equations.vo_cost` (bit for bit the same costs:
    the same operations in the same order), replaced by ``np.argmax(clear,
    axis=1)`` on the rows without a safe sample. Costs are computed for the
    safe samples only, the trigonometry once per distinct turn rate
    (``w_stride`` as in :func:`vo_clearance`).

    Args:
        theta: ``(N,)`` current headings, rad.
        v: ``(N, S)`` sampled speeds, m/s.
        w: ``(N, S)`` sampled turn rates, rad/s.
        v_ref: ``(N,)`` preferred speeds (eq 4), m/s.
        w_ref: ``(N,)`` preferred turn rates (eq 4), rad/s.
        theta_t: ``(N,)`` target directions (eq 10), rad.
        clear: ``(N, S)`` clearances (:func:`vo_clearance`), m; safe when ``>= 0``.
        tau: Time over which the heading turns, s.
        pref_weight: Weight of the velocity distance, s/m.
        heading_weight: Weight of the progress shortfall, s/m.
        turn_weight: Weight of the turn-rate distance to ``w_ref``, s/rad.
        w_stride: Samples ``s`` and ``s - w_stride`` often share ``w``; any value is exact.

    Returns:
        ``(best (N,), fell (N,))``: the chosen sample's index and whether the row
        had no safe sample.
    """
    vv = np.ascontiguousarray(v, dtype=np.float64)
    n = vv.shape[0]
    if vv.ndim != 2 or vv.shape[1] == 0:
        raise ValueError(f"vo_choose needs (N, S) samples with S >= 1, got {vv.shape}")

    def per_robot(a: ArrayLike) -> FloatArray:
        return np.ascontiguousarray(a, dtype=np.float64).reshape(n)

    best = np.empty(n, dtype=np.int64)
    fell = np.empty(n, dtype=np.bool_)
    _choose(per_robot(theta), vv, np.ascontiguousarray(w, dtype=np.float64), per_robot(v_ref),
            per_robot(w_ref), per_robot(theta_t), np.ascontiguousarray(clear, dtype=np.float64),
            float(tau), float(pref_weight), float(heading_weight), float(turn_weight),
            int(w_stride), best, fell)
    return best, fell
