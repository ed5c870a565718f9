"""The Boxes of the environments: one robot's action and one robot's observation vector.

Bounds as arrays (numpy only); the environments build their ``gymnasium.spaces.Box``
from them. Tables: ``docs/envs.md`` ("Observation", "Action").
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.control.features import ObservationSpec
from dfcoa_opt.world.robots.models import CommandKind
from dfcoa_opt.world.robots.spec import RobotSpec

FloatArray = NDArray[np.float64]


def action_bounds(robots: RobotSpec, kind: CommandKind) -> tuple[FloatArray, FloatArray]:
    """The Box of one robot's action: its command kind within the robot's limits.

    Args:
        robots: The scenario's ``[robots]``.
        kind: The robot model's command kind.

    Returns:
        ``low`` and ``high``, each ``(2,)``: (v m/s, omega rad/s) in
        ``[v_lower, v_max] x [-w_max, w_max]`` for a unicycle; (vx, vy) m/s in
        ``[-v_max, v_max]^2`` for a single integrator, (ax, ay) m/s^2 in
        ``[-a_max, a_max]^2`` for a double one (the model also caps the norm).
    """
    if kind == "unicycle":
        return (np.array([robots.v_lower, -robots.w_max]),
                np.array([robots.v_max, robots.w_max]))
    limit = robots.v_max if kind == "velocity" else robots.a_max
    return np.full(2, -limit), np.full(2, limit)


def observation_bounds(spec: ObservationSpec) -> tuple[FloatArray, FloatArray]:
    """The Box of one robot's observation vector (``docs/envs.md``, "Observation").

    Bounded blocks: ``heading`` in [-1, 1], ``lidar`` in [0, 1], every
    ``present`` flag in [0, 1], moving-obstacle radii in [0, inf). The relative
    positions and velocities are unbounded (a robot can be anywhere relative to
    its slot), so their bounds are infinite.

    Returns:
        ``low`` and ``high``, each ``(spec.size,)``.
    """
    lay = spec.layout()
    low, high = np.full(spec.size, -np.inf), np.full(spec.size, np.inf)
    for name, lo, hi in (("heading", -1.0, 1.0), ("lidar", 0.0, 1.0)):
        low[lay[name]], high[lay[name]] = lo, hi
    nb_lo, nb_hi = low[lay["neighbours"]].reshape(-1, 5), high[lay["neighbours"]].reshape(-1, 5)
    nb_lo[:, 4], nb_hi[:, 4] = 0.0, 1.0
    ob_lo, ob_hi = low[lay["obstacles"]].reshape(-1, 6), high[lay["obstacles"]].reshape(-1, 6)
    ob_lo[:, 4:6], ob_hi[:, 5] = 0.0, 1.0
    return low, high
