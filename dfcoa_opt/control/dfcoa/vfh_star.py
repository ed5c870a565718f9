"""Improved VFH* pipeline and the section 4.5.3 safety layer (paper 000, Algorithm 1).

:func:`vfh_step` runs the histogram stages of :mod:`dfcoa_opt.control.dfcoa.histogram` for
every robot; :func:`danger_level` and :func:`blend` mix its steering with the
formation law when obstacles are close; :class:`VFHStar` keeps the hysteresis
and previous-direction state between steps. Choices: ``docs/methods/vfh.md``.

Speed: :class:`VFHStar` steps through two numba kernels (``kernel=True``, the
default) and :func:`blend_fast` is :func:`blend` in numba; both give the bits of
the NumPy functions, which stay the reference (``tests/test_vfh_kernel.py``).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from dfcoa_opt.control.base import Neighbours
from dfcoa_opt.control.dfcoa.histogram import (
    BoolArray,
    FloatArray,
    VFHParams,
    VFHResult,
    binary_histogram,
    polar_histogram,
    repulsion_histogram,
    sector1,
    sector_centres,
    select_direction,
    turning_mask,
)
from dfcoa_opt.core.geometry import wrap_angle
from dfcoa_opt.core.scalar_kernels import clip1, wrap1
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


# ------------------------------------------------------------------ numba path
# The kernels below redo vfh_step and blend row by row with the same float
# operations in the same order (bit-identical; tests/test_vfh_kernel.py). arcsin
# and arctan2 stay in NumPy: numba's libm differs from NumPy's in the last bit.


@numba.njit(cache=True)
def _ranges_kernel(ranges: FloatArray, lo: float, hi: float, c: float,
                   range_min: float
                   ) -> tuple[FloatArray, FloatArray, FloatArray]:  # pragma: no cover - numba
    """Used ranges, ``min(1, c / d)`` and each row's nearest return, m.

    ``d`` as :func:`~dfcoa_opt.control.dfcoa.histogram.used_ranges`, ``c = r + s`` (the arcsin
    argument of the enlargement angle), the minimum as :func:`min_obstacle_distance`.
    """
    n, nb = ranges.shape
    d, ratio, dmin = np.empty((n, nb)), np.empty((n, nb)), np.empty(n)
    for i in range(n):
        m = np.inf
        for j in range(nb):
            r = ranges[i, j]
            v = lo if r < lo else r
            v = v if v <= hi else np.nan
            d[i, j] = v
            x = c / v
            ratio[i, j] = 1.0 if x >= 1.0 else x  # np.minimum(1, x); NaN stays
            q = range_min if r == -np.inf else r
            q = np.inf if np.isnan(q) else q
            m = q if q < m else m
        dmin[i] = m
    return d, ratio, dmin


@numba.njit(cache=True)
def _vfh_kernel(d: FloatArray, gam: FloatArray, dmin: FloatArray, beam: FloatArray,
                centres: FloatArray, theta: FloatArray, target: FloatArray, rel: FloatArray,
                bearing: FloatArray, nmask: BoolArray, rows: NDArray[np.intp],
                state_bin: BoolArray, state_prev: FloatArray, fp: FloatArray, use_mask: bool,
                has_nb: bool) -> tuple[FloatArray, BoolArray, BoolArray, FloatArray,
                                       FloatArray]:  # pragma: no cover - numba
    """:func:`vfh_step` plus the :class:`VFHStar` state update (Algorithm 1, eq 29)."""
    n, nb = d.shape
    k = centres.shape[0]
    inv, scale, rt, reach, low, high, d_safe, gain = fp[:8]
    cdiv, ow, tw, cw, pw, half, b_start, span = fp[8:]
    hist, rep = np.zeros((n, k)), np.zeros(k)
    binary, masked = np.empty((n, k), np.bool_), np.empty((n, k), np.bool_)
    direction, danger = np.empty(n), np.empty(n)
    for r in range(n):
        i, th, h = rows[r], theta[r], hist[r]
        for j in range(nb):  # polar histogram, Alg. 1 l. 5-11 (enlarged returns)
            dv = d[r, j]
            if not np.isfinite(dv):
                continue
            w = 1.0 / (dv * dv)
            lo = int(np.ceil((beam[0, j] - gam[r, j]) * inv - 0.5))
            hi = int(np.floor((beam[0, j] + gam[r, j]) * inv + 0.5))
            jj = lo % k
            for _ in range(min(hi - lo + 1, k)):  # sectors lo, lo + 1, ... mod K
                h[jj] += w
                jj = jj + 1 if jj + 1 < k else 0
        if has_nb:  # repulsion, Alg. 1 l. 12-22
            rep[:] = 0.0
            for m in range(nmask.shape[1]):
                if not nmask[r, m]:
                    continue
                dd = math.hypot(rel[r, m, 0], rel[r, m, 1])
                if dd < d_safe:
                    rep[sector1(bearing[r, m] - th, scale, k)] += gain * (d_safe - dd)
            for j in range(k):
                h[j] = h[j] + rep[j]
        phi_r, phi_l = -np.inf, np.inf  # turning mask
        if use_mask:
            for j in range(nb):
                bt = beam[0, j]
                x, y = d[r, j] * beam[1, j], d[r, j] * beam[2, j]
                if bt <= 0.0 and x * x + (y + rt) * (y + rt) < reach and bt > phi_r:
                    phi_r = bt
                if bt >= 0.0 and x * x + (y - rt) * (y - rt) < reach and bt < phi_l:
                    phi_l = bt
        for j in range(k):  # hysteresis, then the masked histogram
            binary[r, j] = True if h[j] > high else (False if h[j] < low else state_bin[i, j])
            masked[r, j] = binary[r, j] or (
                (np.isfinite(phi_r) and centres[j] - half < phi_r)
                or (np.isfinite(phi_l) and centres[j] + half > phi_l))
        # direction, eq 29 / Alg. 1 l. 23-44 (select_direction)
        t = target[r]
        has_t = np.isfinite(t)
        t0 = t if has_t else 0.0
        if not (t0 > -np.pi and t0 <= np.pi):
            t0 = wrap1(t0)
        jt = sector1(t0, scale, k)
        prev = wrap1(state_prev[i] - th)
        has_p = np.isfinite(prev)
        p0 = prev if has_p else 0.0
        best, best_v, any_ok = 0, np.inf, False
        for j in range(k + 1):
            c = t0 if j == 0 else centres[j - 1]
            ok = (has_t and not masked[r, jt]) if j == 0 else not masked[r, j - 1]
            cost = (ow * ((h[jt] if j == 0 else h[j - 1]) / cdiv)
                    + (tw * abs(wrap1(c - t0)) if has_t else 0.0) + cw * abs(c))
            cost = cost + (pw * abs(wrap1(c - p0)) if has_p else 0.0)
            v = cost if ok else np.inf
            any_ok = any_ok or ok
            if j == 0:
                best_v = v
            elif not np.isnan(best_v) and (np.isnan(v) or v < best_v):
                best, best_v = j, v  # np.argmin: the first NaN, else the first minimum
        direction[r] = ((t0 if best == 0 else centres[best - 1]) if any_ok else np.nan)
        danger[r] = clip1((b_start - dmin[r]) / span, 0.0, 1.0)
    for r in range(n):  # state update after all reads
        i = rows[r]
        state_bin[i, :] = binary[r]
        if np.isfinite(direction[r]):
            state_prev[i] = wrap1(direction[r] + theta[r])
    return hist, binary, masked, direction, danger


@numba.njit(cache=True)
def _blend_kernel(u: FloatArray, th: FloatArray, danger: FloatArray, k_h: float, w_max: float,
                  v_avoid: float) -> FloatArray:  # pragma: no cover - numba
    """:func:`blend` row by row."""
    out = np.empty_like(u)
    for i in range(u.shape[0]):
        a = clip1(danger[i], 0.0, 1.0)
        found = np.isfinite(th[i])
        th0 = th[i] if found else 0.0
        w_a = clip1(k_h * th0, -w_max, w_max) if found else u[i, 1]
        v_a = clip1(u[i, 0], 0.0, v_avoid) * max(math.cos(th0), 0.0) if found else 0.0
        out[i, 0] = (1.0 - a) * u[i, 0] + a * v_a
        out[i, 1] = (1.0 - a) * u[i, 1] + a * w_a
    return out


def blend_fast(formation_cmd: ArrayLike, vfh_dir: ArrayLike, danger: ArrayLike,
               params: VFHParams) -> FloatArray:
    """:func:`blend` (section 4.5.3) as one numba kernel, bit-identical.

    Args:
        formation_cmd: ``(N, 2)`` formation law's (v, omega), m/s, rad/s.
        vfh_dir: ``(N,)`` theta* in the robot frame, rad (NaN = none).
        danger: ``(N,)`` in [0, 1].
        params: ``heading_gain``, ``w_max``, ``avoid_speed``.

    Returns:
        ``(N, 2)`` blended (v, omega).
    """
    u = np.asarray(formation_cmd, dtype=float).reshape(-1, 2)
    return _blend_kernel(u, np.asarray(vfh_dir, dtype=float).reshape(len(u)),
                         np.asarray(danger, dtype=float).reshape(len(u)),
                         float(params.heading_gain), float(params.w_max),
                         float(params.avoid_speed))


class VFHStar:
    """Stateful improved VFH*: keeps each robot's binary histogram and last direction.

    The previous direction is stored in the world frame and turned into the
    current robot frame at the next step, so the robot's own rotation does not
    bias the ``previous_weight`` term; the binary histogram is kept in the robot
    frame (as MATLAB ``controllerVFH`` does).

    Every row is computed from its own inputs and state row only, so one object
    can hold the robots of every run of a batch (state row ``env * N + robot``,
    :class:`~dfcoa_opt.control.dfcoa.controller.DFCOA`) and step them all in one call.

    Attributes:
        params: Parameters.
        n_robots: Number of state rows (the robots of one run, or of every run of a batch).
        kernel: Step with the numba kernels (same bits as :func:`vfh_step`, faster);
            False runs the NumPy reference :func:`vfh_step`.
    """

    def __init__(self, params: VFHParams, n_robots: int, kernel: bool = True) -> None:
        self.params = params
        self.n_robots = int(n_robots)
        self.kernel = kernel
        self.reset()

    def reset(self) -> None:
        """Forget the hysteresis state (all sectors free) and the previous direction."""
        p = self.params
        self.binary = np.zeros((self.n_robots, p.num_sectors), dtype=bool)
        self.previous_world = np.full(self.n_robots, np.nan)
        # kernel constants, each computed as the NumPy functions compute it
        low, high = p.histogram_thresholds
        rt = p.min_turning_radius
        self._fp = np.array([
            1.0 / p.sector_width, p.num_sectors / (2.0 * np.pi), rt,
            (rt + p.robot_radius + p.safety_distance) ** 2, low, high, p.d_safe,
            p.repulsive_gain, max(high, np.finfo(float).tiny), p.obstacle_weight,
            p.target_weight, p.current_weight, p.previous_weight, 0.5 * p.sector_width,
            p.blend_start, p.blend_start - p.blend_full], dtype=float)
        self._centres = sector_centres(p.num_sectors)
        self._beam_key: tuple[float, float, int] | None = None
        self._beam = np.zeros((3, 0))  # wrapped beam angles, their cos and sin

    def step(self, scan: LaserScan | None, neighbours: Neighbours | None, pose: ArrayLike,
             target_dir: ArrayLike, rows: ArrayLike | None = None) -> VFHResult:
        """Run :func:`vfh_step` (or its numba kernel) and update the state.

        Args:
            scan: Own scans, ``(R, B)`` ranges, or None.
            neighbours: Neighbour table, or None.
            pose: ``(R, 3)`` own poses, m, m, rad.
            target_dir: ``(R,)`` target direction in the robot frame, rad.
            rows: ``(R,)`` state rows of the inputs (robot indices,
                ``Observation.robot_ids``; in a batch ``env * N + robot_ids``);
                default all ``n_robots`` rows in order.
        """
        idx = np.arange(self.n_robots) if rows is None else np.asarray(rows, dtype=np.intp)
        p = np.asarray(pose, dtype=float).reshape(len(idx), 3)
        if self.kernel and scan is not None:
            return self._step_kernel(scan, neighbours, p, target_dir, idx)
        prev = wrap_angle(self.previous_world[idx] - p[:, 2])
        res = vfh_step(scan, neighbours, p, target_dir, self.params, self.binary[idx], prev)
        self.binary[idx] = res.binary
        self.previous_world[idx] = np.where(res.found, wrap_angle(res.direction + p[:, 2]),
                                            self.previous_world[idx])
        return res

    def _step_kernel(self, scan: LaserScan, neighbours: Neighbours | None, p: FloatArray,
                     target_dir: ArrayLike, idx: NDArray[np.intp]) -> VFHResult:
        """:meth:`step` with a scan, through :func:`_ranges_kernel` and :func:`_vfh_kernel`."""
        par, n = self.params, len(p)
        ranges = np.atleast_2d(np.asarray(scan.ranges, dtype=float))
        if ranges.shape[0] != n:
            raise ValueError("scan and pose must have the same number of rows")
        key = (scan.angle_min, scan.angle_increment, ranges.shape[1])
        if key != self._beam_key:  # the beam layout is fixed: trig once
            beta = wrap_angle(scan.angles)
            self._beam, self._beam_key = np.stack((beta, np.cos(beta), np.sin(beta))), key
        d, ratio, dmin = _ranges_kernel(ranges, *par.distance_limits,
                                        par.robot_radius + par.safety_distance,
                                        float(scan.range_min))
        gam = np.arcsin(ratio)  # enlargement angle, rad (NaN where unused)
        if neighbours is None:
            rel, bearing, nmask = np.zeros((n, 0, 2)), np.zeros((n, 0)), np.zeros((n, 0), bool)
        else:
            rel = np.asarray(neighbours.position, dtype=float) - p[:, None, :2]
            bearing = np.arctan2(rel[..., 1], rel[..., 0])
            nmask = np.asarray(neighbours.mask, dtype=bool)
        hist, binary, masked, direction, danger = _vfh_kernel(
            d, gam, dmin, self._beam, self._centres, np.ascontiguousarray(p[:, 2]),
            np.ascontiguousarray(target_dir, dtype=float).reshape(n), rel, bearing, nmask, idx,
            self.binary, self.previous_world, self._fp, par.use_turning_mask,
            neighbours is not None)
        return VFHResult(direction, np.isfinite(direction), dmin, danger, hist, binary, masked)
