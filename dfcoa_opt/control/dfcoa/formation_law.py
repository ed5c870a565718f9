"""DFCOA formation tracking law (paper 000 eq 14-28 and Algorithm 2), re-derived.

Each follower steers a *tracking point* a distance ``d`` ahead of its centre,
``P = (x_f + d cos th_f, y_f + d sin th_f)``. In the virtual leader's frame the
point has coordinates ``l = (l_x, l_y)`` (eq 15) and its target is the slot
offset ``l* = (l_x*, l_y*)`` (eq 14). With the errors ``e = l* - l`` (eq 16) the
law below makes the closed loop exactly ``de_x/dt = -k1 e_x``,
``de_y/dt = -k2 e_y`` (eq 24) for any leader motion, as long as the robot's
limits do not saturate. The printed eq 26-27 swap sin/cos and a sign; the
derivation is in ``docs/methods/formation_law.md`` and the decay rates are
checked by ``tests/test_formation_law.py``. :func:`formation_tracking_law_fast`
is the same law in numba, bit-identical, for the per-step controller.

Both take one leader state for every row, or one per row (``(N, 5)``, e.g.
:meth:`~dfcoa_opt.control.base.Observation.row_leader` of a batch of runs):
each row uses only its own leader, with the same float operations, so a row
gets the same bits in a batch as in its run alone.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from dfcoa_opt.core.geometry import wrap_angle
from dfcoa_opt.core.scalar_kernels import wrap1

FloatArray = NDArray[np.float64]


def tracking_point_coordinates(pose: ArrayLike, leader: ArrayLike, d: float) -> FloatArray:
    """Tracking point of each follower in the leader frame, eq 15.

    Args:
        pose: ``(N, 3)`` follower poses (x, y, theta) in m, m, rad.
        leader: Leader pose ``(x_l, y_l, theta_l, ...)`` (m, m, rad; extra entries
            ignored), or ``(N, >= 3)`` one per row.
        d: Distance from the robot centre to its tracking point, m.

    Returns:
        ``(N, 2)`` coordinates ``(l_x, l_y)`` in m.
    """
    p = np.asarray(pose, dtype=float)
    lead = np.asarray(leader, dtype=float)
    x_l, y_l, th_l = lead[..., 0], lead[..., 1], lead[..., 2]
    dx = p[:, 0] + d * np.cos(p[:, 2]) - x_l
    dy = p[:, 1] + d * np.sin(p[:, 2]) - y_l
    c, s = np.cos(th_l), np.sin(th_l)
    return np.column_stack((dx * c + dy * s, dy * c - dx * s))


def formation_errors(offsets: ArrayLike, pose: ArrayLike, leader: ArrayLike,
                     d: float) -> FloatArray:
    """Errors ``e = l* - l`` of eq 16, in the leader frame.

    Args:
        offsets: ``(N, 2)`` target coordinates ``l*`` of the tracking points
            (the slot offsets of eq 3-5 / eq 14), m.
        pose: ``(N, 3)`` follower poses (x, y, theta), m, m, rad.
        leader: Leader pose ``(x, y, theta, ...)``, or ``(N, >= 3)`` one per row.
        d: Tracking-point distance, m.

    Returns:
        ``(N, 2)`` errors ``(e_x, e_y)`` in m.
    """
    return np.asarray(offsets, dtype=float) - tracking_point_coordinates(pose, leader, d)


def formation_tracking_law(offsets: ArrayLike, pose: ArrayLike, leader: ArrayLike, k1: float,
                           k2: float, d: float) -> FloatArray:
    """Follower commands ``(v_f, w_f)`` giving ``de/dt = -diag(k1, k2) e`` (eq 24-28).

    From eq 20-21, ``dl/dt = R(delta) (v_f, d w_f) - (v_l - w_l l_y, w_l l_x)``
    with ``delta = th_f - th_l`` (eq 28) and ``R`` the rotation by ``delta``.
    Requiring eq 24 and solving:

    ``v_f = a cos(delta) + b sin(delta)``,
    ``w_f = (b cos(delta) - a sin(delta)) / d``,

    with ``a = k1 e_x + v_l - w_l l_y`` and ``b = k2 e_y + w_l l_x``.

    Args:
        offsets: ``(N, 2)`` targets ``l*`` in the leader frame, m.
        pose: ``(N, 3)`` follower poses (x, y, theta), m, m, rad.
        leader: Broadcast leader state ``(x, y, theta, v, w)`` (m, m, rad, m/s, rad/s),
            or ``(N, 5)`` the state each row received.
        k1: Longitudinal gain, 1/s (> 0).
        k2: Lateral gain, 1/s (> 0).
        d: Tracking-point distance, m (> 0).

    Returns:
        ``(N, 2)`` commands ``(v_f, w_f)`` in m/s and rad/s (unsaturated).
    """
    lead = np.asarray(leader, dtype=float)
    v_l, w_l = lead[..., 3], lead[..., 4]
    pose = np.asarray(pose, dtype=float)
    lxy = tracking_point_coordinates(pose, lead, d)
    e = np.asarray(offsets, dtype=float) - lxy
    a = k1 * e[:, 0] + v_l - w_l * lxy[:, 1]
    b = k2 * e[:, 1] + w_l * lxy[:, 0]
    delta = wrap_angle(pose[:, 2] - lead[..., 2])
    c, s = np.cos(delta), np.sin(delta)
    return np.column_stack((a * c + b * s, (b * c - a * s) / d))


@numba.njit(cache=True)
def _tracking_law_kernel(offsets: FloatArray, pose: FloatArray, leader: FloatArray, k1: float,
                         k2: float, d: float) -> FloatArray:  # pragma: no cover - numba
    """:func:`formation_tracking_law` row by row, same float operations in the same order.

    ``leader`` is ``(N, >= 5)``: row i's leader state in row i.
    """
    n = pose.shape[0]
    out = np.empty((n, 2))
    for i in range(n):
        x_l, y_l, th_l = leader[i, 0], leader[i, 1], leader[i, 2]
        v_l, w_l = leader[i, 3], leader[i, 4]
        c, s = math.cos(th_l), math.sin(th_l)
        th = pose[i, 2]
        dx = pose[i, 0] + d * math.cos(th) - x_l
        dy = pose[i, 1] + d * math.sin(th) - y_l
        l_x, l_y = dx * c + dy * s, dy * c - dx * s  # eq 15
        a = k1 * (offsets[i, 0] - l_x) + v_l - w_l * l_y
        b = k2 * (offsets[i, 1] - l_y) + w_l * l_x
        delta = wrap1(th - th_l)  # eq 28
        cd, sd = math.cos(delta), math.sin(delta)
        out[i, 0] = a * cd + b * sd
        out[i, 1] = (b * cd - a * sd) / d
    return out


def formation_tracking_law_fast(offsets: ArrayLike, pose: ArrayLike, leader: ArrayLike,
                                k1: float, k2: float, d: float) -> FloatArray:
    """:func:`formation_tracking_law` (eq 24-28) as one numba kernel, bit-identical.

    ``sin``, ``cos`` and the angle wrap give the same bits in numba as in NumPy
    (``tests/test_formation_law.py`` checks it); the NumPy function is the reference.

    Args:
        offsets: ``(N, 2)`` targets ``l*`` in the leader frame, m.
        pose: ``(N, 3)`` follower poses (x, y, theta), m, m, rad.
        leader: Broadcast leader state ``(x, y, theta, v, w)`` (m, m, rad, m/s, rad/s),
            or ``(N, 5)`` the state each row received.
        k1: Longitudinal gain, 1/s.
        k2: Lateral gain, 1/s.
        d: Tracking-point distance, m.

    Returns:
        ``(N, 2)`` commands ``(v_f, w_f)`` in m/s and rad/s (unsaturated).
    """
    p = np.asarray(pose, dtype=float).reshape(-1, 3)
    off = np.asarray(offsets, dtype=float).reshape(len(p), 2)
    lead = np.asarray(leader, dtype=float)
    lead = lead.reshape(1, -1) if lead.ndim < 2 else lead
    if lead.ndim != 2 or lead.shape[1] < 5 or len(lead) not in (1, len(p)):
        raise ValueError("leader must be (x, y, theta, v, w), or one such row per pose")
    if len(lead) != len(p):
        lead = np.broadcast_to(lead, (len(p), lead.shape[1]))  # one state for every row
    return _tracking_law_kernel(off, p, lead, float(k1), float(k2), float(d))


def pose_error(leader: ArrayLike, d_a: ArrayLike, phi_a: ArrayLike,
               pose: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Algorithm 2 / eq 31: world-frame position error of each agent.

    Args:
        leader: Leader pose ``(x_v, y_v, theta_v, ...)``.
        d_a: ``(N,)`` target distances to the leader, m.
        phi_a: ``(N,)`` target angles in the leader frame, rad.
        pose: ``(N, 3)`` agent poses.

    Returns:
        ``(e, p_true)``: ``(N, 2)`` errors ``p_true - p_a`` and ``(N, 2)`` expected
        positions, m.
    """
    x_v, y_v, th_v = np.asarray(leader, dtype=float)[:3]
    d_a, phi_a = np.asarray(d_a, dtype=float), np.asarray(phi_a, dtype=float)
    p_true = np.column_stack((x_v + d_a * np.cos(phi_a + th_v), y_v + d_a * np.sin(phi_a + th_v)))
    return p_true - np.asarray(pose, dtype=float)[:, :2], p_true
