"""The formation metrics of paper 000 section 3.3 (eq 6-10), and the reductions its tables use.

Every metric is a pure, vectorised function of a :class:`~dfcoa_opt.sim.log.RunLog`;
time series have one value per logged step ``t[k]``. Definitions and choices:
``docs/metrics.md``.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.metrics.risk import CHUNK_ELEMS
from dfcoa_opt.metrics.settings import Settings, log_radius, log_step, metric_settings
from dfcoa_opt.scenario.schema import MetricSpec
from dfcoa_opt.sim.log import RunLog

FloatArray = NDArray[np.float64]


def rms(x: np.ndarray) -> float:
    """Root mean square of all entries; NaN when empty."""
    return float(np.sqrt(np.mean(np.square(x)))) if np.size(x) else math.nan


def mean_of(x: np.ndarray) -> float:
    """Mean of all entries; NaN when empty."""
    return float(np.mean(x)) if np.size(x) else math.nan


def max_of(x: np.ndarray) -> float:
    """Largest entry; NaN when empty."""
    return float(np.max(x)) if np.size(x) else math.nan


def min_of(x: np.ndarray) -> float:
    """Smallest entry; NaN when empty."""
    return float(np.min(x)) if np.size(x) else math.nan


def centroids(log: RunLog) -> tuple[FloatArray, FloatArray]:
    """Actual and desired centroids (paper 000 eq 6), ``(T, 2)`` each in m: means of pose, slots."""
    return log.pose[..., :2].mean(axis=1), log.slots.mean(axis=1)


def centroid_offset(log: RunLog) -> FloatArray:
    """Centroid error vector ``(X_c - X_c*, Y_c - Y_c*)`` (paper 000 eq 6), ``(T, 2)`` in m."""
    actual, desired = centroids(log)
    return actual - desired


def formation_centroid_error(log: RunLog) -> FloatArray:
    """Compute the Formation Centroid Error E_c(t), paper 000 eq 6.

    Args:
        log: The run.

    Returns:
        ``(T,)`` distance between the actual and the desired centroid, m.
    """
    return np.linalg.norm(centroid_offset(log), axis=-1)


def formation_shape_error(log: RunLog) -> FloatArray:
    """Compute the Formation Shape Error E_s(t), paper 000 eq 7.

    ``E_s = mean_i ||(p_i - centroid) - (p_i* - centroid*)||``: the mean distance
    between each robot's and its slot's position relative to their centroids.
    The unit is m (Table 5's m^2 is a typo).

    Args:
        log: The run.

    Returns:
        ``(T,)`` shape error, m.
    """
    rel = (log.pose[..., :2] - log.slots) - centroid_offset(log)[:, None, :]
    return np.linalg.norm(rel, axis=-1).mean(axis=1)


def formation_stability_error(log: RunLog, window_s: float | None = None) -> FloatArray:
    """Compute the Formation Stability Error E_st(t), paper 000 eq 8.

    Trailing moving average of E_c (eq 6) over the ``n = max(1, round(T / dt))``
    most recent samples, the current one included (rectangle rule of
    ``1/T int_{t-T}^t E_c``). While fewer than n samples exist, the mean is over
    the samples there are.

    Args:
        log: The run.
        window_s: Window T in s; default ``MetricSpec.fste_window`` (5 s).

    Returns:
        ``(T,)`` moving-average centroid error, m.
    """
    window = MetricSpec().fste_window if window_s is None else float(window_s)
    n = max(1, int(round(window / log_step(log))))
    ec = formation_centroid_error(log)
    csum = np.concatenate(([0.0], np.cumsum(ec)))
    k = np.arange(len(ec))
    start = np.maximum(k + 1 - n, 0)
    return (csum[k + 1] - csum[start]) / (k + 1 - start)


def velocity_centroid_error(log: RunLog) -> FloatArray:
    """Velocity Centroid Error E_v(t), paper 000 eq 9.

    ``V_c, omega_c`` are the means over robots of the applied twist; the desired
    values are the virtual leader's ``(v, omega)`` (``leader[:, 3:5]``).

    Args:
        log: The run.

    Returns:
        ``(T,)`` error, in the mixed unit of eq 9 (m/s combined with rad/s).
    """
    return np.linalg.norm(log.twist.mean(axis=1) - log.leader[:, 3:5], axis=-1)


def rms_velocities(log: RunLog) -> tuple[FloatArray, FloatArray]:
    """RMS linear and angular velocity over the robots, paper 000 eq 10.

    Args:
        log: The run.

    Returns:
        ``(v_rms, w_rms)``, each ``(T,)``: ``sqrt(mean_i v_i^2)`` in m/s and
        ``sqrt(mean_i omega_i^2)`` in rad/s per step.
    """
    per = np.sqrt(np.mean(np.square(log.twist), axis=1))
    return per[:, 0], per[:, 1]


def open_steps(log: RunLog, spec: Settings = None) -> NDArray[np.bool_]:
    """``(T,)`` steps on an open stretch, where nothing is near any robot.

    Every robot keeps a surface gap of at least ``metrics.open_clearance`` (m)
    to every static obstacle and every moving disc. Where nothing is near, no
    method has a reason to deform the formation, so the formation errors over
    these steps (``fce_open_rms``, ``fse_open_rms``) compare tracking alone.
    """
    cfg = metric_settings(spec)
    r = log_radius(log)
    ok = np.all(log.clearance - r >= cfg.open_clearance, axis=1)
    n_t, n = log.pose.shape[:2]
    m = len(log.dyn_radius)
    if m == 0 or n == 0:
        return ok
    step = max(1, CHUNK_ELEMS // (n * m))
    for s in range(0, n_t, step):
        diff = log.pose[s:s + step, :, None, :2] - log.dyn_pos[s:s + step, None, :, :]
        gap = np.linalg.norm(diff, axis=-1) - log.dyn_radius - r
        ok[s:s + step] &= np.all(gap >= cfg.open_clearance, axis=(1, 2))
    return ok


def formation_stability_pct(log: RunLog, spec: Settings = None) -> float:
    """Compute the formation stability (paper 000 Table 5): % of steps with E_s < threshold.

    Args:
        log: The run.
        spec: Metric settings (``stability_threshold``, m; default 0.5).

    Returns:
        Percentage of steps whose shape error (eq 7) is below the threshold; NaN
        for an empty log.
    """
    es = formation_shape_error(log)
    return 100.0 * mean_of(es < metric_settings(spec).stability_threshold)
