"""Improved VFH* with inter-robot repulsion (paper 000, Algorithm 1, eq 29, section 4.5.3).

Batched over robots (row i = robot i, computed from robot i's inputs only) and
vectorised over beams and sectors. Frame: the robot frame (0 = heading,
counter-clockwise positive). Sector ``j`` of ``K`` is centred on
``wrap(j * 2 pi / K)`` (Algorithm 1 line 8: ``round(theta / dtheta) * dtheta``),
so sector 0 is straight ahead. Pipeline (:func:`vfh_step`):

1. :func:`polar_histogram` -- LiDAR returns within ``distance_limits`` weighted
   by ``1/d^2`` (Alg. 1 lines 5-11), each spread over every sector its enlarged
   obstacle ``[beta - gamma, beta + gamma]``, ``gamma = asin((r + s)/d)`` touches
   (VFH+ enlargement, MATLAB ``controllerVFH``).
2. :func:`repulsion_histogram` -- ``lambda (d_safe - d)`` added to the sector of
   each neighbour closer than ``d_safe`` (Alg. 1 lines 12-22).
3. :func:`binary_histogram` -- hysteresis on two thresholds (MATLAB
   ``HistogramThresholds``); :func:`turning_mask` -- VFH+ minimum-turning-radius mask.
4. :func:`select_direction` -- candidates = free sectors (+ the target direction
   when its sector is free), minimise ``J`` of eq 29 (Alg. 1 lines 23-44).
5. :mod:`dfcoa_opt.control.dfcoa.vfh_star`: :func:`~dfcoa_opt.control.dfcoa.vfh_star.vfh_step`
   runs 1-4, and ``danger_level`` and ``blend`` are the safety layer of
   section 4.5.3; :class:`~dfcoa_opt.control.dfcoa.vfh_star.VFHStar` keeps the state.

Choices and Table 2 units: ``docs/methods/vfh.md``. The scalar numba helpers
:func:`sector1` (bit-identical to :func:`sector_index`) and
:func:`wrap_angles` serve the kernels of ``vfh_star``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from dfcoa_opt.core.errors import ScenarioError
from dfcoa_opt.core.geometry import wrap_angle
from dfcoa_opt.core.params import param
from dfcoa_opt.core.scalar_kernels import wrap1

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class VFHParams:
    """Parameters of the improved VFH* and of its blending rule (paper 000 Table 2)."""

    num_sectors: int = param(25, doc="Angular sectors K over 2 pi (Table 2 'Angular Selector').",
                             ge=4, le=3600)
    distance_limits: tuple[float, float] = param(
        (0.05, 3.5), doc="LiDAR ranges used in the histogram (Table 2 'Distance limits' = "
                         "upper; lower = MATLAB default).", unit="m", ge=0.0)
    robot_radius: float = param(0.1, doc="Robot radius r for the enlargement; set it to "
                                         "robots.radius.", unit="m", ge=0.0)
    safety_distance: float = param(0.1, doc="Extra clearance s for the enlargement (MATLAB "
                                            "SafetyDistance; not Table 2's d_safe).",
                                   unit="m", ge=0.0, tune=(0.0, 0.4))
    min_turning_radius: float = param(0.1, doc="Minimum turning radius of the masked "
                                               "histogram.", unit="m", ge=0.0)
    use_turning_mask: bool = param(True, doc="Apply the VFH+ minimum-turning-radius mask.")
    histogram_thresholds: tuple[float, float] = param(
        (5.0, 20.0), doc="(low, high): above high a sector is blocked, below low free, "
                         "in between unchanged (Table 2).", unit="1/m^2", ge=0.0)
    d_safe: float = param(8.5, doc="Neighbours closer than this repel (Table 2 d_safe).",
                          unit="m", ge=0.0)
    repulsive_gain: float = param(3.5, doc="Repulsive gain lambda (Table 2).", unit="1/m^3",
                                  ge=0.0)
    obstacle_weight: float = param(1.0, doc="alpha of eq 29, on C_obs = H / high threshold.",
                                   ge=0.0)
    target_weight: float = param(5.0, doc="beta of eq 29 (MATLAB TargetDirectionWeight).",
                                 unit="1/rad", ge=0.0, tune=(1.0, 10.0), scale="log")
    current_weight: float = param(2.0, doc="gamma of eq 29, deviation from the heading "
                                           "(MATLAB CurrentDirectionWeight).",
                                  unit="1/rad", ge=0.0)
    previous_weight: float = param(2.0, doc="Deviation from the previous choice (MATLAB "
                                            "PreviousDirectionWeight).", unit="1/rad", ge=0.0)
    blend_start: float = param(1.0, doc="Nearest return at which the VFH command starts to "
                                        "take over (danger 0 beyond).", unit="m", gt=0.0,
                               tune=(0.6, 2.0))
    blend_full: float = param(0.5, doc="Nearest return at which the VFH command fully "
                                       "overrides (danger 1 below).", unit="m", ge=0.0)
    heading_gain: float = param(2.0, doc="omega = gain * steering angle in the VFH command.",
                                unit="1/s", gt=0.0)
    w_max: float = param(1.5, doc="Largest |omega| of the VFH command.", unit="rad/s", gt=0.0)
    avoid_speed: float = param(0.3, doc="Largest forward speed of the VFH command.",
                               unit="m/s", ge=0.0)

    def check(self, src: str, key: str) -> None:
        """Ordered limits, thresholds and blending distances."""
        pre = f"{key}." if key else ""
        if not self.distance_limits[0] < self.distance_limits[1]:
            raise ScenarioError(src, pre + "distance_limits", "needs lower < upper")
        if not self.histogram_thresholds[0] <= self.histogram_thresholds[1]:
            raise ScenarioError(src, pre + "histogram_thresholds", "needs low <= high")
        if not self.blend_full < self.blend_start:
            raise ScenarioError(src, pre + "blend_full", "must be < blend_start")

    @property
    def sector_width(self) -> float:
        """Delta theta = 2 pi / K, rad."""
        return 2.0 * np.pi / self.num_sectors


@dataclass(frozen=True)
class VFHResult:
    """Output of one VFH* step (row i = robot i; angles in the robot frame).

    Attributes:
        direction: ``(N,)`` steering direction theta*, rad; NaN when no candidate.
        found: ``(N,)`` True where a candidate direction exists.
        min_distance: ``(N,)`` nearest LiDAR return, m (``inf`` = none).
        danger: ``(N,)`` blending weight in [0, 1] (:func:`danger_level`).
        histogram: ``(N, K)`` polar histogram incl. repulsion, 1/m^2.
        binary: ``(N, K)`` binary histogram after hysteresis (True = blocked).
        masked: ``(N, K)`` binary plus turning mask (True = not a candidate).
    """

    direction: FloatArray
    found: BoolArray
    min_distance: FloatArray
    danger: FloatArray
    histogram: FloatArray
    binary: BoolArray
    masked: BoolArray


@numba.njit(cache=True)
def sector1(angle: float, scale: float, k: int) -> int:  # pragma: no cover - numba
    """Scalar :func:`sector_index`, ``scale = K / (2 pi)`` in 1/rad (finite ``angle``)."""
    return int(np.floor(angle * scale + 0.5)) % k


@numba.njit(cache=True)
def _wrap_kernel(a: FloatArray, out: FloatArray) -> None:  # pragma: no cover - numba
    for i in range(a.size):
        out[i] = wrap1(a[i])


def wrap_angles(a: ArrayLike) -> FloatArray:
    """:func:`~dfcoa_opt.core.geometry.wrap_angle` as one numba call (bit-identical, faster).

    Args:
        a: Angles in rad, any shape.

    Returns:
        The angles wrapped to (-pi, pi], rad, same shape.
    """
    a = np.asarray(a, dtype=float, order="C")
    out = np.empty_like(a)
    _wrap_kernel(a.reshape(-1), out.reshape(-1))
    return out


def sector_centres(num_sectors: int) -> FloatArray:
    """``(K,)`` sector centres ``wrap(j * 2 pi / K)``, rad (Alg. 1 line 8)."""
    return wrap_angle(np.arange(num_sectors) * (2.0 * np.pi / num_sectors))


def sector_index(angles: ArrayLike, num_sectors: int) -> NDArray[np.intp]:
    """Sector of each angle: ``round(angle / dtheta) mod K`` (Alg. 1 lines 8, 18).

    Args:
        angles: Finite angles in rad, any shape.
        num_sectors: K.
    """
    x = np.asarray(angles, dtype=float) * (num_sectors / (2.0 * np.pi))
    return np.mod(np.floor(x + 0.5), num_sectors).astype(np.intp)


def used_ranges(ranges: ArrayLike, params: VFHParams) -> FloatArray:
    """Ranges used by the histogram: NaN outside the limits, ``-inf``/short clamped up.

    Returns closer than the lower limit (REP-117 ``-inf`` included) count as being
    at the lower limit; beyond the upper limit, ``+inf`` and NaN are dropped.

    Args:
        ranges: ``(N, B)`` ranges, m.
        params: Uses ``distance_limits``.
    """
    lo, hi = params.distance_limits
    r = np.asarray(ranges, dtype=float)
    d = np.where(r < lo, lo, r)
    return np.where(d <= hi, d, np.nan)


def polar_histogram(ranges: ArrayLike, angles: ArrayLike, params: VFHParams) -> FloatArray:
    """Primary polar histogram with ``1/d^2`` weights and VFH+ enlargement.

    Every used return (Alg. 1 lines 5-11) adds ``w = 1/d^2`` to each sector whose
    extent ``[c_j - dtheta/2, c_j + dtheta/2]`` meets ``[beta - gamma, beta + gamma]``,
    ``gamma = asin((r + s) / d)`` (``pi/2`` when ``d <= r + s``), so every direction
    in a sector without weight clears all enlarged returns. One ``bincount`` over
    (return, blocked sector) pairs: exact sums, no loop over beams.

    Args:
        ranges: ``(N, B)`` ranges, m (REP-117).
        angles: ``(B,)`` beam angles in the robot frame, rad.
        params: Sectors, limits, radius and safety distance.

    Returns:
        ``(N, K)`` histogram, 1/m^2.
    """
    k = params.num_sectors
    d = used_ranges(np.atleast_2d(ranges), params)
    n = d.shape[0]
    rows, cols = np.nonzero(np.isfinite(d))
    dv = d[rows, cols]
    beta = wrap_angle(np.broadcast_to(np.asarray(angles, dtype=float), d.shape)[rows, cols])
    w = 1.0 / dv**2
    gam = np.arcsin(np.minimum(1.0, (params.robot_radius + params.safety_distance) / dv))
    inv = 1.0 / params.sector_width
    lo = np.ceil((beta - gam) * inv - 0.5).astype(np.intp)
    hi = np.floor((beta + gam) * inv + 0.5).astype(np.intp)
    length = np.minimum(hi - lo + 1, k)  # sectors per return, <= K/2 + 2
    step = np.arange(int(length.max(initial=0)))
    take = step[None, :] < length[:, None]  # (returns, L): the sectors each return blocks
    flat = rows[:, None] * k + np.mod(lo[:, None] + step[None, :], k)
    weights = np.broadcast_to(w[:, None], take.shape)[take]
    return np.bincount(flat[take], weights, minlength=n * k).reshape(n, k)


def repulsion_histogram(pose: ArrayLike, positions: ArrayLike, mask: ArrayLike,
                        params: VFHParams) -> FloatArray:
    """Inter-robot repulsion ``lambda (d_safe - d)`` in each neighbour's sector (Alg. 1 l. 12-22).

    Args:
        pose: ``(N, 3)`` own poses (x, y, theta), m, m, rad.
        positions: ``(N, M, 2)`` neighbour positions, m (world frame).
        mask: ``(N, M)`` True where a neighbour exists.
        params: ``d_safe``, ``repulsive_gain``, ``num_sectors``.

    Returns:
        ``(N, K)`` repulsion added to the histogram (0 where ``d >= d_safe``).
    """
    p = np.asarray(pose, dtype=float)
    rel = np.asarray(positions, dtype=float) - p[:, None, :2]
    d = np.hypot(rel[..., 0], rel[..., 1])
    active = np.asarray(mask, dtype=bool) & (d < params.d_safe)
    bearing = np.arctan2(rel[..., 1], rel[..., 0]) - p[:, 2:3]
    j = sector_index(bearing, params.num_sectors)
    k = params.num_sectors
    flat = (np.arange(len(p))[:, None] * k + j)[active]
    val = (params.repulsive_gain * (params.d_safe - d))[active]
    return np.bincount(flat, val, minlength=len(p) * k).reshape(len(p), k)


def binary_histogram(histogram: ArrayLike, previous: ArrayLike,
                     thresholds: tuple[float, float]) -> BoolArray:
    """Binary histogram with hysteresis (VFH+; MATLAB ``HistogramThresholds``).

    Args:
        histogram: ``(N, K)`` polar histogram.
        previous: ``(N, K)`` previous binary histogram (True = blocked).
        thresholds: (low, high).

    Returns:
        ``(N, K)``: True above ``high``, False below ``low``, ``previous`` otherwise.
    """
    h = np.asarray(histogram, dtype=float)
    low, high = thresholds
    return np.where(h > high, True, np.where(h < low, False, np.asarray(previous, dtype=bool)))


def turning_mask(ranges: ArrayLike, angles: ArrayLike, params: VFHParams) -> BoolArray:
    """VFH+ masked-histogram limits from the minimum turning radius ``r_t``.

    A used return at ``(x, y)`` with bearing ``beta <= 0`` closer than ``r_t + r + s``
    to the right turning circle's centre ``(0, -r_t)`` blocks every direction right
    of ``beta`` (``phi_r = max beta``); left likewise with ``(0, r_t)`` and ``phi_l``.

    Args:
        ranges: ``(N, B)`` ranges, m.
        angles: ``(B,)`` beam angles, rad.
        params: Turning radius, robot radius, safety distance, sectors.

    Returns:
        ``(N, K)`` True where part of the sector lies beyond ``phi_r`` or ``phi_l``.
    """
    d = used_ranges(np.atleast_2d(ranges), params)
    beta = wrap_angle(np.broadcast_to(np.asarray(angles, dtype=float), d.shape))
    x, y = d * np.cos(beta), d * np.sin(beta)  # NaN where unused: comparisons are False
    rt = params.min_turning_radius
    reach = (rt + params.robot_radius + params.safety_distance) ** 2
    right = (beta <= 0.0) & (x**2 + (y + rt) ** 2 < reach)
    left = (beta >= 0.0) & (x**2 + (y - rt) ** 2 < reach)
    phi_r = np.where(right, beta, -np.inf).max(axis=1, initial=-np.inf)[:, None]
    phi_l = np.where(left, beta, np.inf).min(axis=1, initial=np.inf)[:, None]
    c = sector_centres(params.num_sectors)[None, :]
    half = 0.5 * params.sector_width
    return (np.isfinite(phi_r) & (c - half < phi_r)) | (np.isfinite(phi_l) & (c + half > phi_l))


def _gap(a: ArrayLike, b: ArrayLike) -> FloatArray:
    """Angular distance ``|wrap(a - b)|`` in [0, pi], rad."""
    return np.abs(wrap_angle(np.asarray(a) - np.asarray(b)))


def select_direction(masked: ArrayLike, histogram: ArrayLike, target_dir: ArrayLike,
                     previous_dir: ArrayLike, params: VFHParams) -> FloatArray:
    """Steering direction minimising ``J`` of eq 29 over the candidates (Alg. 1 l. 23-44).

    Candidates: the centre of every free sector, plus the target direction itself
    when its sector is free (listed first, so it wins ties). Cost::

        J = alpha H_j / tau_high + beta |c - t| + gamma |c| + gamma_prev |c - c_prev|

    with angular distances wrapped to [0, pi]; a NaN target or previous direction
    drops its term.

    Args:
        masked: ``(N, K)`` True = sector not a candidate.
        histogram: ``(N, K)`` polar histogram (C_obs source).
        target_dir: ``(N,)`` target direction in the robot frame, rad.
        previous_dir: ``(N,)`` previous steering direction in the robot frame, rad.
        params: Weights and thresholds.

    Returns:
        ``(N,)`` theta* in rad (a sector centre or the target), NaN when every
        sector is masked.
    """
    free = ~np.asarray(masked, dtype=bool)
    h = np.asarray(histogram, dtype=float)
    n, k = free.shape
    t = np.asarray(target_dir, dtype=float).reshape(n)
    prev = np.asarray(previous_dir, dtype=float).reshape(n)
    has_t = np.isfinite(t)
    t0 = np.where(has_t, t, 0.0)
    t0 = np.where((t0 > -np.pi) & (t0 <= np.pi), t0, wrap_angle(t0))  # keep exact if wrapped
    jt = sector_index(t0, k)
    rows = np.arange(n)
    cand = np.concatenate([t0[:, None], np.broadcast_to(sector_centres(k), (n, k))], axis=1)
    ok = np.concatenate([(has_t & free[rows, jt])[:, None], free], axis=1)
    c_obs = np.concatenate([h[rows, jt][:, None], h], axis=1) / max(
        params.histogram_thresholds[1], np.finfo(float).tiny)
    cost = (params.obstacle_weight * c_obs
            + np.where(has_t[:, None], params.target_weight * _gap(cand, t0[:, None]), 0.0)
            + params.current_weight * np.abs(cand))
    has_p = np.isfinite(prev)[:, None]
    cost = cost + np.where(has_p, params.previous_weight
                           * _gap(cand, np.where(has_p, prev[:, None], 0.0)), 0.0)
    best = np.argmin(np.where(ok, cost, np.inf), axis=1)
    return np.where(ok.any(axis=1), cand[rows, best], np.nan)
