"""Per-robot metrics of the companion papers' tables (papers 002 and 004).

Pure functions of a :class:`~dfcoa_opt.sim.log.RunLog`, ``(N,)`` per robot or
``(T, N)`` per step and robot; :func:`dfcoa_opt.metrics.summary` turns them
into JSON keys. Definitions: ``docs/metrics.md``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

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
