"""Fast sampled velocity obstacle of ``lf_vo``: rollout + clearance in one numba kernel.

:func:`vo_clearance` returns the same ``(N, S)`` clearances as
``path_clearance(rollout(...), ...)`` of :mod:`comparisons.lf_vo_core` (the
numpy reference), without the dense ``(N, S, H, Q)`` arrays. Per robot:

1. **Rollout.** Every sample's path is integrated with the same floating-point
   operations as :func:`comparisons.lf_vo_core.rollout` (heading
   ``theta + w * t_mid``, increments ``(v * step) * cos``, sequential sums).
   ``cos``/``sin`` are reused where the heading is bitwise the same: samples
   with the same ``w`` (the grid repeats the ``w`` values for every ``v``,
   ``w_stride`` apart) and steps after ``turn_time``.
2. **Exact minimum with culling.** The minimum over steps of ``|p_k - f_k| - r``
   is ``sqrt(min_k |p_k - f_k|^2) - r``: ``sqrt`` and ``- r`` are correctly
   rounded, hence monotone, so taking the square root once per obstacle gives
   bit for bit the reference's minimum. A sample moves at most ``|v| t_k`` and
   an obstacle ``|u| t_k`` by the instant ``t_k = step * (k + 1)``, so every
   gap of obstacle ``q`` at step ``k`` is at least
   ``lb_k = d_q - (v_max + |u_q|) t_k - r_q`` (``d_q``: distance now,
   ``v_max``: the robot's largest ``|v|``). Obstacles are visited by
   increasing ``lb_H``, the first one alone and then :data:`CHUNK` at a time in
   one pass over the rollout. Before each batch, once ``lb_H`` of the next
   obstacle is at least the largest current clearance of the robot's samples,
   neither it nor any later obstacle can lower any sample's minimum, and the
   loop stops. Within a batch, an obstacle's first steps whose ``lb_k`` is at
   least that largest clearance are skipped for the same reason. Skipped gaps
   are never below the minimum kept, so the result is the exact minimum over
   all obstacles and steps (``inf`` when a robot has no real obstacle, as in
   the reference). The bounds are lowered by :data:`SLACK` to absorb rounding.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

#: Margin subtracted from every culling bound (covers rounding of the gaps), m.
SLACK = 1e-6

#: Obstacles checked together in one pass over the rollout (after the first one).
CHUNK = 8


@numba.njit(cache=True)
def _rollout_one(x, y, theta, v, w, step, t_mid, w_stride, px, py):  # pragma: no cover - numba
    """Fill ``px, py`` ``(H, S)`` with the predicted positions of one robot's samples."""
    n_s, n_h = v.shape[0], t_mid.shape[0]
    root = np.empty(n_s, np.int64)  # the first sample with the same w (same headings)
    vs = np.empty(n_s)
    for s in range(n_s):
        root[s] = s
        if w_stride > 0 and s >= w_stride and w[s - w_stride] == w[s]:
            root[s] = root[s - w_stride]
        vs[s] = v[s] * step
    cs = np.empty(n_s)
    sn = np.empty(n_s)
    ax = np.empty(n_s)
    ay = np.empty(n_s)
    for k in range(n_h):
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
def _robot(x, y, theta, v, w, step, t_mid, w_stride, obst, n_obst, clear):  # pragma: no cover
    """Exact min clearance of one robot's samples against ``obst[:n_obst]`` (cx, cy, ux, uy, r)."""
    n_s, n_h = v.shape[0], t_mid.shape[0]
    for s in range(n_s):
        clear[s] = np.inf
    if n_obst == 0:
        return
    horizon = step * n_h
    v_max = 0.0
    for s in range(n_s):
        v_max = max(v_max, abs(v[s]))
    d_now = np.empty(n_obst)
    speed = np.empty(n_obst)
    bound = np.empty(n_obst)
    for q in range(n_obst):
        d_now[q] = math.sqrt((x - obst[q, 0]) ** 2 + (y - obst[q, 1]) ** 2)
        speed[q] = math.sqrt(obst[q, 2] ** 2 + obst[q, 3] ** 2)
        bound[q] = d_now[q] - (v_max + speed[q]) * horizon - obst[q, 4] - SLACK
    order = np.argsort(bound)
    px = np.empty((n_h, n_s))
    py = np.empty((n_h, n_s))
    _rollout_one(x, y, theta, v, w, step, t_mid, w_stride, px, py)
    chunk = np.empty(CHUNK, np.int64)
    k_first = np.empty(CHUNK, np.int64)
    d2min = np.empty((CHUNK, n_s))
    worst = np.inf  # largest clearance over the samples so far
    j = 0
    while j < n_obst:
        # the next obstacles by increasing bound (one first, to get a finite `worst`)
        m = 0
        while j < n_obst and m < (1 if j == 0 else CHUNK):
            q = order[j]
            if bound[q] >= worst:
                j = n_obst  # this and every later one: gap >= bound >= worst >= clear[s]
                break
            k0 = 0
            rate = v_max + speed[q]
            if worst < np.inf and rate > 0.0:
                # steps with step * (k + 1) <= t_free have lb_k >= worst: skip (one less, safe)
                t_free = (d_now[q] - obst[q, 4] - SLACK - worst) / rate
                k0 = min(max(int(math.floor(t_free / step)) - 1, 0), n_h)
            chunk[m] = q
            k_first[m] = k0
            m += 1
            j += 1
        if m == 0:
            break
        k_lo = n_h
        for c in range(m):
            k_lo = min(k_lo, k_first[c])
            for s in range(n_s):
                d2min[c, s] = np.inf
        for k in range(k_lo, n_h):
            t = step * (k + 1.0)
            for c in range(m):
                if k < k_first[c]:
                    continue
                q = chunk[c]
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
def _batch(pose, v, w, step, t_mid, w_stride, static, pos, vel, reach, mask,
           clear):  # pragma: no cover - numba
    n, n_stat, n_dyn = pose.shape[0], static.shape[0], pos.shape[1]
    for i in numba.prange(n):
        obst = np.empty((n_stat + n_dyn, 5))
        m = 0
        for q in range(n_stat):
            for c in range(5):
                obst[m, c] = static[q, c]
            m += 1
        for q in range(n_dyn):
            if mask[i, q]:
                obst[m, 0] = pos[i, q, 0]
                obst[m, 1] = pos[i, q, 1]
                obst[m, 2] = vel[i, q, 0]
                obst[m, 3] = vel[i, q, 1]
                obst[m, 4] = reach[i, q]
                m += 1
        _robot(pose[i, 0], pose[i, 1], pose[i, 2], v[i], w[i], step, t_mid, w_stride, obst, m,
               clear[i])


def vo_clearance(pose: ArrayLike, v: ArrayLike, w: ArrayLike, step: float, steps: int,
                 turn_time: float, centres: ArrayLike, velocities: ArrayLike, reach: ArrayLike,
                 mask: ArrayLike, static_centres: ArrayLike | None = None,
                 static_reach: ArrayLike | None = None, w_stride: int = 0) -> FloatArray:
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
    static = np.zeros((0, 5))
    if static_centres is not None:
        sc = np.asarray(static_centres, dtype=np.float64).reshape(-1, 2)
        static = np.zeros((len(sc), 5))
        static[:, :2] = sc
        static[:, 4] = np.asarray(static_reach, dtype=np.float64).reshape(-1)
    t_mid = np.minimum((np.arange(steps, dtype=float) + 0.5) * step, turn_time)
    clear = np.empty(vv.shape)
    _batch(p, vv, ww, float(step), t_mid, int(w_stride), static, pos, vel, rch, msk, clear)
    return clear
