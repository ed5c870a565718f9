"""Run metrics of paper 000 section 3.3 (eq 6-11) and of papers 002 and 004.

Every metric is a pure, vectorised function of a :class:`~dfcoa_opt.sim.log.RunLog`
(and, where it has settings, a :class:`~dfcoa_opt.scenario.schema.MetricSpec`, or a
``ScenarioSpec`` / ``Scenario`` whose ``metrics`` section is used). Time series
have one value per logged step ``t[k]``; summaries average over all logged steps.
:func:`summary` collects the JSON keys; every definition and choice is written
down in ``docs/metrics.md``. The collision risk of eq 11 is in
:mod:`dfcoa_opt.metrics.risk` (re-exported here), the per-robot metrics of the
companion papers' tables in :mod:`dfcoa_opt.metrics.robots`, the deployability
report in :mod:`dfcoa_opt.metrics.deploy`, and the unit of
every key in :mod:`dfcoa_opt.metrics.units` (:data:`UNITS`, re-exported).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.control.base import STATUS_FALLBACK, STATUS_MODIFIED, STATUS_SOLVER_FAIL
from dfcoa_opt.metrics.deploy import deployability
from dfcoa_opt.metrics.outcome import classify
from dfcoa_opt.metrics.risk import (
    CHUNK_ELEMS,
    RISK_DISTANCE_FLOOR,
    Settings,
    collision_risk,
    collision_risk_normalised,
    normalise_risk,
    run_risk,
)
from dfcoa_opt.metrics.risk import metric_settings as _cfg
from dfcoa_opt.metrics.robots import (
    leader_follower_position_error,
    mse_per_robot,
    path_length_per_robot,
)
from dfcoa_opt.metrics.units import UNITS, unit
from dfcoa_opt.scenario.schema import MetricSpec
from dfcoa_opt.sim.log import RunLog

__all__ = ["PAPER_000_TABLE5", "RISK_DISTANCE_FLOOR", "UNITS", "centroid_offset", "centroids",
           "collision_risk", "collision_risk_normalised", "filter_counts",
           "formation_centroid_error", "formation_shape_error", "formation_stability_error",
           "formation_stability_pct", "localization_error", "min_inter_robot_distance",
           "min_obstacle_clearance", "normalise_risk", "open_steps", "rms", "rms_velocities",
           "summary", "unit", "velocity_centroid_error"]

FloatArray = NDArray[np.float64]

#: Paper 000 Table 5, (Scenario 1, Scenario 2), under this module's summary keys.
PAPER_000_TABLE5: dict[str, tuple[float, float]] = {
    "fce_rms": (0.9516, 1.0008), "fce_mean": (0.9486, 1.0002), "fce_max": (1.1365, 1.1340),
    "fce_x_rms": (0.7880, 0.6648), "fce_y_rms": (0.5334, 0.7481),
    "fse_rms": (1.0511, 0.6399), "fse_mean": (1.1047, 0.4094),  # paper prints m^2; it is m
    "stability_pct": (95.8, 94.6), "vce_rms": (0.2699, 0.1700),
    "v_rms": (0.3198, 0.3173), "w_rms": (0.0539, 0.0654),
    "risk_mean": (0.7773, 0.5143), "risk_max": (1.0000, 0.6237),
    "min_inter_robot_distance": (0.4702, 0.8763),
}


def _dt(log: RunLog) -> float:
    """Step in s: ``meta["dt"]``, else the spacing of ``t``, else 1."""
    if log.meta.get("dt") is not None:
        return float(log.meta["dt"])
    return float(log.t[1] - log.t[0]) if len(log.t) > 1 else 1.0


def _radius(log: RunLog) -> float:
    """Robot radius in m from ``meta["robot_radius"]``."""
    if log.meta.get("robot_radius") is None:
        raise ValueError("RunLog.meta has no 'robot_radius'")
    return float(log.meta["robot_radius"])


def rms(x: np.ndarray) -> float:
    """Root mean square of all entries; NaN when empty."""
    return float(np.sqrt(np.mean(np.square(x)))) if np.size(x) else math.nan


def _mean(x: np.ndarray) -> float:
    """Mean of all entries; NaN when empty."""
    return float(np.mean(x)) if np.size(x) else math.nan


def _max(x: np.ndarray) -> float:
    """Largest entry; NaN when empty."""
    return float(np.max(x)) if np.size(x) else math.nan


def _min(x: np.ndarray) -> float:
    """Smallest entry; NaN when empty."""
    return float(np.min(x)) if np.size(x) else math.nan


# --------------------------------------------------------------- paper 000, eq 6-11
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
    n = max(1, int(round(window / _dt(log))))
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
    cfg = _cfg(spec)
    r = _radius(log)
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
    return 100.0 * _mean(es < _cfg(spec).stability_threshold)


# ------------------------------------------------------------------- general metrics
def min_inter_robot_distance(log: RunLog) -> float:
    """Smallest centre distance between two robots over the run, m (NaN if N == 1)."""
    d = _min(log.min_inter_robot)
    return d if math.isfinite(d) else math.nan


def min_obstacle_clearance(log: RunLog) -> float:
    """Smallest surface gap to a static obstacle, ``min(clearance - radius)``, m.

    Negative values mean penetration; NaN for an empty log.
    """
    return _min(log.clearance - _radius(log))


def filter_counts(log: RunLog) -> dict[str, int | float]:
    """Safety-filter statistics over all (step, robot) entries.

    Returns:
        ``filter_interventions`` (status 1), ``filter_fallbacks`` (status 2 or 3),
        ``filter_solver_failures`` (status 3), and ``filter_time_median`` in s:
        median solve time over entries with a filter (time > 0 or status != 0), 0
        when there is none.
    """
    st = log.filter_status
    used = (log.filter_time > 0.0) | (st != 0)
    return {
        "filter_interventions": int(np.count_nonzero(st == STATUS_MODIFIED)),
        "filter_fallbacks": int(np.count_nonzero((st == STATUS_FALLBACK)
                                                 | (st == STATUS_SOLVER_FAIL))),
        "filter_solver_failures": int(np.count_nonzero(st == STATUS_SOLVER_FAIL)),
        "filter_time_median": float(np.median(log.filter_time[used])) if used.any() else 0.0,
    }


# --------------------------------------------------------------------------- summary
def localization_error(log: RunLog) -> FloatArray:
    """``(T, N)`` distance between estimated and true position, m (0 with ``truth``)."""
    return np.hypot(*(log.pose_est[..., :2] - log.pose[..., :2]).transpose(2, 0, 1))


def summary(log: RunLog, spec: Settings = None) -> dict[str, Any]:
    """Every scalar metric of a run under its JSON key (docs/metrics.md).

    Args:
        log: The run.
        spec: Metric settings; default ``MetricSpec()``.

    Returns:
        Python floats, ints and bools (NaN where undefined; ``risk_raw_mean`` and
        ``risk_raw_max`` are ``inf`` for a run with a contact); each key's unit
        is :func:`unit` of it.
    """
    cfg = _cfg(spec)
    off = centroid_offset(log)
    fce = np.linalg.norm(off, axis=-1)
    fse = formation_shape_error(log)
    fste = formation_stability_error(log, cfg.fste_window)
    v_rms, w_rms = rms_velocities(log)
    raw = collision_risk(log, cfg)
    risk = normalise_risk(raw, cfg)
    ttg = log.meta.get("time_to_goal")
    end = classify(log, cfg)
    raw_mean, raw_max = run_risk(raw, end["outcome"] == "collision")
    is_open = open_steps(log, cfg)
    return {
        "fce_rms": rms(fce),
        "fce_mean": _mean(fce),
        "fce_max": _max(fce),
        "fce_x_rms": rms(off[:, 0]),
        "fce_y_rms": rms(off[:, 1]),
        "fse_rms": rms(fse),
        "fse_mean": _mean(fse),
        "fce_open_rms": rms(fce[is_open]),
        "fse_open_rms": rms(fse[is_open]),
        "open_pct": 100.0 * _mean(is_open),
        "fste_max": _max(fste),
        "fste_final": float(fste[-1]) if len(fste) else math.nan,
        "stability_pct": formation_stability_pct(log, cfg),
        "vce_rms": rms(velocity_centroid_error(log)),
        "v_rms": _mean(v_rms),
        "w_rms": _mean(w_rms),
        "risk_mean": _mean(risk),
        "risk_max": _max(risk),
        "risk_clip_pct": 100.0 * _mean(risk >= 1.0),
        "risk_raw_mean": raw_mean,
        "risk_raw_max": raw_max,
        "min_inter_robot_distance": min_inter_robot_distance(log),
        "min_obstacle_clearance": min_obstacle_clearance(log),
        "collisions": int(np.sum(log.collision_events)),
        "robot_contact_steps": int(np.count_nonzero(log.robot_contacts > 0)),
        "obstacle_contact_steps": int(np.count_nonzero(
            (log.obstacle_contacts > 0) | (log.dynamic_contacts > 0))),
        "dynamic_contact_steps": int(np.count_nonzero(log.dynamic_contacts > 0)),
        "path_length_mean": _mean(path_length_per_robot(log)),
        "time_to_goal": float(ttg) if end["reached"] and ttg is not None else math.nan,
        "outcome": end["outcome"],
        "success": end["outcome"] == "success",
        "reached": end["reached"],
        "first_contact_time": end["first_contact_time"],
        "deadlock_time": end["deadlock_time"],
        **filter_counts(log),
        "mse_mean": _mean(mse_per_robot(log)),
        "lf_error_mean": _mean(leader_follower_position_error(log)),
        "loc_rmse": rms(localization_error(log)),
        "steps": int(log.n_steps),
        **deployability(log),
        **{f"ctl_{k}": int(v) for k, v in (log.meta.get("controller_counters") or {}).items()},
    }
