"""Compiled pass of an environment step: the score of every run.

At E = 1 a step is dozens of numpy calls of a few microseconds each; this
kernel replaces most of them with one call, and gives the bits of the numpy
references it stands for (``tests/test_envs.py`` compares them on random
inputs; the observation vectors have their own kernel,
:func:`dfcoa_opt.control.features_kernel.flatten_rows`):

- :func:`score_runs`: the formation errors
  (:func:`~dfcoa_opt.envs.rewards.formation_errors`), the centroid's arc
  length (:func:`~dfcoa_opt.envs.rewards.path_arc_length`), the contacts, the
  reward (:func:`~dfcoa_opt.envs.rewards.dense_reward`) and the stall test
  (:meth:`~dfcoa_opt.sim.stall.BatchStall.update_reference`) of every active
  run at its instant, read from the run log.

Same bits means the same operations in the same order, without fast-math:
products and sums written as numpy evaluates them (``_to_body``'s ``c x + s
y`` and ``-s x + c y``, divisions by the scales, flags multiplied in last),
numpy's reductions (a mean over the robots of a strided or non-inner axis is
a sequential sum from 0; over a contiguous inner axis numpy's pairwise sum,
:func:`_pairwise`; a norm of two components ``sqrt(x x + y y)``) and numpy's
``argsort(kind="stable")`` and ``argmin`` (NaN last, resp. first). numba's
``sin``, ``cos`` and ``hypot`` are numpy's here (``dfcoa_opt.core.scalar_kernels``);
no ``arctan2`` is needed.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from dfcoa_opt.control.features_kernel import _pairwise
from dfcoa_opt.sim.stall import stalled_at


@numba.njit(cache=True)
def _arc(x, y, start, count, segs):  # pragma: no cover - numba
    """:func:`~dfcoa_opt.envs.rewards.path_arc_length` of one point on ``segs[:, start:+count]``."""
    if count == 0:  # a one-point path
        return 0.0
    best, best_d, best_t = -1, 0.0, 0.0
    for q in range(start, start + count):
        ax, ay, abx, aby, seg = segs[0, q], segs[1, q], segs[2, q], segs[3, q], segs[4, q]
        t = ((x - ax) * abx + (y - ay) * aby) / (seg * seg)
        if t < 0.0:
            t = 0.0
        if t > 1.0:
            t = 1.0
        dx, dy = ax + t * abx - x, ay + t * aby - y
        d = math.sqrt(dx * dx + dy * dy)
        if math.isnan(d):  # argmin: the first NaN
            return segs[5, q] + t * seg
        if best < 0 or d < best_d:
            best, best_d, best_t = q, d, t
    return segs[5, best] + best_t * segs[4, best]


@numba.njit(cache=True)
def score_runs(pose, slots, robot_c, obstacle_c, dynamic_c, active, kk, group, start, count,
               segs, arc_prev, weights, dt, progress, flags, stall, lag, advance, settle,
               displacement):  # pragma: no cover - numba
    """Score every active run at its instant, read from the log (module docstring).

    Args:
        pose: The log's ``(E, T, N, 3)`` poses (a :class:`~dfcoa_opt.sim.log.BatchLog`'s,
            rows up to ``kk`` written).
        slots: The log's ``(E, T, N, 2)`` slots.
        robot_c: The log's ``(E, T)`` robot-robot contacts.
        obstacle_c: The log's ``(E, T)`` robot-static contacts.
        dynamic_c: The log's ``(E, T)`` robot-moving contacts.
        active: ``(A,)`` the runs' slots.
        kk: ``(A,)`` their instants.
        group: ``(E,)`` each slot's world (its path).
        start: A :class:`~dfcoa_opt.envs.rewards.PathTable`'s ``start``.
        count: Its ``count``.
        segs: Its ``data``.
        arc_prev: ``(E,)`` each slot's arc length at its previous instant; updated.
        weights: ``(4,)`` formation, shape, progress and contact weights.
        dt: Step, s.
        progress: ``(E, T)`` the stall test's arc lengths; updated when ``stall``.
        flags: ``(E,)`` the stall flags; set when ``stall``.
        stall: Whether to run the stall test.
        lag: :class:`~dfcoa_opt.envs.rewards.BatchStall`'s window, in steps.
        advance: Its least advance along the path, m.
        settle: Its distance from the slot below which a robot is settled, m.
        displacement: Its least displacement of a robot away from its slot, m.

    Returns:
        ``(A,)`` each: rewards without the end bonus, contacts, ``E_c``, ``E_s``, arc lengths.
    """
    a, n = active.shape[0], pose.shape[2]
    reward, e_c, e_s, arc = np.empty(a), np.empty(a), np.empty(a), np.empty(a)
    contact = np.empty(a, dtype=np.bool_)
    norms = np.empty(n)
    for j in range(a):
        e, k = active[j], kk[j]
        cx = cy = sx = sy = 0.0
        for i in range(n):
            cx += pose[e, k, i, 0]
            cy += pose[e, k, i, 1]
            sx += slots[e, k, i, 0]
            sy += slots[e, k, i, 1]
        cx, cy, sx, sy = cx / n, cy / n, sx / n, sy / n
        ox, oy = cx - sx, cy - sy
        e_c[j] = math.sqrt(ox * ox + oy * oy)
        for i in range(n):
            rx = (pose[e, k, i, 0] - slots[e, k, i, 0]) - ox
            ry = (pose[e, k, i, 1] - slots[e, k, i, 1]) - oy
            norms[i] = math.sqrt(rx * rx + ry * ry)
        e_s[j] = (0.0 + _pairwise(norms, n)) / n
        g = group[e]
        s = _arc(cx, cy, start[g], count[g], segs)
        arc[j] = s
        hit = robot_c[e, k] > 0 or obstacle_c[e, k] > 0 or dynamic_c[e, k] > 0
        contact[j] = hit
        step = 0.0 if k == 0 else s - arc_prev[e]
        arc_prev[e] = s
        reward[j] = (-(weights[0] * e_c[j] + weights[1] * e_s[j]) * dt + weights[2] * step
                     - weights[3] * (1.0 if hit else 0.0))
        if stall:
            progress[e, k] = s
            flags[e] = stalled_at(pose, slots, progress, e, k, lag, advance, settle, displacement)
    return reward, contact, e_c, e_s, arc
