"""Actuated differential drive: wheel-speed limits, wheel acceleration limits and motor lag.

``robots.dynamics = "actuated"`` (docs/robots.md). Each step:

1. The command ``(v, omega)`` becomes wheel-speed set points by the inverse of
   paper 000 eq 2, after the limits of :func:`~dfcoa_opt.world.robots.unicycle_kernel.saturate1`
   (v and omega clipped, then both wheels scaled by one factor to the wheel
   limit, which keeps the curvature).
2. Optional Gaussian noise on each set point (``robots.wheel_noise_std``), then
   each set point is clipped to the wheel limit.
3. Each wheel's speed ``phi`` follows its set point ``s`` by

   ``dphi/dt = clip((s - phi) / tau, -alpha, alpha)``

   with ``tau = robots.motor_time_constant`` (s; 0: no lag) and
   ``alpha = robots.wheel_accel_max / wheel_radius`` (rad/s^2; inf: no limit): a
   first-order motor lag whose rate is bounded. It is solved exactly: a ramp at
   ``alpha`` while ``|s - phi| > alpha tau``, then the exponential (with
   ``tau = 0``: the ramp, then the set point).
4. The pose moves along ``robots.substeps`` arcs. Over each substep the
   wheels' exact mean speeds give ``(v, omega)``; the robot follows the arc of
   that constant twist. So the heading constraint holds inside every substep
   (the robot always moves along its heading), the heading is exact (omega is
   linear in the wheel speeds), and a command of constant curvature is
   followed exactly on its circle whatever the number of substeps (both wheels
   then keep one ratio, so each arc lies on that circle).

The state adds the wheel speeds at the end of the step (``RobotState.wheels``);
``twist`` is the mean ``(v, omega)`` over the step (what odometry integrates)
and ``velocity`` the world velocity at its end. Rows are independent, so a
batch gives each run's bits.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.world.robots.unicycle_kernel import arc, saturate1, store_row

FloatArray = NDArray[np.float64]


@numba.njit(cache=True, inline="always")
def wheel_advance(phi: float, s: float, alpha: float, tau: float, h: float,
                  decay_h: float) -> tuple[float, float]:  # pragma: no cover - numba
    """One wheel's speed after ``h`` s and its mean over them (module docstring, step 3).

    Args:
        phi: Speed now, rad/s.
        s: Set point, rad/s.
        alpha: Largest wheel acceleration, rad/s^2 (inf: none).
        tau: Motor time constant, s (0: none).
        h: Duration, s.
        decay_h: ``1 - exp(-h / tau)`` (0 when ``tau`` is 0), computed once per step.

    Returns:
        ``(speed after h, mean speed over h)``, rad/s.
    """
    e0 = s - phi
    sign = 1.0 if e0 >= 0.0 else -1.0
    mag = abs(e0)
    cap = alpha * tau if tau > 0.0 else 0.0  # the error below which the lag is linear
    t1 = (mag - cap) / alpha if mag > cap else 0.0  # time spent ramping at alpha
    if t1 >= h:  # ramping throughout
        end = phi + sign * alpha * h
        return end, 0.5 * (phi + end)
    ramp_end = phi + sign * alpha * t1 if t1 > 0.0 else phi
    integral = 0.5 * (phi + ramp_end) * t1
    rest = h - t1
    e1 = s - ramp_end
    if tau > 0.0:
        decay = decay_h if t1 == 0.0 else -math.expm1(-rest / tau)  # 1 - exp(-rest / tau)
        end = s - e1 * (1.0 - decay)
        integral += s * rest - e1 * tau * decay
    else:
        end = s
        integral += s * rest
    return end, integral / h


@numba.njit(cache=True)
def actuated_step(pose: FloatArray, wheels: FloatArray, command: FloatArray, dt: float,
                  v_lower: float, v_max: float, w_max: float, wheel_max: float, wheel_r: float,
                  track: float, alpha: float, tau: float, substeps: int, noise: FloatArray,
                  disturbance: FloatArray
                  ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:  # pragma: no cover
    """Advance N actuated unicycles by ``dt`` (module docstring).

    Args:
        pose: ``(N, 3)`` poses (m, m, rad).
        wheels: ``(N, 2)`` wheel speeds now (right, left), rad/s.
        command: ``(N, 2)`` requested (v m/s, omega rad/s).
        dt: Step, s.
        v_lower: Lowest forward speed, m/s.
        v_max: Highest forward speed, m/s.
        w_max: Largest turn rate, rad/s.
        wheel_max: Largest wheel speed, rad/s (inf: none).
        wheel_r: Wheel radius, m.
        track: Track width, m.
        alpha: Largest wheel acceleration, rad/s^2 (inf: none).
        tau: Motor time constant, s.
        substeps: Arcs per step (>= 1).
        noise: ``(N, 2)`` set-point noise, rad/s, or ``(0, 2)``.
        disturbance: ``(N, 2)`` world velocity added to the motion (m/s), or ``(0, 2)``.

    Returns:
        ``(pose (N, 3), velocity (N, 2) m/s at the end, mean twist (N, 2),
        wheel speeds (N, 2) rad/s at the end)``.
    """
    n = pose.shape[0]
    out = np.empty((n, 3))
    vel = np.empty((n, 2))
    u = np.empty((n, 2))
    wh = np.empty((n, 2))
    h = dt / substeps
    decay_h = -math.expm1(-h / tau) if tau > 0.0 else 0.0
    for i in range(n):
        v, w = saturate1(command[i, 0], command[i, 1], v_lower, v_max, w_max, wheel_max,
                         wheel_r, track)
        sr = (v + 0.5 * track * w) / wheel_r
        sl = (v - 0.5 * track * w) / wheel_r
        if noise.shape[0]:
            sr = min(max(sr + noise[i, 0], -wheel_max), wheel_max)
            sl = min(max(sl + noise[i, 1], -wheel_max), wheel_max)
        pr, pl = wheels[i, 0], wheels[i, 1]
        x, y, th = pose[i, 0], pose[i, 1], pose[i, 2]
        sum_v = 0.0
        sum_w = 0.0
        for _ in range(substeps):
            pr, mr = wheel_advance(pr, sr, alpha, tau, h, decay_h)
            pl, ml = wheel_advance(pl, sl, alpha, tau, h, decay_h)
            vm, wm = 0.5 * wheel_r * (mr + ml), wheel_r / track * (mr - ml)
            x, y, th = arc(x, y, th, vm, wm, h)
            sum_v += vm
            sum_w += wm
        store_row(out, vel, u, i, x, y, th, 0.5 * wheel_r * (pr + pl), sum_v / substeps,
                  sum_w / substeps, disturbance, dt)
        wh[i, 0], wh[i, 1] = pr, pl
    return out, vel, u, wh
