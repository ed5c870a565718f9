"""Paper 004's velocity-obstacle conflict resolution (eq 15-17) for ``virtual_spring``.

Pure, vectorised numpy, row by row like :mod:`comparisons.virtual_spring.equations`
(split from it to keep modules small); the controller runs their compiled twin,
:func:`comparisons.virtual_spring.kernels.conflict_changes` (same bits):

* :func:`vo_conflict` -- eq 15-16: is ``v_i`` in the velocity obstacle of robot ``c_k``;
* :func:`conflict_resolution` -- eq 17.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from comparisons.virtual_spring.equations import FloatArray, norm2, unit_vectors


def vo_conflict(rel_pos: ArrayLike, rel_vel: ArrayLike, radius: ArrayLike,
                horizon: float = np.inf) -> NDArray[np.bool_]:
    """Eq 15-16: whether ``v_i`` lies in the velocity obstacle ``VO^i_ck(v_ck)``.

    The ray ``gamma = {p_i + tau (v_i - v_ck) | 0 <= tau <= horizon}`` (eq 15,
    infinite with ``horizon = inf``) meets the disc ``c_k (+) i`` of radius
    ``radius`` centred on ``p_ck`` (eq 16). A robot already inside that disc is
    in conflict.

    Args:
        rel_pos: ``(..., 2)`` ``p_ck - p_i``, m.
        rel_vel: ``(..., 2)`` ``v_i - v_ck``, m/s.
        radius: ``(...)`` radius of the Minkowski sum (``r_i + r_ck`` + margin), m.
        horizon: Largest ``tau``, s.

    Returns:
        ``(...)`` True where there is a conflict.
    """
    d = np.asarray(rel_pos, dtype=float)
    w = np.asarray(rel_vel, dtype=float)
    wx, wy = w[..., 0], w[..., 1]
    ww = wx * wx + wy * wy
    moves = ww > 0.0
    dw = d[..., 0] * wx + (d[..., 1] * wy + 0.0)  # (d * w).sum(-1), bit for bit
    tau = np.where(moves, np.clip(dw / np.where(moves, ww, 1.0), 0.0, horizon), 0.0)
    return norm2(d - tau[..., None] * w) <= np.asarray(radius, dtype=float)


def conflict_resolution(p_i: ArrayLike, v_i: ArrayLike, p_k: ArrayLike, v_k: ArrayLike,
                        conflict: ArrayLike, share: ArrayLike = 1.0) -> FloatArray:
    """Eq 17: the robot in front speeds up by ``|v_i - v_ck|/2``, the one behind slows down.

    ``v_i-c = v_i -+ |v_i - v_ck|/2`` along the pair's common direction of
    motion ``a = (v_i + v_ck)/|v_i + v_ck|`` (``v_i``'s direction when the two
    cancel, then ``v_ck``'s). Robot i is in front when ``(p_i - p_ck) . a > 0``
    and gets ``+``; otherwise ``-``. The changes of all conflicts add up.

    Args:
        p_i: ``(N, 2)`` own positions, m.
        v_i: ``(N, 2)`` own (planned) velocities, m/s.
        p_k: ``(N, K, 2)`` the other robots' positions, m.
        v_k: ``(N, K, 2)`` their velocities, m/s.
        conflict: ``(N, K)`` True where eq 15-16 found a conflict.
        share: ``(N, K)`` or scalar factor on the change (1 = eq 17's half).

    Returns:
        ``(N, 2)`` velocity changes ``v_i-c - v_i``, m/s.
    """
    p_i = np.asarray(p_i, dtype=float)[:, None, :]
    v_i = np.asarray(v_i, dtype=float)[:, None, :]
    p_k, v_k = np.asarray(p_k, dtype=float), np.asarray(v_k, dtype=float)
    axis, _ = unit_vectors(v_i + v_k)
    for fallback in (v_i, v_k):  # own direction ((N, 1, 2)), then the other's
        none = (axis[..., 0] == 0.0) & (axis[..., 1] == 0.0)  # |axis| == 0: no direction
        if none.any():
            axis = np.where(none[..., None], unit_vectors(fallback)[0], axis)
    rel = p_i - p_k
    front = rel[..., 0] * axis[..., 0] + rel[..., 1] * axis[..., 1] > 0.0
    half = 0.5 * norm2(v_i - v_k) * np.asarray(share, dtype=float)
    step = np.where(front, half, -half) * np.asarray(conflict, dtype=bool)
    return (step[..., None] * axis).sum(axis=1)
