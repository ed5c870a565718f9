"""Fast sampled velocity obstacle of ``lf_vo``: rollout and clearance in a numba kernel.

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
   increasing ``lb`` at their last step, :data:`CHUNK` at a time in one pass
   over the rollout. Let ``worst`` be the largest current clearance of the
   robot's samples, capped at ``exact_below``. Once that bound of the next
   obstacle is at least ``worst``, neither it nor any later obstacle can
   lower a minimum below ``worst``, and the loop stops; within a pass, an
   obstacle's first steps whose ``lb_k`` is at least ``worst`` are skipped.
   Skipped gaps are never below the minimum kept or below ``exact_below``, so
   every clearance below ``exact_below`` is the exact minimum over all
   obstacles and steps, and every other one is at least ``exact_below``
   (default ``inf``: all exact; ``inf`` when a robot has no real obstacle, as
   in the reference). The bounds are lowered by :data:`SLACK` to absorb
   rounding.
4. **Batches.** Rows are independent: a batch of runs is one call, each row
   seeing the static discs of its own run's world (``static_ptr``,
   ``static_of``). Rows are split into one block per thread; a block
   allocates its work space (the rollout) once, not once per robot.

:func:`~comparisons.lf_vo.choose.vo_choose` (re-exported here) picks each
robot's sample from the clearances.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from comparisons.lf_vo.choose import _roots, vo_choose
from dfcoa_opt.core.runtime.threads import kernel_threads

__all__ = ["CHUNK", "SLACK", "vo_choose", "vo_clearance"]

FloatArray = NDArray[np.float64]

#: Margin subtracted from every culling bound (covers rounding of the gaps), m.
SLACK = 1e-6

#: Obstacles checked together in one pass over the rollout.
CHUNK = 8


@numba.njit(cache=True)
def _extend(x, y, theta, w, t_mid, root, uniq, n_uniq, vs, cs, sn, ax, ay, px, py, k_from,
            k_to):  # pragma: no cover - numba
    """Fill rows ``k_from..k_to - 1`` of ``px, py`` ``(H, S)``, continuing the sums ``ax, ay``.

    ``cs, sn`` hold the cos/sin of the headings of step ``k_from - 1``; they are
    computed for the samples ``uniq[:n_uniq]`` (the roots) and copied to the others.
    """
    n_s = vs.shape[0]
    for k in range(k_from, k_to):
        if k == 0 or t_mid[k] != t_mid[k - 1]:  # else: same heading as the step before
            for u in range(n_uniq):
                s = uniq[u]
                h = theta + w[s] * t_mid[k]
                cs[s] = math.cos(h)
                sn[s] = math.sin(h)
            for s in range(n_s):
                cs[s] = cs[root[s]]
                sn[s] = sn[root[s]]
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
def _robot(x, y, theta, v, w, step, t_mid, w_stride, obst, lim, n_obst, exact_below, clear,
           roots, per_s, px, py, per_q, order, d2min, picked):  # pragma: no cover - numba
    """Exact min clearance of one robot's samples against ``obst[:n_obst]`` (cx, cy, ux, uy, r).

    Obstacle ``q`` is checked over the steps ``0..lim[q] - 1``. The obstacle
    with the lowest bound is checked first, alone (unless ``exact_below`` is
    finite); then only the obstacles whose bound is below the largest
    clearance so far and ``exact_below``, by increasing bound (the order
    changes which gaps are skipped, never a minimum below ``exact_below``).
    The arguments after ``clear`` are work space, overwritten: ``roots``
    ``(2, S)``, ``per_s`` ``(5, S)``, ``px, py`` ``(H, S)``, ``per_q`` ``(3, Q)``,
    ``order`` ``(Q,)``, ``d2min`` ``(CHUNK, S)``, ``picked`` ``(2, CHUNK)``.
    """
    n_s, n_h = v.shape[0], t_mid.shape[0]
    for s in range(n_s):
        clear[s] = np.inf
    if n_obst == 0:
        return
    v_max = 0.0
    for s in range(n_s):
        v_max = max(v_max, abs(v[s]))
    d_now, speed, bound = per_q[0], per_q[1], per_q[2]
    lowest = 0
    for q in range(n_obst):
        d_now[q] = math.sqrt((x - obst[q, 0]) ** 2 + (y - obst[q, 1]) ** 2)
        speed[q] = math.sqrt(obst[q, 2] ** 2 + obst[q, 3] ** 2)
        bound[q] = d_now[q] - (v_max + speed[q]) * (step * lim[q]) - obst[q, 4] - SLACK
        if bound[q] < bound[lowest]:
            lowest = q
    order[0] = lowest
    n_order = 1
    # the rollout, filled up to row k_done - 1 as the obstacles need it
    root, uniq = roots[0], roots[1]
    _roots(w, w_stride, root)
    n_uniq = 0
    for s in range(n_s):
        if root[s] == s:
            uniq[n_uniq] = s
            n_uniq += 1
    vs, cs, sn, ax, ay = per_s[0], per_s[1], per_s[2], per_s[3], per_s[4]
    for s in range(n_s):
        vs[s] = v[s] * step
    k_done = 0
    chunk, k_first = picked[0], picked[1]
    worst = exact_below  # skip gaps >= this: the largest clearance so far, at most exact_below
    j = 0
    ranked = False
    while j < n_order or not ranked:
        if not ranked and (j > 0 or worst < np.inf):
            # the obstacles that may still lower a minimum (bound < worst), by increasing bound
            ranked = True
            for q in range(n_obst):
                if q == lowest or bound[q] >= worst:
                    continue
                r = n_order
                while r > 1 and bound[order[r - 1]] > bound[q]:
                    order[r] = order[r - 1]
                    r -= 1
                order[r] = q
                n_order += 1
            continue
        # the next obstacles by increasing bound (without exact_below, one first: a finite worst)
        m = 0
        size = CHUNK if ranked else 1
        while j < n_order and m < size:
            q = order[j]
            if bound[q] >= worst:
                j = n_order  # this and every later one: gap >= bound >= worst >= clear[s]
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
            _extend(x, y, theta, w, t_mid, root, uniq, n_uniq, vs, cs, sn, ax, ay, px, py,
                    k_done, k_hi)
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
                    # a plain store (not a masked one): the next step reads it back
                    d2min[c, s] = d2 if d2 < d2min[c, s] else d2min[c, s]
        for c in range(m):
            reach = obst[chunk[c], 4]
            for s in range(n_s):
                g = math.sqrt(d2min[c, s]) - reach
                if g < clear[s]:
                    clear[s] = g
        worst = -np.inf
        for s in range(n_s):
            worst = max(worst, clear[s])
        worst = min(worst, exact_below)


@numba.njit(cache=True)
def _rows(lo, hi, pose, v, w, step, t_mid, w_stride, static, static_ptr, static_of, pos, vel,
          reach, mask, limit, exact_below, clear):  # pragma: no cover - numba
    """Fill rows ``lo..hi - 1`` of ``clear`` (see :func:`_batch`), with one work space."""
    n_s, n_h, n_dyn = v.shape[1], t_mid.shape[0], pos.shape[1]
    n_q = n_dyn
    for g in range(static_ptr.shape[0] - 1):
        n_q = max(n_q, static_ptr[g + 1] - static_ptr[g] + n_dyn)
    obst = np.empty((n_q, 5))
    lim = np.empty(n_q, np.int64)
    roots, per_s = np.empty((2, n_s), np.int64), np.empty((5, n_s))
    px, py = np.empty((n_h, n_s)), np.empty((n_h, n_s))
    per_q, order = np.empty((3, n_q)), np.empty(n_q, np.int64)
    d2min, picked = np.empty((CHUNK, n_s)), np.empty((2, CHUNK), np.int64)
    for i in range(lo, hi):
        m = 0
        for q in range(static_ptr[static_of[i]], static_ptr[static_of[i] + 1]):
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
               m, exact_below, clear[i], roots, per_s, px, py, per_q, order, d2min, picked)


@numba.njit(cache=True, parallel=True)
def _batch(pose, v, w, step, t_mid, w_stride, static, static_ptr, static_of, pos, vel, reach,
           mask, limit, exact_below, clear, blocks):  # pragma: no cover - numba
    """Fill ``clear`` ``(N, S)``: each robot's static discs (its world's) and real obstacles.

    ``blocks`` blocks of rows (one per thread), each with its own work space,
    allocated once per block: a fresh rollout per robot cost more than its checks.
    """
    n = pose.shape[0]
    for b in numba.prange(blocks):
        _rows(b * n // blocks, (b + 1) * n // blocks, pose, v, w, step, t_mid, w_stride, static,
              static_ptr, static_of, pos, vel, reach, mask, limit, exact_below, clear)


def vo_clearance(pose: ArrayLike, v: ArrayLike, w: ArrayLike, step: float, steps: int,
                 turn_time: float, centres: ArrayLike, velocities: ArrayLike, reach: ArrayLike,
                 mask: ArrayLike, static_centres: ArrayLike | None = None,
                 static_reach: ArrayLike | None = None, w_stride: int = 0,
                 limit: ArrayLike | None = None, static_ptr: ArrayLike | None = None,
                 static_of: ArrayLike | None = None, exact_below: float = np.inf) -> FloatArray:
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
        static_centres: ``(C, 2)`` static discs, m (optional): seen by every robot,
            or by the robots of their world (``static_ptr``).
        static_reach: ``(C,)`` their collision distances, m.
        w_stride: Samples ``s`` and ``s - w_stride`` often share ``w`` (a speed-major
            grid with ``w_stride`` turn rates); only a speed-up, any value is exact.
        limit: ``(Q,)`` number of prediction steps checked against column ``q`` of the
            per-robot obstacles (clipped to ``0..steps``; default ``steps``): the
            result is then the minimum of the reference over the columns' own
            first ``limit_q`` steps (static discs: all ``steps``).
        static_ptr: ``(W + 1,)`` the static discs of W worlds (a batch of runs whose
            maps differ): world ``g``'s are rows ``static_ptr[g]:static_ptr[g + 1]`` of
            ``static_centres``. Default: one world, every disc.
        static_of: ``(N,)`` each robot's world (default 0): a robot sees its world's
            discs only, and gets the clearances of a call with those discs alone.
        exact_below: Clearances below this (m) are exact; the others are only at
            least this (any gap whose bound reaches it is skipped). ``lf_vo``'s choice
            needs the sign and the negative values only (``exact_below = 0``).

    Returns:
        ``(N, S)`` clearance in m (``inf`` when the robot has no obstacle), equal
        to the reference's (below ``exact_below``).
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
    ptr = np.array([0, len(static)], dtype=np.int64) if static_ptr is None else \
        np.ascontiguousarray(static_ptr, dtype=np.int64)
    world = np.zeros(len(p), dtype=np.int64) if static_of is None else \
        np.ascontiguousarray(static_of, dtype=np.int64).reshape(len(p))
    t_mid = np.minimum((np.arange(steps, dtype=float) + 0.5) * step, turn_time)
    clear = np.empty(vv.shape)
    with kernel_threads(len(p)):
        _batch(p, vv, ww, float(step), t_mid, int(w_stride), static, ptr, world, pos, vel, rch,
               msk, lim, float(exact_below), clear, min(len(p), numba.get_num_threads()))
    return clear
