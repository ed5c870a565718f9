"""The deployability report of a run: whether its commands would run on its robot.

Every key is a pure function of a :class:`~dfcoa_opt.sim.log.RunLog` and its
``meta["robots"]`` (the run's ``[robots]`` table); docs/metrics.md defines them
and docs/robots.md says how to read them.

- What the controller asked of the wheels: its logged command, turned into the
  robot model's ``(v, omega)`` by the simulator's own adapter (with the pose
  and velocity it was given), then into wheel speeds by the inverse of paper
  000 eq 2. ``wheel_speed_peak`` is the largest of them, ``wheel_speed_ratio``
  its ratio to the robot's wheel limit, ``wheel_accel_peak`` the largest change
  of a wheel's rim speed between two steps over ``dt`` (from rest at t = 0),
  ``wheel_accel_ratio`` its ratio to the acceleration limit (:func:`accel_limit_of`),
  and ``saturated_pct`` the share of robot-steps whose command the robot could
  not follow as asked (v, omega or a wheel beyond its limit).
- ``body_gap_min``: the smallest distance between two robot bodies (centre
  distance less two radii; negative in contact).
- With ``robots.profile = "gritsbot"``, the Robotarium's checks
  (:data:`~dfcoa_opt.world.robots.profiles.ROBOTARIUM`): ``robotarium_arena`` (every
  robot centre fits in the arena's width and height, wherever the run is
  placed in it), ``robotarium_collision`` (no two collision discs, centred
  ``collision_offset`` ahead of each robot as the Robotarium places them,
  closer than the collision diameter), ``robotarium_speed`` (no wheel asked beyond the
  Robotarium's wheel limit) and ``robotarium_ok`` (all three). ``None`` with
  any other robot.

Holonomic models have no wheels: their wheel keys are NaN.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.distance import pdist

from dfcoa_opt.control.adapters import convert
from dfcoa_opt.sim.log import RunLog
from dfcoa_opt.world.robots.models import wheel_speeds

FloatArray = NDArray[np.float64]

#: Slack (m/s, rad/s) within which a command counts as within a limit (rounding).
LIMIT_TOL = 1e-9

#: The keys of :func:`deployability`, in report order.
DEPLOY_KEYS = ("wheel_speed_peak", "wheel_speed_ratio", "wheel_accel_peak", "wheel_accel_ratio",
               "saturated_pct",
               "body_gap_min", "robotarium_arena", "robotarium_collision", "robotarium_speed",
               "robotarium_ok")


def _robots(log: RunLog) -> dict[str, Any] | None:
    return log.meta.get("robots")


def commanded_twist(log: RunLog) -> FloatArray | None:
    """``(T, N, 2)`` the (v m/s, omega rad/s) the controller asked, before any limit.

    None when the robots are not unicycles (or the log has no ``meta["robots"]``).
    """
    robots = _robots(log)
    if robots is None or robots.get("model") != "unicycle":
        return None
    cmd, t_steps, n = log.command, log.n_steps, log.n_robots
    kind = log.meta.get("command_kind", "unicycle")
    flat = convert(cmd.reshape(t_steps * n, -1), kind, "unicycle",
                   log.pose_est.reshape(-1, 3), log.velocity.reshape(-1, 2),
                   float(log.meta["dt"]), float(robots["nid_distance"]))
    return np.asarray(flat, dtype=float)[:, :2].reshape(t_steps, n, 2)


def commanded_wheel_speeds(log: RunLog, twist: FloatArray | None = None) -> FloatArray | None:
    """``(T, N, 2)`` the (right, left) wheel speeds asked, rad/s (paper 000 eq 2 inverted).

    ``twist``: :func:`commanded_twist` of the log, when already computed.
    """
    twist = commanded_twist(log) if twist is None else twist
    if twist is None:
        return None
    robots = _robots(log)
    r, d = float(robots["wheel_radius"]), float(robots["track_width"])  # type: ignore[index]
    return np.stack(wheel_speeds(twist[..., 0], twist[..., 1], r, d), axis=-1)


def saturated(log: RunLog, twist: FloatArray | None = None) -> NDArray[np.bool_] | None:
    """``(T, N)`` whether the robot could not follow the command as asked (v, omega, a wheel).

    ``twist``: :func:`commanded_twist` of the log, when already computed.
    """
    twist = commanded_twist(log) if twist is None else twist
    if twist is None:
        return None
    robots = _robots(log)
    assert robots is not None
    v, w = twist[..., 0], twist[..., 1]
    v_max = float(robots["v_max"])
    v_min = -v_max if robots.get("v_min") is None else float(robots["v_min"])
    w_max = float(robots["w_max"])
    tol = LIMIT_TOL
    out = (v > v_max + tol) | (v < v_min - tol) | (np.abs(w) > w_max + tol)
    wheel_max = float(robots["wheel_speed_max"])
    if math.isfinite(wheel_max):
        vc, wc = np.clip(v, v_min, v_max), np.clip(w, -w_max, w_max)
        right, left = wheel_speeds(vc, wc, float(robots["wheel_radius"]),
                                   float(robots["track_width"]))
        peak = np.maximum(np.abs(right), np.abs(left))
        out |= peak > wheel_max + tol
    return out


def accel_limit_of(robots: dict[str, Any]) -> float:
    """The wheel acceleration limit a run is judged against, m/s^2 (inf: none).

    The robot's own (``dynamics = "actuated"``), else its profile's: a kinematic
    run with a profile is judged against the robot it stands for.
    """
    own = float(robots.get("wheel_accel_max", math.inf))
    if math.isfinite(own) or robots.get("profile") is None:
        return own
    from dfcoa_opt.world.robots.profiles import PROFILES

    return float(PROFILES[str(robots["profile"])]["robots"]["wheel_accel_max"])


def body_gap_min(log: RunLog) -> float:
    """Smallest distance between two robot bodies over the run, m (NaN with one robot)."""
    gap = float(np.min(log.min_inter_robot)) if log.n_steps else math.inf
    if not math.isfinite(gap):
        return math.nan
    return gap - 2.0 * float(log.meta["robot_radius"])


def robotarium_gap(log: RunLog) -> float:
    """Smallest distance between two robots' Robotarium collision centres over the run, m.

    The Robotarium puts each robot's collision disc ``collision_offset`` ahead of
    its pose, along its heading (:data:`~dfcoa_opt.world.robots.profiles.ROBOTARIUM`).
    """
    from dfcoa_opt.world.robots.profiles import ROBOTARIUM

    if log.n_robots < 2:
        return math.inf
    off = float(ROBOTARIUM["collision_offset"])  # type: ignore[arg-type]
    th = log.pose[..., 2]
    centre = log.pose[..., :2] + off * np.stack((np.cos(th), np.sin(th)), axis=-1)
    return float(min(pdist(c).min() for c in centre))


def robotarium_checks(log: RunLog, wheels: FloatArray | None) -> dict[str, bool | None]:
    """The Robotarium's checks of a gritsbot run (module docstring); None for other robots."""
    keys = ("robotarium_arena", "robotarium_collision", "robotarium_speed", "robotarium_ok")
    robots = _robots(log)
    if robots is None or robots.get("profile") != "gritsbot" or not log.n_steps:
        return dict.fromkeys(keys)
    from dfcoa_opt.world.robots.profiles import ROBOTARIUM

    _, _, width, height = ROBOTARIUM["boundaries"]  # type: ignore[misc]
    xy = log.pose[..., :2].reshape(-1, 2)
    span = xy.max(axis=0) - xy.min(axis=0)
    arena = bool(span[0] <= width and span[1] <= height)
    collision = robotarium_gap(log) >= float(ROBOTARIUM["collision_diameter"])  # type: ignore[arg-type]
    limit = float(ROBOTARIUM["max_wheel_velocity"])  # type: ignore[arg-type]
    speed = bool(wheels is None or np.max(np.abs(wheels)) <= limit + LIMIT_TOL)
    return dict(zip(keys, (arena, collision, speed, arena and collision and speed), strict=True))


def deployability(log: RunLog) -> dict[str, Any]:
    """The deployability keys of a run (:data:`DEPLOY_KEYS`, module docstring)."""
    twist = commanded_twist(log)
    wheels = commanded_wheel_speeds(log, twist)
    out: dict[str, Any] = {"wheel_speed_peak": math.nan, "wheel_speed_ratio": math.nan,
                           "wheel_accel_peak": math.nan, "wheel_accel_ratio": math.nan,
                           "saturated_pct": math.nan}
    if wheels is not None and log.n_steps:
        robots = _robots(log)
        assert robots is not None
        peak = float(np.max(np.abs(wheels)))
        limit = float(robots["wheel_speed_max"])
        rim = wheels * float(robots["wheel_radius"])
        change = np.diff(rim, axis=0, prepend=np.zeros((1, *rim.shape[1:])))
        sat = saturated(log, twist)
        assert sat is not None
        accel = float(np.max(np.abs(change))) / float(log.meta["dt"])
        accel_limit = accel_limit_of(robots)
        out.update(wheel_speed_peak=peak,
                   wheel_speed_ratio=peak / limit if math.isfinite(limit) else math.nan,
                   wheel_accel_peak=accel,
                   wheel_accel_ratio=accel / accel_limit if math.isfinite(accel_limit)
                   else math.nan,
                   saturated_pct=100.0 * float(np.mean(sat)))
    out["body_gap_min"] = body_gap_min(log)
    out.update(robotarium_checks(log, wheels))
    return out
