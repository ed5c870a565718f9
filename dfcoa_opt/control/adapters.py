"""Command-kind adapters: run any controller on any robot model.

Kinds: ``unicycle`` (v, omega), ``velocity`` (vx, vy) and ``acceleration``
(ax, ay), all per robot. The conversions:

* velocity -> unicycle: the near-identity diffeomorphism (NID). The point
  ``l`` metres ahead of the axle, ``p + l (cos th, sin th)``, has the velocity
  ``R(th) [v, l w]^T``; inverting gives ``v = cos th vx + sin th vy`` and
  ``w = (-sin th vx + cos th vy) / l``. That point then moves exactly with the
  commanded velocity (until the limits saturate). ``l`` is
  ``robots.nid_distance``.
* acceleration -> velocity: integrate one step, ``v_des = v + a dt``.
* velocity -> acceleration: reach the velocity in one step, ``a = (v_des - v) / dt``
  (the model then clips to ``a_max``).
* unicycle -> velocity / acceleration: ``(v cos th, v sin th)`` plus a third
  column ``w``; holonomic models turn their heading at that rate, so a
  unicycle command moves them exactly like a unicycle (Euler step).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.world.robots.models import CommandKind

FloatArray = NDArray[np.float64]

KINDS: tuple[CommandKind, ...] = ("unicycle", "velocity", "acceleration")


def velocity_to_unicycle(vel: FloatArray, theta: FloatArray, nid_distance: float) -> FloatArray:
    """Near-identity diffeomorphism: world velocity of the offset point -> (v, omega).

    Args:
        vel: ``(N, 2)`` desired world velocity of the point ``nid_distance`` ahead, m/s.
        theta: ``(N,)`` headings, rad.
        nid_distance: Offset ``l`` of that point, m (> 0).

    Returns:
        ``(N, 2)`` (v m/s, omega rad/s).
    """
    c, s = np.cos(theta), np.sin(theta)
    v = c * vel[:, 0] + s * vel[:, 1]
    w = (-s * vel[:, 0] + c * vel[:, 1]) / nid_distance
    return np.stack((v, w), axis=1)


def unicycle_to_velocity(cmd: FloatArray, theta: FloatArray) -> FloatArray:
    """(v, omega) -> ``(N, 3)`` (vx, vy, omega) for holonomic models."""
    return np.stack((cmd[:, 0] * np.cos(theta), cmd[:, 0] * np.sin(theta), cmd[:, 1]), axis=1)


def convert(cmd: FloatArray, src: CommandKind, dst: CommandKind, pose: FloatArray,
            velocity: FloatArray, dt: float, nid_distance: float) -> FloatArray:
    """Convert commands of kind ``src`` to kind ``dst``.

    Args:
        cmd: ``(N, k)`` commands of kind ``src``.
        src: Kind produced by the controller.
        dst: Kind the consumer (robot model or safety filter) takes.
        pose: ``(N, 3)`` current poses (m, m, rad).
        velocity: ``(N, 2)`` current world velocities, m/s.
        dt: Step, s.
        nid_distance: Near-identity offset, m.

    Returns:
        ``(N, k')`` commands of kind ``dst`` (holonomic kinds may carry a third
        column, the heading rate in rad/s).
    """
    if src == dst:
        return cmd
    if src not in KINDS or dst not in KINDS:
        raise ValueError(f"unknown command kind {src!r} or {dst!r}")
    theta = pose[:, 2]
    if src == "acceleration":
        vel = velocity + cmd[:, :2] * dt
        vel = np.column_stack((vel, cmd[:, 2:])) if cmd.shape[1] > 2 else vel
        return convert(vel, "velocity", dst, pose, velocity, dt, nid_distance)
    if src == "unicycle":
        vel3 = unicycle_to_velocity(cmd, theta)
        return convert(vel3, "velocity", dst, pose, velocity, dt, nid_distance)
    # src == "velocity"
    if dst == "unicycle":
        return velocity_to_unicycle(cmd[:, :2], theta, nid_distance)
    acc = (cmd[:, :2] - velocity) / dt
    return np.column_stack((acc, cmd[:, 2:])) if cmd.shape[1] > 2 else acc
