"""Per-robot metrics of the companion papers' tables (papers 002 and 004).

Pure functions of a :class:`~dfcoa_opt.sim.log.RunLog`, ``(N,)`` per robot or
``(T, N)`` per step and robot; :func:`dfcoa_opt.metrics.summary` turns them
into JSON keys. Definitions: ``docs/metrics.md``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.core.geometry import body_to_world
from dfcoa_opt.sim.log import RunLog

FloatArray = NDArray[np.float64]


def path_length_per_robot(log: RunLog) -> FloatArray:
    """Length of each robot's polyline through its logged positions, ``(N,)`` in m."""
    return np.linalg.norm(np.diff(log.pose[..., :2], axis=0), axis=-1).sum(axis=0)



def average_velocities_per_robot(log: RunLog) -> tuple[FloatArray, FloatArray]:
    """Time means of each robot's v (m/s) and signed omega (rad/s), paper 002 Tables II-IV."""
    avg = log.twist.mean(axis=0)
    return avg[:, 0], avg[:, 1]


def mean_abs_angular_velocity_per_robot(log: RunLog) -> FloatArray:
    """Time mean of each robot's |omega|, ``(N,)`` in rad/s (companion of paper 002)."""
    return np.abs(log.twist[..., 1]).mean(axis=0)


def distance_travelled(log: RunLog) -> FloatArray:
    """Distance travelled per robot (paper 002 Tables II-IV), ``(N,)`` in m."""
    return path_length_per_robot(log)


def leader_follower_position_error(log: RunLog) -> FloatArray:
    """Position error ``||p_i - slot_i||`` (papers 002 and 004), ``(T, N)`` in m."""
    return np.linalg.norm(log.pose[..., :2] - log.slots, axis=-1)


def formation_position_error_per_robot(log: RunLog) -> FloatArray:
    """Time mean of ``||p_i - slot_i||`` (paper 002 Tables II-IV), ``(N,)`` in m.

    Robot 0 is included; the caller picks the followers.
    """
    return leader_follower_position_error(log).mean(axis=0)


def mse_per_robot(log: RunLog) -> FloatArray:
    """Squared distance to the ideal position (the slot), paper 004 eq 14, ``(T, N)`` m^2."""
    return np.sum(np.square(log.pose[..., :2] - log.slots), axis=-1)


def leader_robot_target_error(log: RunLog, leader_index: int = 0,
                              frame_heading: float | None = None) -> FloatArray:
    """Follower error against its eq 5-6 target around the leader robot (paper 002), ``(T, N)`` m.

    Paper 002 defines the formation position error as "the difference between
    the target position of the follower robot and the actual position", the
    target being eq 5-6 applied to the leader robot's pose:
    ``x_T = x_L + R(theta_L) (o_i - o_L)`` with the leader-frame slot offsets
    ``o`` of ``log.offsets``. Unlike :func:`leader_follower_position_error`
    (against the virtual leader's slots), this follows the leader robot's real
    pose. The leader robot's own column is 0. With ``frame_heading`` the
    offsets are turned by that fixed angle instead of the leader robot's
    heading: paper 004's constant world-frame errors ``E_i``, where the
    follower's target is ``p_L + E_i`` (eq 4-5).

    Args:
        log: The run log.
        leader_index: Column of the leader robot.
        frame_heading: Fixed heading of the offsets' frame, rad; default: the
            leader robot's logged heading.

    Returns:
        ``(T, N)`` distances ``||p_i - x_T,i||``, m.
    """
    lead = log.pose[:, leader_index].copy()  # (T, 3)
    if frame_heading is not None:
        lead[:, 2] = frame_heading
    rel = log.offsets - log.offsets[leader_index]  # (N, 2)
    target = body_to_world(lead[:, None, :], rel[None, :, :])
    return np.linalg.norm(log.pose[..., :2] - target, axis=-1)


def _onsets(touch: NDArray[np.bool_]) -> NDArray[np.int64]:
    """Count False -> True transitions along axis 0 (a contact already at t_0 counts)."""
    before = np.concatenate((np.zeros_like(touch[:1]), touch[:-1]), axis=0)
    return np.sum(touch & ~before, axis=0)


def collisions_per_robot(log: RunLog) -> NDArray[np.int64]:
    """Collision events each robot takes part in (paper 002 Tables II-IV), ``(N,)``.

    An event is the start of a contact, as in the simulator's
    ``collision_events``: with a static obstacle (``clearance < r``), with a
    moving obstacle (centre distance ``< r + r_k``) or with another robot
    (``< 2 r``; the event counts for both robots). Summed over robots, robot
    pairs count twice.

    Args:
        log: The run log.

    Returns:
        ``(N,)`` event counts.
    """
    r = float(log.meta["robot_radius"])
    pos = log.pose[..., :2]
    count = _onsets(log.clearance < r)
    if log.dyn_pos.shape[1]:
        gap = np.linalg.norm(pos[:, :, None, :] - log.dyn_pos[:, None, :, :], axis=-1)
        count = count + _onsets(gap < r + log.dyn_radius[None, None, :]).sum(axis=1)
    pair = np.linalg.norm(pos[:, :, None, :] - pos[:, None, :, :], axis=-1) < 2.0 * r
    pair &= ~np.eye(log.n_robots, dtype=bool)[None]
    return count + _onsets(pair).sum(axis=1)
