"""The unicycle model of the ``nmpc`` controller: the exact arc, in casadi and in numpy.

Under a constant twist ``(v, omega)`` for ``tau`` s the unicycle moves along an arc;
its chord ``v tau sinc(omega tau / 2)`` points along ``theta + omega tau / 2``
(the simulator's model, :func:`dfcoa_opt.robots.models.integrate_unicycle`,
without wrapping the heading).
"""

from __future__ import annotations

import casadi as ca
import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
#: Below this half turn angle (rad) the arc's sinc uses its Taylor series.
_SMALL = 1e-4


def _sinc(a: ca.SX) -> ca.SX:
    """``sin(a) / a``, smooth at 0."""
    small = ca.fabs(a) < _SMALL
    return ca.if_else(small, 1.0 - a * a / 6.0, ca.sin(a) / ca.if_else(small, 1.0, a))


def arc_step(x: ca.SX, u: ca.SX, tau: float) -> ca.SX:
    """Exact unicycle motion under constant (v, omega) for ``tau`` s (the simulator's model).

    The chord ``v tau sinc(omega tau / 2)`` points along ``theta + omega tau / 2``
    (:func:`dfcoa_opt.robots.models.integrate_unicycle`, without wrapping the heading).
    """
    half = 0.5 * u[1] * tau
    chord = u[0] * tau * _sinc(half)
    return ca.vertcat(x[0] + chord * ca.cos(x[2] + half), x[1] + chord * ca.sin(x[2] + half),
                      x[2] + 2.0 * half)


def rollout(pose: FloatArray, controls: FloatArray, tau: float) -> FloatArray:
    """Numpy twin of :func:`arc_step` over a horizon, batched over robots.

    Args:
        pose: ``(N, 3)`` start poses (m, m, rad).
        controls: ``(N, H, 2)`` (v m/s, omega rad/s) per stage.
        tau: Stage length, s.

    Returns:
        ``(N, H + 1, 3)`` poses, heading not wrapped.
    """
    n, h = controls.shape[:2]
    out = np.empty((n, h + 1, 3))
    out[:, 0] = pose
    for k in range(h):
        v, w = controls[:, k, 0], controls[:, k, 1]
        half = 0.5 * w * tau
        small = np.abs(half) < _SMALL
        sinc = np.where(small, 1.0 - half * half / 6.0,
                        np.sin(half) / np.where(small, 1.0, half))
        chord = v * tau * sinc
        th = out[:, k, 2]
        out[:, k + 1, 0] = out[:, k, 0] + chord * np.cos(th + half)
        out[:, k + 1, 1] = out[:, k, 1] + chord * np.sin(th + half)
        out[:, k + 1, 2] = th + 2.0 * half
    return out
