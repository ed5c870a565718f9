"""Equations of paper 002 used by the ``lf_vo`` controller (pure, vectorised numpy).

Shapes: ``N`` robots, ``S`` velocity samples per robot, ``H`` horizon steps,
``Q`` obstacles per robot. Every function works row by row: row ``i`` of each
output depends on row ``i`` of the inputs only.

* :func:`formation_target` -- eq 5-6 (V-formation targets).
* :func:`target_error` -- eq 7-11 (distance and angle to the target).
* :func:`reference_command` -- eq 4 (pure pursuit towards the target).
* :func:`rollout` and :func:`path_clearance` -- the sampled velocity obstacle of
  eq 12, checked on the predicted unicycle path over a finite horizon.
* :func:`vo_cost` -- the penalties that choose among the safe samples.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dfcoa_opt.core.geometry import body_to_world, wrap_angle

FloatArray = NDArray[np.float64]


def formation_target(leader_pose: ArrayLike, offset: ArrayLike) -> FloatArray:
    """Eq 5-6: ``x_T = x_L - d cos(theta_L + phi)``, ``y_T = y_L - d sin(theta_L + phi)``.

    The toolkit stores a slot as a Cartesian offset in the leader frame; an
    offset ``o`` is eq 5-6's ``(d, phi)`` with ``o = -d (cos phi, sin phi)``,
    i.e. ``d = |o|`` and ``phi = atan2(-o_y, -o_x)``. The V of
    :func:`dfcoa_opt.scenario.formation.v_offsets` has ``d = rank * spacing`` and
    ``phi = -angle`` (left wing) or ``+angle`` (right wing).

    Args:
        leader_pose: ``(..., 3)`` leader pose (x m, y m, theta rad).
        offset: ``(..., 2)`` target offsets in the leader frame, m.

    Returns:
        ``(..., 2)`` world targets, m.
    """
    # -d (cos(theta + phi), sin(theta + phi)) = R(theta) o: the leader-frame offset in the world
    return body_to_world(leader_pose, offset)


def target_error(pose: ArrayLike, target: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Eq 7-11: offsets, distance, target direction and orientation difference.

    ``l_x = x_T - x_F`` (7), ``l_y = y_T - y_F`` (8), ``l = sqrt(l_x^2 + l_y^2)``
    (9), ``theta_T = atan2(l_y, l_x)`` (10; the paper's garbled ``atan^-1(l_x /
    l_y)`` read as the direction from the robot to its target, which the text
    states), ``alpha = theta_F - theta_T`` (11), wrapped to (-pi, pi].

    Args:
        pose: ``(..., 3)`` robot pose (x m, y m, theta rad).
        target: ``(..., 2)`` target position, m.

    Returns:
        ``(l m, theta_T rad, alpha rad)``, each of shape ``(...)``.
    """
    p = np.asarray(pose, dtype=float)
    tg = np.asarray(target, dtype=float)
    lx = tg[..., 0] - p[..., 0]
    ly = tg[..., 1] - p[..., 1]
    dist = np.hypot(lx, ly)
    theta_t = np.arctan2(ly, lx)
    alpha = wrap_angle(p[..., 2] - theta_t)
    return dist, theta_t, alpha


def reference_command(dist: ArrayLike, alpha: ArrayLike, v_max: ArrayLike, w_max: float,
                      reach_time: float, turn_when_behind: bool = True,
                      arrival_radius: float = 0.0) -> tuple[FloatArray, FloatArray]:
    """Eq 4 with eq 11's angle: the preferred (v, omega) towards the target.

    ``v = min(l / t, v_max)`` and pure pursuit ``omega = 2 v sin(a) / L_d`` with
    the look-ahead distance ``L_d = l`` (the target is the look-ahead point) and
    ``a = theta_T - theta = -alpha`` (eq 1 measures the bearing of the target
    from the heading; eq 11 measures the opposite difference). ``omega`` is
    clipped to ``[-w_max, w_max]``. Within ``arrival_radius`` of the target
    (a decision, not in the paper) the command is (0, 0): a unicycle cannot
    turn onto a point it has reached, and pure pursuit's turn rate
    ``2 v sin(a) / l`` grows without bound as ``l -> 0``.

    With ``turn_when_behind`` (a decision, not in the paper), a target behind
    the robot (``cos(alpha) < 0``) gives ``v = 0`` and ``omega = w_max`` towards it
    (left when exactly behind): pure pursuit's ``sin(a)`` vanishes as ``a -> pi``
    and the robot would drive away from a target it has overtaken.

    Args:
        dist: ``(...)`` distance l to the target, m.
        alpha: ``(...)`` eq 11 orientation difference, rad.
        v_max: Largest speed, m/s, broadcastable to ``dist``.
        w_max: Largest turn rate, rad/s.
        reach_time: Time interval t of eq 4, s.
        turn_when_behind: Turn in place towards a target behind the robot.
        arrival_radius: Stop within this distance of the target, m (at least 1e-12).

    Returns:
        ``(v m/s, omega rad/s)``.
    """
    dist = np.asarray(dist, dtype=float)
    alpha = np.asarray(alpha, dtype=float)
    away = dist > max(arrival_radius, 1e-12)
    v = np.where(away, np.minimum(dist / reach_time, v_max), 0.0)
    safe = np.where(away, dist, 1.0)
    w = np.where(away, 2.0 * v * np.sin(-alpha) / safe, 0.0)
    w = np.clip(w, -w_max, w_max)
    if turn_when_behind:
        behind = (np.cos(alpha) < 0.0) & away
        v = np.where(behind, 0.0, v)
        w = np.where(behind, np.where(np.sin(-alpha) < 0.0, -w_max, w_max), w)
    return v, w


def rollout(pose: ArrayLike, v: ArrayLike, w: ArrayLike, step: float, steps: int,
            turn_time: float) -> FloatArray:
    """Predicted positions of unicycles for ``steps`` steps of each (v, omega) sample.

    A sample turns at ``omega`` for ``turn_time`` and then goes straight at the
    heading ``theta + omega * turn_time`` reached, at speed ``v``: the straight
    part is eq 12's ray, the first part the unicycle's way of getting there.
    Midpoint integration (heading at the middle of each step), exact on the
    straight part.

    Args:
        pose: ``(N, 3)`` current poses (x m, y m, theta rad).
        v: ``(N, S)`` sampled speeds, m/s.
        w: ``(N, S)`` sampled turn rates, rad/s.
        step: Prediction step, s.
        steps: Number of prediction steps H.
        turn_time: How long the sample's turn rate is held, s.

    Returns:
        ``(N, S, H, 2)`` positions after steps 1..H, m.
    """
    p = np.asarray(pose, dtype=float)
    v = np.asarray(v, dtype=float)[..., None]
    w = np.asarray(w, dtype=float)[..., None]
    t_mid = np.minimum((np.arange(steps, dtype=float) + 0.5) * step, turn_time)
    heading = p[:, None, None, 2] + w * t_mid  # (N, S, H)
    dx = np.cumsum(v * step * np.cos(heading), axis=-1)
    dy = np.cumsum(v * step * np.sin(heading), axis=-1)
    return p[:, None, None, :2] + np.stack((dx, dy), axis=-1)


def path_clearance(points: ArrayLike, step: float, centres: ArrayLike, velocities: ArrayLike,
                   reach: ArrayLike, mask: ArrayLike) -> FloatArray:
    """Smallest gap between predicted paths and constant-velocity discs (< 0: collision).

    Eq 12's velocity obstacle is the set of velocities whose relative path
    ``lambda(p_A, v_A - v_B)`` meets the Minkowski sum ``B (+) -A``; here the
    robot's predicted unicycle path is compared with the obstacle's straight
    path at the same instants ``step * (1..H)``, and the discs are inflated by
    ``reach`` (obstacle radius + robot radius + margin). A sample lies in the
    (truncated) VO exactly when its clearance is negative.

    Args:
        points: ``(N, S, H, 2)`` predicted robot positions (from :func:`rollout`), m.
        step: Prediction step, s.
        centres: ``(N, Q, 2)`` obstacle centres now, m.
        velocities: ``(N, Q, 2)`` obstacle velocities, m/s (0 for static discs).
        reach: ``(N, Q)`` collision distance between centres, m.
        mask: ``(N, Q)`` True where obstacle q is real (False = padding).

    Returns:
        ``(N, S)`` clearance in m (``inf`` when the robot has no obstacle).
    """
    pts = np.asarray(points, dtype=float)
    n, s, h = pts.shape[:3]
    c = np.asarray(centres, dtype=float)
    if c.shape[1] == 0:
        return np.full((n, s), np.inf)
    t = step * (np.arange(h, dtype=float) + 1.0)
    future = c[:, None, :, :] + t[None, :, None, None] * np.asarray(velocities)[:, None]  # N,H,Q,2
    gap = np.linalg.norm(pts[:, :, :, None, :] - future[:, None], axis=-1)  # (N, S, H, Q)
    gap = gap - np.asarray(reach, dtype=float)[:, None, None, :]
    gap = np.where(np.asarray(mask, dtype=bool)[:, None, None, :], gap, np.inf)
    return gap.min(axis=(2, 3))


def vo_cost(theta: ArrayLike, v: ArrayLike, w: ArrayLike, v_ref: ArrayLike, w_ref: ArrayLike,
            theta_t: ArrayLike, tau: float, pref_weight: float,
            heading_weight: float, turn_weight: float = 0.0) -> FloatArray:
    """Penalty of each sample: distance to the preferred velocity + target-direction consistency.

    A sample (v, w) stands for the world velocity ``V(v, w) = v (cos psi, sin psi)``
    at the heading it aims for, ``psi = theta + w tau`` (``tau`` = the turn time
    of :func:`rollout`). With ``e_T = (cos theta_T, sin theta_T)``::

        J = pref_weight * |V(v, w) - V(v_ref, w_ref)|
            + heading_weight * max(0, v_ref - V(v, w) . e_T)
            + turn_weight * |w - w_ref|

    The second term is the shortfall of the progress towards the target below
    the preferred speed: 0 for a sample that moves towards the target at least
    as fast as preferred, ``v_ref`` for stopping. (An angle penalty
    ``|psi - theta_T|`` makes stopping in front of a disc cheaper than going
    round it: the robots deadlock.) The third term, small, breaks ties: every
    sample with ``v = 0`` has the same first two terms, and without it a robot
    that stands still turns at the grid's first turn rate, ``-w_max``.

    Args:
        theta: ``(N,)`` current headings, rad.
        v: ``(N, S)`` sampled speeds, m/s (or ``(N, ...)``, with ``w`` broadcastable).
        w: ``(N, S)`` sampled turn rates, rad/s (or broadcastable to ``v``, e.g. a
            speed-major grid as ``v (N, V, W)`` and ``w (1, 1, W)``: the same values
            as the flat call, with the trigonometry done once per turn rate).
        v_ref: ``(N,)`` preferred speeds (eq 4), m/s.
        w_ref: ``(N,)`` preferred turn rates (eq 4), rad/s.
        theta_t: ``(N,)`` target directions (eq 10), rad.
        tau: Time over which the heading turns, s.
        pref_weight: Weight of the velocity distance, s/m.
        heading_weight: Weight of the progress shortfall, s/m.
        turn_weight: Weight of the turn-rate distance to ``w_ref``, s/rad.

    Returns:
        ``(N, S)`` costs (dimensionless), or the broadcast shape of ``v`` and ``w``.
    """
    v, w = np.asarray(v, dtype=float), np.asarray(w, dtype=float)
    shape = (-1,) + (1,) * (max(v.ndim, w.ndim) - 1)  # (N, 1, ...): one value per robot

    def per_robot(a: ArrayLike) -> FloatArray:
        return np.asarray(a, dtype=float).reshape(shape)

    th = per_robot(theta)
    psi = th + w * tau
    psi_ref = th + per_robot(w_ref) * tau
    vr = per_robot(v_ref)
    dvx = v * np.cos(psi) - vr * np.cos(psi_ref)
    dvy = v * np.sin(psi) - vr * np.sin(psi_ref)
    progress = v * np.cos(psi - per_robot(theta_t))
    return (pref_weight * np.hypot(dvx, dvy) + heading_weight * np.maximum(vr - progress, 0.0)
            + turn_weight * np.abs(w - per_robot(w_ref)))
