"""Compiled observation vectors: every row of an Observation as its vector, in one call.

:func:`flatten_rows` gives the bits of its numpy reference,
:func:`dfcoa_opt.control.features.flatten_reference` (``tests/test_envs.py``
compares them on random inputs). Same bits means the same operations in the
same order, without fast-math: products and sums written as numpy evaluates
them (``_to_body``'s ``c x + s y`` and ``-s x + c y``, divisions by the
scales, flags multiplied in last), numpy's reductions (over a contiguous inner
axis numpy's pairwise sum, :func:`_pairwise`; a norm of two components ``sqrt(x
x + y y)``) and numpy's ``argsort(kind="stable")`` (NaN last). numba's
``sin``, ``cos`` and ``hypot`` are numpy's here (``dfcoa_opt.core.scalar_kernels``).
"""

from __future__ import annotations

import math

import numba
import numpy as np

#: numpy's pairwise summation: below this many terms a plain loop, above it halves.
_PW_BLOCK = 128


@numba.njit(cache=True)
def _pairwise_block(a, start, n):  # pragma: no cover - numba
    """The ``pairwise_sum`` of numpy of ``a[start:start + n]`` for ``n <= 128`` (no halving)."""
    if n < 8:
        res = 0.0
        for i in range(n):
            res += a[start + i]
        return res
    r0, r1, r2, r3 = a[start], a[start + 1], a[start + 2], a[start + 3]
    r4, r5, r6, r7 = a[start + 4], a[start + 5], a[start + 6], a[start + 7]
    i = 8
    while i < n - n % 8:
        j = start + i
        r0 += a[j]
        r1 += a[j + 1]
        r2 += a[j + 2]
        r3 += a[j + 3]
        r4 += a[j + 4]
        r5 += a[j + 5]
        r6 += a[j + 6]
        r7 += a[j + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[start + i]
        i += 1
    return res


@numba.njit(cache=True)
def _pairwise(a, n):  # pragma: no cover - numba
    """The ``pairwise_sum`` of numpy of ``a[:n]`` (the sum of a contiguous inner-axis reduction).

    Above ``_PW_BLOCK`` terms numpy sums the halves (split at a multiple of 8)
    recursively; here with an explicit stack (a cached recursive numba
    function can crash when loaded).
    """
    if n <= _PW_BLOCK:
        return _pairwise_block(a, 0, n)
    starts, sizes = np.empty(64, dtype=np.int64), np.empty(64, dtype=np.int64)
    stage, vals = np.zeros(64, dtype=np.int64), np.empty(64)
    top, nv = 0, 0
    starts[0], sizes[0] = 0, n
    while top >= 0:
        s0, m = starts[top], sizes[top]
        if m <= _PW_BLOCK:
            vals[nv] = _pairwise_block(a, s0, m)
            nv += 1
            top -= 1
            continue
        half = m // 2
        half -= half % 8
        if stage[top] == 2:  # both halves summed
            vals[nv - 2] = vals[nv - 2] + vals[nv - 1]
            nv -= 1
            top -= 1
            continue
        stage[top] += 1
        top += 1
        starts[top], sizes[top], stage[top] = ((s0, half, 0) if stage[top - 1] == 1
                                               else (s0 + half, m - half, 0))
    return vals[0]


@numba.njit(cache=True)
def _earlier(d, q, best):  # pragma: no cover - numba
    """Whether entry ``q`` sorts before ``best`` (numpy's stable order: NaN last, ties by index)."""
    if best < 0:
        return True
    if math.isnan(d[best]):
        return not math.isnan(d[q])
    return d[q] < d[best]


@numba.njit(cache=True)
def flatten_rows(pose, velocity, leader, env, slot, ranges, scanned, range_max, nb_index,
                 nb_pos, nb_vel, mv_pos, mv_vel, mv_radius, mv_mask, beams, k_keep, m_keep,
                 scale, v_scale):  # pragma: no cover - numba
    """Every row's observation vector, :func:`~dfcoa_opt.control.features.flatten_reference`'s bits.

    Args:
        pose: ``(R, 3)`` own poses.
        velocity: ``(R, 2)`` own world velocities.
        leader: ``(L, 5)`` leader states; row i reads ``leader[env[i]]`` (``leader[0]``
            when ``env`` is empty).
        env: ``(R,)`` each row's leader row, or ``(0,)``.
        slot: ``(R, 2)`` own slots.
        ranges: ``(R, B)`` LiDAR ranges (read when ``scanned``).
        scanned: Whether there is a scan (else the LiDAR block is 1).
        range_max: The LiDAR's reach, m.
        nb_index: ``(R, K')`` neighbour indices, -1 where absent.
        nb_pos: ``(R, K', 2)`` their positions.
        nb_vel: ``(R, K', 2)`` their velocities.
        mv_pos: ``(R, M', 2)`` moving obstacles' positions.
        mv_vel: ``(R, M', 2)`` their velocities.
        mv_radius: ``(R, M')`` their radii.
        mv_mask: ``(R, M')`` whether each is sensed.
        beams: ``ObservationSpec.beams``, the LiDAR beams kept.
        k_keep: ``ObservationSpec.neighbours``, K.
        m_keep: ``ObservationSpec.obstacles``, M.
        scale: ``ObservationSpec.range``, the distance scale, m.
        v_scale: ``ObservationSpec.v_max``, the speed scale, m/s.

    Returns:
        ``(R, 8 + beams + 5 k_keep + 6 m_keep)`` float64.

    Raises:
        ValueError: Arrays of other shapes than these (the reference's numpy
            would refuse them; unchecked, they would be read out of bounds).
        IndexError: An ``env`` entry out of ``leader``'s rows.
    """
    r = pose.shape[0]
    if (pose.shape[1] < 3 or velocity.shape != (r, 2) or slot.shape != (r, 2)
            or leader.shape[1] != 5 or (env.shape[0] != 0 and env.shape[0] != r)
            or (scanned and beams and ranges.shape[0] != r) or nb_index.shape[0] != r
            or nb_pos.shape != nb_index.shape + (2,) or nb_vel.shape != nb_pos.shape
            or mv_mask.shape[0] != r or mv_pos.shape != mv_mask.shape + (2,)
            or mv_vel.shape != mv_pos.shape or mv_radius.shape != mv_mask.shape):
        raise ValueError("flatten: the observation's arrays have inconsistent shapes")
    for i in range(env.shape[0]):
        if not -leader.shape[0] <= env[i] < leader.shape[0]:
            raise IndexError("flatten: a row's env is not a row of the leader states")
    out = np.zeros((r, 8 + beams + 5 * k_keep + 6 * m_keep))
    kn = min(k_keep, nb_index.shape[1])
    m = mv_mask.shape[1]
    mk = min(m_keep, m)
    width = ranges.shape[1]
    nb0, mv0 = 8 + beams, 8 + beams + 5 * k_keep
    dist = np.empty(m)
    taken = np.zeros(m, dtype=np.bool_)
    last, cl, sl = leader.shape[0], 0.0, 0.0  # the row before's leader row (none), cos, sin
    for i in range(r):
        px, py, th = pose[i, 0], pose[i, 1], pose[i, 2]
        vx, vy = velocity[i, 0], velocity[i, 1]
        c, s = np.cos(th), np.sin(th)
        e = env[i] if env.shape[0] else 0
        lx, ly, lth, lv, lw = leader[e, 0], leader[e, 1], leader[e, 2], leader[e, 3], leader[e, 4]
        if e != last:  # a team's rows share their leader's heading
            last, cl, sl = e, np.cos(lth), np.sin(lth)
        sx, sy = slot[i, 0], slot[i, 1]
        dx, dy = sx - px, sy - py
        out[i, 0] = (c * dx + s * dy) / scale
        out[i, 1] = (-s * dx + c * dy) / scale
        rel = lth - th
        out[i, 2] = np.cos(rel)
        out[i, 3] = np.sin(rel)
        out[i, 4] = (c * vx + s * vy) / v_scale
        out[i, 5] = (-s * vx + c * vy) / v_scale
        wx = lv * cl - lw * (sy - ly)
        wy = lv * sl + lw * (sx - lx)
        out[i, 6] = (c * wx + s * wy) / v_scale
        out[i, 7] = (-s * wx + c * wy) / v_scale
        for b in range(beams):
            if scanned:
                x = ranges[i, (b * width) // beams] / range_max
                out[i, 8 + b] = 1.0 if x == np.inf else (0.0 if x == -np.inf else x)
            else:
                out[i, 8 + b] = 1.0
        for j in range(kn):
            p = 1.0 if nb_index[i, j] >= 0 else 0.0
            col = nb0 + 5 * j
            _relative(out[i], col, nb_pos[i, j], nb_vel[i, j], px, py, vx, vy, c, s, scale,
                      v_scale, p)
            out[i, col + 4] = 1.0 * p
        if mk == 0:
            continue
        for q in range(m):
            dist[q] = (np.hypot(mv_pos[i, q, 0] - px, mv_pos[i, q, 1] - py) if mv_mask[i, q]
                       else np.inf)
            taken[q] = False
        for j in range(mk):
            q = -1
            for cand in range(m):
                if not taken[cand] and _earlier(dist, cand, q):
                    q = cand
            taken[q] = True
            p = 1.0 if mv_mask[i, q] else 0.0
            col = mv0 + 6 * j
            _relative(out[i], col, mv_pos[i, q], mv_vel[i, q], px, py, vx, vy, c, s, scale,
                      v_scale, p)
            out[i, col + 4] = mv_radius[i, q] / scale * p
            out[i, col + 5] = 1.0 * p
    return out


@numba.njit(cache=True, inline="always")
def _relative(row, col, pos, vel, px, py, vx, vy, c, s, scale, v_scale, p):  # pragma: no cover
    """Columns ``col .. col+3`` of one row: another body relative to the robot.

    Its position and velocity minus the robot's, turned into the robot's frame
    (cos ``c``, sin ``s``), divided by ``scale`` (m) and ``v_scale`` (m/s),
    times its presence ``p`` (0 or 1).
    """
    dx, dy = pos[0] - px, pos[1] - py
    row[col] = (c * dx + s * dy) / scale * p
    row[col + 1] = (-s * dx + c * dy) / scale * p
    dx, dy = vel[0] - vx, vel[1] - vy
    row[col + 2] = (c * dx + s * dy) / v_scale * p
    row[col + 3] = (-s * dx + c * dy) / v_scale * p


