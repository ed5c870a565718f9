"""Improved VFH* pipeline and the section 4.5.3 safety layer (paper 000, Algorithm 1).

:func:`vfh_step` runs the histogram stages of :mod:`dfcoa_opt.control.vfh` for
every robot; :func:`danger_level` and :func:`blend` mix its steering with the
formation law when obstacles are close; :class:`VFHStar` keeps the hysteresis
and previous-direction state between steps. Choices: ``docs/methods/vfh.md``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from dfcoa_opt.control.base import Neighbours
from dfcoa_opt.control.vfh import (
    FloatArray,
    VFHParams,
    VFHResult,
    binary_histogram,
    polar_histogram,
    repulsion_histogram,
    select_direction,
    turning_mask,
)
from dfcoa_opt.geometry import wrap_angle
from dfcoa_opt.world.lidar import LaserScan


def min_obstacle_distance(scan: LaserScan | None, n: int) -> FloatArray:
    """``(N,)`` nearest return in m (``-inf`` read as ``range_min``; ``inf`` = none)."""
    if scan is None:
        return np.full(n, np.inf)
    r = np.atleast_2d(np.asarray(scan.ranges, dtype=float))
    r = np.where(r == -np.inf, scan.range_min, r)
    return np.where(np.isnan(r), np.inf, r).min(axis=1, initial=np.inf)


def danger_level(min_distance: ArrayLike, params: VFHParams) -> FloatArray:
    """Linear ramp ``(d_start - d_min) / (d_start - d_full)`` clipped to [0, 1].

    0 at or beyond ``blend_start``, 1 at or below ``blend_full`` (section 4.5.3's
    "override when collisions are imminent").
    """
    d = np.asarray(min_distance, dtype=float)
    span = params.blend_start - params.blend_full
    return np.clip((params.blend_start - d) / span, 0.0, 1.0)


def blend(formation_cmd: ArrayLike, vfh_dir: ArrayLike, danger: ArrayLike,
          params: VFHParams) -> FloatArray:
    """Safety-layer blend of unicycle commands (section 4.5.3), pure.

    VFH command: ``omega_a = clip(k_h theta*, +-w_max)``,
    ``v_a = clip(v_f, 0, avoid_speed) max(cos theta*, 0)``; with no candidate
    (NaN) ``v_a = 0, omega_a = omega_f`` (stop, keep turning: a disc cannot hit
    anything by rotating). Output ``u = (1 - danger) u_f + danger u_a``.

    Args:
        formation_cmd: ``(N, 2)`` formation law's (v, omega), m/s, rad/s.
        vfh_dir: ``(N,)`` theta* in the robot frame, rad (NaN = none).
        danger: ``(N,)`` in [0, 1] (:func:`danger_level`).
        params: ``heading_gain``, ``w_max``, ``avoid_speed``.

    Returns:
        ``(N, 2)`` blended (v, omega).
    """
    u = np.asarray(formation_cmd, dtype=float).reshape(-1, 2)
    th = np.asarray(vfh_dir, dtype=float).reshape(len(u))
    a = np.clip(np.asarray(danger, dtype=float).reshape(len(u)), 0.0, 1.0)[:, None]
    found = np.isfinite(th)
    th0 = np.where(found, th, 0.0)
    w_a = np.where(found, np.clip(params.heading_gain * th0, -params.w_max, params.w_max), u[:, 1])
    v_a = np.where(found, np.clip(u[:, 0], 0.0, params.avoid_speed)
                   * np.maximum(np.cos(th0), 0.0), 0.0)
    return (1.0 - a) * u + a * np.column_stack((v_a, w_a))


def vfh_step(scan: LaserScan | None, neighbours: Neighbours | None, pose: ArrayLike,
             target_dir: ArrayLike, params: VFHParams, prev_binary: ArrayLike,
             prev_dir: ArrayLike) -> VFHResult:
    """One improved-VFH* step for all robots (Algorithm 1), pure.

    Args:
        scan: Own scans (``ranges`` ``(N, B)``), or None (no LiDAR: empty histogram).
        neighbours: Neighbour table, or None (no repulsion).
        pose: ``(N, 3)`` own poses, m, m, rad.
        target_dir: ``(N,)`` target direction in the robot frame, rad.
        params: Parameters.
        prev_binary: ``(N, K)`` previous binary histogram (hysteresis state).
        prev_dir: ``(N,)`` previous steering direction in the robot frame, rad (NaN = none).
    """
    p = np.asarray(pose, dtype=float).reshape(-1, 3)
    n, k = len(p), params.num_sectors
    if scan is None:
        hist = np.zeros((n, k))
        mask = np.zeros((n, k), dtype=bool)
    else:
        if np.atleast_2d(scan.ranges).shape[0] != n:
            raise ValueError("scan and pose must have the same number of rows")
        hist = polar_histogram(scan.ranges, scan.angles, params)
        mask = (turning_mask(scan.ranges, scan.angles, params) if params.use_turning_mask
                else np.zeros((n, k), dtype=bool))
    if neighbours is not None:
        hist = hist + repulsion_histogram(p, neighbours.position, neighbours.mask, params)
    binary = binary_histogram(hist, prev_binary, params.histogram_thresholds)
    masked = binary | mask
    direction = select_direction(masked, hist, target_dir, prev_dir, params)
    dmin = min_obstacle_distance(scan, n)
    return VFHResult(direction, np.isfinite(direction), dmin, danger_level(dmin, params), hist,
                     binary, masked)


class VFHStar:
    """Stateful improved VFH*: keeps each robot's binary histogram and last direction.

    The previous direction is stored in the world frame and turned into the
    current robot frame at the next step, so the robot's own rotation does not
    bias the ``previous_weight`` term; the binary histogram is kept in the robot
    frame (as MATLAB ``controllerVFH`` does).

    Attributes:
        params: Parameters.
        n_robots: Number of rows.
    """

    def __init__(self, params: VFHParams, n_robots: int) -> None:
        self.params = params
        self.n_robots = int(n_robots)
        self.reset()

    def reset(self) -> None:
        """Forget the hysteresis state (all sectors free) and the previous direction."""
        self.binary = np.zeros((self.n_robots, self.params.num_sectors), dtype=bool)
        self.previous_world = np.full(self.n_robots, np.nan)

    def step(self, scan: LaserScan | None, neighbours: Neighbours | None, pose: ArrayLike,
             target_dir: ArrayLike, rows: ArrayLike | None = None) -> VFHResult:
        """Run :func:`vfh_step` and update the state.

        Args:
            scan: Own scans, ``(R, B)`` ranges, or None.
            neighbours: Neighbour table, or None.
            pose: ``(R, 3)`` own poses, m, m, rad.
            target_dir: ``(R,)`` target direction in the robot frame, rad.
            rows: ``(R,)`` state rows (robot indices, ``Observation.robot_ids``) of the
                inputs; default all ``n_robots`` rows in order.
        """
        idx = np.arange(self.n_robots) if rows is None else np.asarray(rows, dtype=np.intp)
        p = np.asarray(pose, dtype=float).reshape(len(idx), 3)
        prev = wrap_angle(self.previous_world[idx] - p[:, 2])
        res = vfh_step(scan, neighbours, p, target_dir, self.params, self.binary[idx], prev)
        self.binary[idx] = res.binary
        self.previous_world[idx] = np.where(res.found, wrap_angle(res.direction + p[:, 2]),
                                            self.previous_world[idx])
        return res
