"""Numba kernels of the unicycle model: the simulator's fast path.

:func:`unicycle_step` is :meth:`dfcoa_opt.world.robots.models.Unicycle.step` --
saturation (paper 000 eq 1-2 wheel mapping), the exact arc of
:func:`~dfcoa_opt.world.robots.models.integrate_unicycle` and the world velocity --
as one loop, with the same floating-point operations in the same order, so
that both give bit-identical states (``tests/test_models.py`` checks it). It
replaces some 30 small numpy calls per step (~60 us for 4 robots) with one.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from dfcoa_opt.core.scalar_kernels import wrap1


@numba.njit(cache=True, inline="always")
def arc(x: float, y: float, th: float, v: float, w: float,
        dt: float) -> tuple[float, float, float]:  # pragma: no cover - numba
    """One pose moved along the arc of constant ``(v, omega)`` for ``dt`` s (m, m, rad)."""
    dth = w * dt
    if abs(dth) < 1e-9:
        chord = v * dt
    else:
        chord = 2.0 * v / w * math.sin(0.5 * dth)
    th_mid = th + 0.5 * dth
    return x + chord * math.cos(th_mid), y + chord * math.sin(th_mid), wrap1(th + dth)


@numba.njit(cache=True, inline="always")
def saturate1(v: float, w: float, v_lower: float, v_max: float, w_max: float, wheel_max: float,
              wheel_r: float, track: float) -> tuple[float, float]:  # pragma: no cover - numba
    """One command's admissible ``(v, omega)`` (m/s, rad/s): paper 000 eq 1-2 limits.

    Clip v to ``[v_lower, v_max]`` and |omega| to ``w_max``; then, when a wheel
    would exceed ``wheel_max`` (rad/s; inf: no wheel limit), scale both wheels by
    one factor, which keeps the curvature omega / v (docs/robots.md).
    """
    v = min(max(v, v_lower), v_max)
    w = min(max(w, -w_max), w_max)
    if math.isfinite(wheel_max):
        pr = (v + 0.5 * track * w) / wheel_r
        pl = (v - 0.5 * track * w) / wheel_r
        peak = max(abs(pr), abs(pl))
        scale = wheel_max / max(peak, 1e-300) if peak > wheel_max else 1.0
        pr, pl = pr * scale, pl * scale
        v, w = 0.5 * wheel_r * (pr + pl), wheel_r / track * (pr - pl)
    return v, w


@numba.njit(cache=True, inline="always")
def store_row(out, vel, u, i, x, y, th, speed, v, w, disturbance,
              dt):  # pragma: no cover - numba
    """Row ``i`` of a step's outputs, the disturbance (world velocity, m/s) added.

    ``out[i]`` the pose (m, m, rad) moved by ``disturbance[i] dt``; ``vel[i]`` the world
    velocity of ``speed`` (m/s) along the heading ``th``, plus the disturbance; ``u[i]``
    the applied twist ``(v, w)`` (m/s, rad/s).
    """
    vx, vy = speed * math.cos(th), speed * math.sin(th)
    if disturbance.shape[0]:
        x = x + disturbance[i, 0] * dt
        y = y + disturbance[i, 1] * dt
        vx, vy = vx + disturbance[i, 0], vy + disturbance[i, 1]
    out[i, 0], out[i, 1], out[i, 2] = x, y, th
    vel[i, 0], vel[i, 1] = vx, vy
    u[i, 0], u[i, 1] = v, w


@numba.njit(cache=True)
def unicycle_arc(pose, v, w, dt):  # pragma: no cover - numba
    """:func:`~dfcoa_opt.world.robots.models.integrate_unicycle` of one ``(3,)`` pose (m, rad)."""
    x, y, th = arc(pose[0], pose[1], pose[2], v, w, dt)
    return np.array([x, y, th])


@numba.njit(cache=True)
def unicycle_step(pose, command, dt, v_lower, v_max, w_max, wheel_max, wheel_r, track,
                  disturbance):  # pragma: no cover - numba
    """Saturate, integrate and differentiate N unicycles (see the module docstring).

    Args:
        pose: ``(N, 3)`` poses (m, m, rad).
        command: ``(N, 2)`` requested (v m/s, omega rad/s).
        dt: Step, s.
        v_lower: Lowest forward speed, m/s.
        v_max: Highest forward speed, m/s.
        w_max: Largest turn rate, rad/s.
        wheel_max: Largest wheel speed, rad/s (inf: no wheel limit).
        wheel_r: Wheel radius, m.
        track: Track width, m.
        disturbance: ``(N, 2)`` world velocity added to the motion (m/s), or ``(0, 2)``.

    Returns:
        ``(pose (N, 3), velocity (N, 2) m/s, applied twist (N, 2))``.
    """
    n = pose.shape[0]
    out = np.empty((n, 3))
    vel = np.empty((n, 2))
    u = np.empty((n, 2))
    for i in range(n):
        v, w = saturate1(command[i, 0], command[i, 1], v_lower, v_max, w_max, wheel_max,
                         wheel_r, track)
        x, y, th = arc(pose[i, 0], pose[i, 1], pose[i, 2], v, w, dt)
        store_row(out, vel, u, i, x, y, th, v, v, w, disturbance, dt)
    return out, vel, u
