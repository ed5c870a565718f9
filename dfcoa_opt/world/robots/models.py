"""Batched kinematic robot models (one row per robot).

State of every model: ``pose (N, 3)`` = (x, y, theta) in m, m, rad and
``velocity (N, 2)`` = world-frame (vx, vy) in m/s, plus the applied
``twist (N, 2)`` = (v, omega) in m/s, rad/s that the metrics use.

* :class:`Unicycle` -- differential drive, command (v, omega). Wheel mapping of
  paper 000 eq 1-2; v, omega and wheel speeds saturate (the wheel limit scales
  both wheels by one factor, which keeps the path curvature). Integrated
  exactly along the arc for a constant (v, omega) over the step.
* :class:`ActuatedUnicycle` -- the same with wheel acceleration limits and
  motor lag (``robots.dynamics = "actuated"``, :mod:`dfcoa_opt.world.robots.actuated`).
* :class:`SingleIntegrator` -- command (vx, vy[, omega]).
* :class:`DoubleIntegrator` -- command (ax, ay[, omega]); paper 001 eq 1 and
  paper 004 eq 3: ``p+ = p + T v``, ``v+ = v + T u`` (explicit Euler).

Holonomic models carry a heading too: with a third command column it turns at
that rate (so a unicycle command runs exactly), otherwise it points along the
velocity when moving.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.core.geometry import wrap_angle
from dfcoa_opt.world.robots.actuated import actuated_step
from dfcoa_opt.world.robots.spec import RobotSpec
from dfcoa_opt.world.robots.unicycle_kernel import unicycle_step

FloatArray = NDArray[np.float64]
CommandKind = Literal["unicycle", "velocity", "acceleration"]

#: Speeds below this (m/s) leave a holonomic robot's heading unchanged.
HEADING_SPEED_EPS = 1e-9
_NO_DISTURBANCE = np.zeros((0, 2))


@dataclass(frozen=True)
class RobotState:
    """State of N robots.

    Attributes:
        pose: ``(N, 3)`` x, y in m and heading in rad.
        velocity: ``(N, 2)`` world-frame velocity in m/s.
        twist: ``(N, 2)`` applied forward speed (m/s) and turn rate (rad/s).
        wheels: ``(N, 2)`` wheel speeds (right, left) in rad/s of actuated robots
            (None: kinematic models, and actuated robots at rest).
    """

    pose: FloatArray
    velocity: FloatArray
    twist: FloatArray
    wheels: FloatArray | None = None

    def rows(self, keep: NDArray[np.bool_] | slice) -> RobotState:
        """The state of the rows ``keep`` selects."""
        return RobotState(self.pose[keep], self.velocity[keep], self.twist[keep],
                          None if self.wheels is None else self.wheels[keep])

    def insert(self, at: int, pose: FloatArray) -> RobotState:
        """The state with robots at rest at ``pose (n, 3)`` inserted before row ``at``."""
        n = len(pose)
        return RobotState(np.insert(self.pose, at, pose, axis=0),
                          np.insert(self.velocity, at, np.zeros((n, 2)), axis=0),
                          np.insert(self.twist, at, np.zeros((n, 2)), axis=0),
                          None if self.wheels is None else
                          np.insert(self.wheels, at, np.zeros((n, 2)), axis=0))

    @classmethod
    def at_rest(cls, pose: FloatArray) -> RobotState:
        """Robots at ``pose (N, 3)`` with zero velocity."""
        pose = np.array(pose, dtype=float).reshape(-1, 3)
        n = len(pose)
        return cls(pose, np.zeros((n, 2)), np.zeros((n, 2)))


def wheel_speeds(v: FloatArray, w: FloatArray, r: float, d: float) -> tuple[FloatArray, FloatArray]:
    """Inverse of paper 000 eq 2: wheel speeds from (v, omega).

    Args:
        v: Forward speed, m/s.
        w: Turn rate, rad/s.
        r: Wheel radius, m.
        d: Track width, m.

    Returns:
        ``(phi_dot_R, phi_dot_L)`` in rad/s.
    """
    return (v + 0.5 * d * w) / r, (v - 0.5 * d * w) / r


def twist_from_wheels(phi_r: FloatArray, phi_l: FloatArray, r: float,
                      d: float) -> tuple[FloatArray, FloatArray]:
    """Paper 000 eq 2: ``v = r/2 (phiR + phiL)``, ``omega = r/d (phiR - phiL)``."""
    return 0.5 * r * (phi_r + phi_l), r / d * (phi_r - phi_l)


def integrate_unicycle(pose: FloatArray, v: FloatArray, w: FloatArray, dt: float) -> FloatArray:
    """Exact motion of unicycles under constant (v, omega) for ``dt`` seconds.

    The robot moves along a circular arc; the chord has length
    ``2 v / w sin(w dt / 2)`` (``v dt`` as ``w -> 0``) and direction
    ``theta + w dt / 2``.

    Args:
        pose: ``(N, 3)`` or ``(3,)`` poses (m, m, rad).
        v: Forward speeds, m/s (broadcast to N).
        w: Turn rates, rad/s (broadcast to N).
        dt: Duration, s.

    Returns:
        New poses, same shape as ``pose``, heading wrapped to (-pi, pi].
    """
    pose = np.asarray(pose, dtype=float)
    x, y, th = pose[..., 0], pose[..., 1], pose[..., 2]
    dth = w * dt
    small = np.abs(dth) < 1e-9
    safe_w = np.where(small, 1.0, w)
    chord = np.where(small, v * dt, 2.0 * v / safe_w * np.sin(0.5 * dth))
    th_mid = th + 0.5 * dth
    return np.stack((x + chord * np.cos(th_mid), y + chord * np.sin(th_mid),
                     wrap_angle(th + dth)), axis=-1)


class Unicycle:
    """Differential-drive robots, native command ``(v, omega)``.

    Args:
        spec: Robot limits and wheel geometry.
    """

    native: CommandKind = "unicycle"

    def __init__(self, spec: RobotSpec) -> None:
        self.spec = spec

    def saturate(self, command: FloatArray) -> FloatArray:
        """Clip v to [v_min, v_max], |omega| to w_max, then scale both wheels to the wheel limit.

        Args:
            command: ``(N, 2)`` (v, omega) in m/s, rad/s.

        Returns:
            The admissible ``(N, 2)`` command.
        """
        s = self.spec
        v = np.clip(command[:, 0], s.v_lower, s.v_max)
        w = np.clip(command[:, 1], -s.w_max, s.w_max)
        if np.isfinite(s.wheel_speed_max):
            pr, pl = wheel_speeds(v, w, s.wheel_radius, s.track_width)
            peak = np.maximum(np.abs(pr), np.abs(pl))
            scale = np.where(peak > s.wheel_speed_max,
                             s.wheel_speed_max / np.maximum(peak, 1e-300), 1.0)
            v, w = twist_from_wheels(pr * scale, pl * scale, s.wheel_radius, s.track_width)
        return np.stack((v, w), axis=1)

    def step(self, state: RobotState, command: FloatArray, dt: float,
             disturbance: FloatArray | None = None, force: FloatArray | None = None) -> RobotState:
        """Advance ``dt`` seconds with a constant command, exactly along the arc.

        Args:
            state: Current state.
            command: ``(N, 2)`` (v, omega); saturated here.
            dt: Step in s.
            disturbance: ``(N, 2)`` world-frame velocity added to the motion, m/s.
            force: Unused: kinematic models take no forces (the loader rejects them).

        Returns:
            The new state.
        """
        s = self.spec
        dist = _NO_DISTURBANCE if disturbance is None else \
            np.ascontiguousarray(disturbance, dtype=float)
        pose, vel, u = unicycle_step(np.ascontiguousarray(state.pose, dtype=float),
                                     np.ascontiguousarray(command, dtype=float), float(dt),
                                     float(s.v_lower), float(s.v_max), float(s.w_max),
                                     float(s.wheel_speed_max), float(s.wheel_radius),
                                     float(s.track_width), dist)
        return RobotState(pose, vel, u)

    def step_reference(self, state: RobotState, command: FloatArray, dt: float,
                       disturbance: FloatArray | None = None) -> RobotState:
        """:meth:`step` in vectorised numpy (:meth:`saturate`, :func:`integrate_unicycle`).

        The reference the numba kernel of :meth:`step` is tested against, bit for bit.
        """
        u = self.saturate(command)
        v, w = u[:, 0], u[:, 1]
        pose = integrate_unicycle(state.pose, v, w, dt)
        nx, ny, th_new = pose[:, 0], pose[:, 1], pose[:, 2]
        vel = np.stack((v * np.cos(th_new), v * np.sin(th_new)), axis=1)
        if disturbance is not None:
            nx = nx + disturbance[:, 0] * dt
            ny = ny + disturbance[:, 1] * dt
            vel = vel + disturbance
        return RobotState(np.stack((nx, ny, th_new), axis=1), vel, u)


class ActuatedUnicycle(Unicycle):
    """Differential drive with wheel acceleration limits and motor lag (``dynamics = 'actuated'``).

    The model of :mod:`dfcoa_opt.world.robots.actuated`: the same saturation as
    :class:`Unicycle`, then each wheel follows its set point with a bounded
    rate and a first-order lag, integrated over ``spec.substeps`` arcs.
    """

    def step(self, state: RobotState, command: FloatArray, dt: float,
             disturbance: FloatArray | None = None, force: FloatArray | None = None,
             wheel_noise: FloatArray | None = None) -> RobotState:
        """Advance ``dt`` seconds (:func:`~dfcoa_opt.world.robots.actuated.actuated_step`).

        Args:
            state: Current state (``wheels`` None: at rest).
            command: ``(N, 2)`` (v, omega); saturated here.
            dt: Step in s.
            disturbance: ``(N, 2)`` world-frame velocity added to the motion, m/s.
            force: Unused: the loader rejects forces on unicycles.
            wheel_noise: ``(N, 2)`` noise on the wheel set points, rad/s.

        Returns:
            The new state, with the wheel speeds at the end of the step.
        """
        s = self.spec
        n = len(state.pose)
        wheels = np.zeros((n, 2)) if state.wheels is None else \
            np.ascontiguousarray(state.wheels, dtype=float)
        pose, vel, u, wh = actuated_step(
            np.ascontiguousarray(state.pose, dtype=float), wheels,
            np.ascontiguousarray(command, dtype=float), float(dt), float(s.v_lower),
            float(s.v_max), float(s.w_max), float(s.wheel_speed_max), float(s.wheel_radius),
            float(s.track_width), float(s.wheel_accel_max / s.wheel_radius),
            float(s.motor_time_constant), int(s.substeps),
            _NO_DISTURBANCE if wheel_noise is None else np.ascontiguousarray(wheel_noise, float),
            _NO_DISTURBANCE if disturbance is None else np.ascontiguousarray(disturbance, float))
        return RobotState(pose, vel, u, wh)


class _Holonomic:
    """Shared heading handling of the integrator models."""

    def __init__(self, spec: RobotSpec) -> None:
        self.spec = spec

    def _heading(self, state: RobotState, command: FloatArray, vel: FloatArray,
                 dt: float) -> tuple[FloatArray, FloatArray]:
        th = state.pose[:, 2]
        if command.shape[1] >= 3:
            w = np.clip(command[:, 2], -self.spec.w_max, self.spec.w_max)
            return wrap_angle(th + w * dt), w
        speed = np.hypot(vel[:, 0], vel[:, 1])
        th_new = np.where(speed > HEADING_SPEED_EPS, np.arctan2(vel[:, 1], vel[:, 0]), th)
        return th_new, wrap_angle(th_new - th) / dt

    @staticmethod
    def _clip_norm(a: FloatArray, limit: float) -> FloatArray:
        n = np.hypot(a[:, 0], a[:, 1])
        return a * np.where(n > limit, limit / np.maximum(n, limit), 1.0)[:, None]  # no 1/0


class SingleIntegrator(_Holonomic):
    """Velocity-controlled point robots, native command ``(vx, vy[, omega])``."""

    native: CommandKind = "velocity"

    def saturate(self, command: FloatArray) -> FloatArray:
        """Scale ``(vx, vy)`` to ``|v| <= v_max`` (other columns pass)."""
        out = command.astype(float, copy=True)
        out[:, :2] = self._clip_norm(command[:, :2], self.spec.v_max)
        return out

    def step(self, state: RobotState, command: FloatArray, dt: float,
             disturbance: FloatArray | None = None, force: FloatArray | None = None) -> RobotState:
        """``p+ = p + T (u + disturbance)`` with the saturated velocity ``u``; ``force`` unused."""
        u = self.saturate(command)
        vel = u[:, :2]
        th, w = self._heading(state, u, vel, dt)
        if disturbance is not None:
            vel = vel + disturbance
        pos = state.pose[:, :2] + vel * dt
        twist = np.stack((np.hypot(vel[:, 0], vel[:, 1]), w), axis=1)
        return RobotState(np.column_stack((pos, th)), vel, twist)


class DoubleIntegrator(_Holonomic):
    """Acceleration-controlled point robots, native command ``(ax, ay[, omega])``."""

    native: CommandKind = "acceleration"

    def saturate(self, command: FloatArray) -> FloatArray:
        """Scale ``(ax, ay)`` to ``|a| <= a_max`` (other columns pass)."""
        out = command.astype(float, copy=True)
        out[:, :2] = self._clip_norm(command[:, :2], self.spec.a_max)
        return out

    def step(self, state: RobotState, command: FloatArray, dt: float,
             disturbance: FloatArray | None = None, force: FloatArray | None = None) -> RobotState:
        """Paper 004 eq 3: ``p+ = p + T v``, ``v+ = clip(v + T (u + F/m))``.

        Args:
            state: Current state.
            command: ``(N, 2|3)`` accelerations in m/s^2 (and optional turn rate).
            dt: Step in s.
            disturbance: ``(N, 2)`` world velocity added to the motion, m/s.
            force: ``(N, 2)`` disturbance force in N.
        """
        u = self.saturate(command)
        acc = u[:, :2]
        if force is not None:
            acc = acc + force / self.spec.mass
        move = state.velocity if disturbance is None else state.velocity + disturbance
        pos = state.pose[:, :2] + move * dt
        vel = self._clip_norm(state.velocity + acc * dt, self.spec.v_max)
        th, w = self._heading(state, u, vel, dt)
        twist = np.stack((np.hypot(vel[:, 0], vel[:, 1]), w), axis=1)
        return RobotState(np.column_stack((pos, th)), vel, twist)


RobotModel = Unicycle | ActuatedUnicycle | SingleIntegrator | DoubleIntegrator


def make_model(spec: RobotSpec) -> RobotModel:
    """The model named by ``spec.model`` (and ``spec.dynamics`` for unicycles)."""
    if spec.model == "unicycle" and spec.dynamics == "actuated":
        return ActuatedUnicycle(spec)
    return {"unicycle": Unicycle, "single_integrator": SingleIntegrator,
            "double_integrator": DoubleIntegrator}[spec.model](spec)


