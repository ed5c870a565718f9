"""Odometry motion model of Monte Carlo localization (:mod:`dfcoa_opt.sim.localization.mcl`).

**Odometry motion model** (Thrun, *Probabilistic Robotics* Table 5.6; MATLAB
``odometryMotionModel``): a relative motion between two odometry poses is
split into ``(rot1, trans, rot2)`` and each part is perturbed by a zero-mean
Gaussian whose *variance* is ``alpha1 rot1^2 + alpha2 trans^2`` (rotations),
``alpha3 trans^2 + alpha4 (rot1^2 + rot2^2)`` (translation). As in AMCL,
the rotations that scale the noise are those of the robot's own turn (see
:func:`decompose_motion`), so driving backwards or being pushed sideways is
not mistaken for a half or quarter turn, and a translation below
:data:`MIN_TRANSLATION` is treated as a rotation in place.

The same model simulates each robot's odometry and moves its particles; every
step is a few vectorised numpy operations over all particles (no numba kernel).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dfcoa_opt.core.geometry import wrap_angle_fast

FloatArray = NDArray[np.float64]

#: Relative motions shorter than this (m) are treated as rotations in place by
#: the noise model (AMCL uses the same 0.01 m), so a rotation of the direction
#: of a tiny displacement does not inflate the heading noise.
MIN_TRANSLATION = 0.01


def decompose_motion(prev: FloatArray, cur: FloatArray, rotation_noise: str = "heading_change"
                     ) -> tuple[FloatArray, ...]:
    """Split the motions ``prev -> cur`` into the odometry model's three parts.

    Args:
        prev: ``(M, 3)`` start poses (m, m, rad).
        cur: ``(M, 3)`` end poses (m, m, rad).
        rotation_noise: Which rotations scale the noise (below
            :data:`MIN_TRANSLATION` always ``0`` and the whole heading change,
            as AMCL). ``"decomposition"``: ``rot1`` and ``rot2`` folded to
            ``min(|rot|, pi - |rot|)`` (AMCL). ``"heading_change"``: half the
            heading change each. The two agree for every motion a differential
            drive can make (an arc, forwards or backwards, has ``rot1 = rot2``);
            they differ for a sideways displacement (an external push), which
            the first takes for a +-90 deg turn there and back.

    Returns:
        ``(rot1, trans, rot2, rot1_noise, rot2_noise)``, each ``(M,)``: the exact
        decomposition (rad, m, rad; ``rot1 + rot2`` is the heading change) and
        the rotations (rad) that scale the noise.
    """
    dx = cur[:, 0] - prev[:, 0]
    dy = cur[:, 1] - prev[:, 1]
    dth = wrap_angle_fast(cur[:, 2] - prev[:, 2])
    trans = np.hypot(dx, dy)
    rot1 = wrap_angle_fast(np.arctan2(dy, dx) - prev[:, 2])
    rot2 = wrap_angle_fast(dth - rot1)
    moving = trans >= MIN_TRANSLATION
    if rotation_noise == "decomposition":
        n1 = np.minimum(np.abs(rot1), np.pi - np.abs(rot1))
        n2 = np.minimum(np.abs(rot2), np.pi - np.abs(rot2))
    else:
        n1 = n2 = 0.5 * np.abs(dth)
    return rot1, trans, rot2, np.where(moving, n1, 0.0), np.where(moving, n2, np.abs(dth))


def sample_motion(poses: FloatArray, motion: tuple[FloatArray, ...], alphas: ArrayLike,
                  normals: FloatArray) -> FloatArray:
    """Apply noisy odometry motions (Thrun's ``sample_motion_model_odometry``).

    Args:
        poses: ``(M, 3)`` poses to move (m, m, rad).
        motion: ``(rot1, trans, rot2, rot1_noise, rot2_noise)`` from
            :func:`decompose_motion`, each ``(M,)`` (or broadcastable).
        alphas: ``(alpha1, alpha2, alpha3, alpha4)``: rotation from rotation,
            rotation from translation, translation from translation, translation
            from rotation (MATLAB ``Noise`` order); variance coefficients
            (rad^2/rad^2, rad^2/m^2, m^2/m^2, m^2/rad^2).
        normals: ``(M, 3)`` standard normal draws.

    Returns:
        The moved poses ``(M, 3)``, heading wrapped to ``[-pi, pi)``.
    """
    a1, a2, a3, a4 = (float(a) for a in alphas)
    rot1, trans, rot2, n1, n2 = motion
    t2 = trans * trans
    s1 = np.sqrt(a1 * n1 * n1 + a2 * t2)
    st = np.sqrt(a3 * t2 + a4 * (n1 * n1 + n2 * n2))
    s2 = np.sqrt(a1 * n2 * n2 + a2 * t2)
    r1 = rot1 - s1 * normals[:, 0]
    tr = trans - st * normals[:, 1]
    r2 = rot2 - s2 * normals[:, 2]
    head = poses[:, 2] + r1
    out = np.empty_like(poses)
    out[:, 0] = poses[:, 0] + tr * np.cos(head)
    out[:, 1] = poses[:, 1] + tr * np.sin(head)
    out[:, 2] = wrap_angle_fast(head + r2)
    return out


def compose_relative(base: FloatArray, frm: FloatArray, to: FloatArray) -> FloatArray:
    """``base (+) (frm^-1 (+) to)``: move ``base`` by the relative motion ``frm -> to``.

    Args:
        base: ``(M, 3)`` poses to move.
        frm: ``(M, 3)`` start of the relative motion.
        to: ``(M, 3)`` end of the relative motion.
    """
    c, s = np.cos(frm[:, 2]), np.sin(frm[:, 2])
    dx, dy = to[:, 0] - frm[:, 0], to[:, 1] - frm[:, 1]
    lx, ly = c * dx + s * dy, -s * dx + c * dy
    cb, sb = np.cos(base[:, 2]), np.sin(base[:, 2])
    out = np.empty_like(base)
    out[:, 0] = base[:, 0] + cb * lx - sb * ly
    out[:, 1] = base[:, 1] + sb * lx + cb * ly
    out[:, 2] = wrap_angle_fast(base[:, 2] + to[:, 2] - frm[:, 2])
    return out
