"""Pure-pursuit path tracking (the virtual leader's tracker).

Follows MATLAB ``controllerPurePursuit`` semantics: constant desired speed,
look-ahead point on the path ``L_d`` ahead of the closest point, turn rate
``omega = 2 v sin(alpha) / L_d`` clipped to ``omega_max`` (``alpha`` = bearing of
the look-ahead point in the robot frame). Progress along the path is
monotonic: the closest-point search never goes back to an earlier segment.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.core.scalar_kernels import wrap1

FloatArray = NDArray[np.float64]


class PurePursuit:
    """Pure pursuit along a polyline.

    Args:
        path: ``(P, 2)`` path points in m (P >= 1).
        speed: Desired speed, m/s.
        lookahead: Look-ahead distance L_d, m.
        w_max: Largest turn rate, rad/s.
    """

    def __init__(self, path: FloatArray, speed: float, lookahead: float, w_max: float) -> None:
        path = np.asarray(path, dtype=float).reshape(-1, 2)
        keep = np.concatenate(([True], np.linalg.norm(np.diff(path, axis=0), axis=1) > 1e-12))
        self.path = path[keep]
        self.speed, self.lookahead, self.w_max = speed, lookahead, w_max
        seg = np.diff(self.path, axis=0)
        self._seg_len = np.linalg.norm(seg, axis=1)
        self._cum = np.concatenate(([0.0], np.cumsum(self._seg_len)))
        self._s = 0.0  # arc length of the closest point so far

    @property
    def length(self) -> float:
        """Path length in m."""
        return float(self._cum[-1])

    def point_at(self, s: float) -> FloatArray:
        """Path point at arc length ``s`` (clamped to the path), m."""
        if len(self.path) == 1:
            return self.path[0].copy()
        s = min(max(s, 0.0), self.length)
        k = min(int(np.searchsorted(self._cum, s, side="right")) - 1, len(self._seg_len) - 1)
        frac = (s - self._cum[k]) / self._seg_len[k]
        return self.path[k] + frac * (self.path[k + 1] - self.path[k])

    def _project(self, p: FloatArray) -> float:
        """Arc length of the closest path point at or after the current progress."""
        if len(self.path) == 1:
            return 0.0
        return _project_kernel(self.path, self._seg_len, self._cum, float(p[0]), float(p[1]),
                               self._s)

    def arc_length(self, points: FloatArray) -> FloatArray:
        """Arc length of the closest path point of each point, anywhere on the path.

        Unlike the tracker's own projection this one may go back along the path
        (no monotonic progress), so it measures where each point is.

        Args:
            points: ``(K, 2)`` points, m.

        Returns:
            ``(K,)`` arc lengths from the path's start, m (0 for a one-point path).
        """
        pts = np.asarray(points, dtype=float).reshape(-1, 2)
        if len(self.path) == 1:
            return np.zeros(len(pts))
        return np.array([_project_kernel(self.path, self._seg_len, self._cum, float(x),
                                         float(y), 0.0) for x, y in pts])

    def command(self, pose: FloatArray) -> tuple[float, float, FloatArray]:
        """Speed, turn rate and look-ahead point for the current pose.

        Args:
            pose: ``(3,)`` (x, y, theta) in m, m, rad.

        Returns:
            ``(v m/s, omega rad/s, lookahead point (2,) m)``.
        """
        self._s = self._project(pose[:2])
        target = self.point_at(self._s + self.lookahead)
        dx, dy = target - pose[:2]
        alpha = wrap1(float(np.arctan2(dy, dx) - pose[2]))  # numpy's atan2 (SIMD), as before
        dist = max(float(np.hypot(dx, dy)), 1e-9)
        w = 2.0 * self.speed * math.sin(alpha) / max(dist, self.lookahead) if dist > 1e-9 else 0.0
        return self.speed, min(max(w, -self.w_max), self.w_max), target


@numba.njit(cache=True)
def _project_kernel(path, seg_len, cum, px, py, s_min):  # pragma: no cover - numba
    """:meth:`PurePursuit._project` for a path of >= 2 points (one loop over segments).

    For each segment ``[a, b]`` the clipped projection ``t``, its arc length
    ``cum + t |ab|`` and distance ``|a + t ab - p|``; segments ending before
    ``s_min`` are skipped (no going back); the first nearest wins.
    """
    best_d = np.inf
    best_s = 0.0
    for k in range(seg_len.shape[0]):
        ax, ay = path[k, 0], path[k, 1]
        abx, aby = path[k + 1, 0] - ax, path[k + 1, 1] - ay
        t = ((px - ax) * abx + (py - ay) * aby) / (seg_len[k] * seg_len[k])
        t = min(max(t, 0.0), 1.0)
        dx, dy = ax + t * abx - px, ay + t * aby - py
        d = math.sqrt(dx * dx + dy * dy) if cum[k + 1] >= s_min else np.inf
        if d < best_d or k == 0:
            best_d, best_s = d, cum[k] + t * seg_len[k]
    return max(best_s, s_min)
