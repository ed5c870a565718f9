"""Every scalar metric of a run under its JSON key (:func:`summary`), and the run-wide ones.

The formation metrics (paper 000 eq 6-10) are :mod:`dfcoa_opt.metrics.formation`'s,
the collision risk (eq 11) :mod:`dfcoa_opt.metrics.risk`'s, the outcome
:mod:`dfcoa_opt.metrics.outcome`'s, the per-robot metrics of the companion papers
:mod:`dfcoa_opt.metrics.robots`'s, deployability :mod:`dfcoa_opt.metrics.deploy`'s;
each key's unit is in :mod:`dfcoa_opt.metrics.units`. Definitions: ``docs/metrics.md``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.control.base import STATUS_FALLBACK, STATUS_MODIFIED, STATUS_SOLVER_FAIL
from dfcoa_opt.metrics.deploy import deployability
from dfcoa_opt.metrics.formation import (
    centroid_offset,
    formation_shape_error,
    formation_stability_error,
    formation_stability_pct,
    max_of,
    mean_of,
    min_of,
    open_steps,
    rms,
    rms_velocities,
    velocity_centroid_error,
)
from dfcoa_opt.metrics.outcome import classify
from dfcoa_opt.metrics.risk import collision_risk, normalise_risk, run_risk
from dfcoa_opt.metrics.robots import (
    leader_follower_position_error,
    mse_per_robot,
    path_length_per_robot,
)
from dfcoa_opt.metrics.settings import Settings, log_radius, metric_settings
from dfcoa_opt.sim.log import RunLog

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


def min_inter_robot_distance(log: RunLog) -> float:
    """Smallest centre distance between two robots over the run, m (NaN if N == 1)."""
    d = min_of(log.min_inter_robot)
    return d if math.isfinite(d) else math.nan


def min_obstacle_clearance(log: RunLog) -> float:
    """Smallest surface gap to a static obstacle, ``min(clearance - radius)``, m.

    Negative values mean penetration; NaN for an empty log.
    """
    return min_of(log.clearance - log_radius(log))


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
    cfg = metric_settings(spec)
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
        "fce_mean": mean_of(fce),
        "fce_max": max_of(fce),
        "fce_x_rms": rms(off[:, 0]),
        "fce_y_rms": rms(off[:, 1]),
        "fse_rms": rms(fse),
        "fse_mean": mean_of(fse),
        "fce_open_rms": rms(fce[is_open]),
        "fse_open_rms": rms(fse[is_open]),
        "open_pct": 100.0 * mean_of(is_open),
        "fste_max": max_of(fste),
        "fste_final": float(fste[-1]) if len(fste) else math.nan,
        "stability_pct": formation_stability_pct(log, cfg),
        "vce_rms": rms(velocity_centroid_error(log)),
        "v_rms": mean_of(v_rms),
        "w_rms": mean_of(w_rms),
        "risk_mean": mean_of(risk),
        "risk_max": max_of(risk),
        "risk_clip_pct": 100.0 * mean_of(risk >= 1.0),
        "risk_raw_mean": raw_mean,
        "risk_raw_max": raw_max,
        "min_inter_robot_distance": min_inter_robot_distance(log),
        "min_obstacle_clearance": min_obstacle_clearance(log),
        "collisions": int(np.sum(log.collision_events)),
        "robot_contact_steps": int(np.count_nonzero(log.robot_contacts > 0)),
        "obstacle_contact_steps": int(np.count_nonzero(
            (log.obstacle_contacts > 0) | (log.dynamic_contacts > 0))),
        "dynamic_contact_steps": int(np.count_nonzero(log.dynamic_contacts > 0)),
        "path_length_mean": mean_of(path_length_per_robot(log)),
        "time_to_goal": float(ttg) if end["reached"] and ttg is not None else math.nan,
        "outcome": end["outcome"],
        "success": end["outcome"] == "success",
        "reached": end["reached"],
        "first_contact_time": end["first_contact_time"],
        "deadlock_time": end["deadlock_time"],
        **filter_counts(log),
        "mse_mean": mean_of(mse_per_robot(log)),
        "lf_error_mean": mean_of(leader_follower_position_error(log)),
        "loc_rmse": rms(localization_error(log)),
        "steps": int(log.n_steps),
        **deployability(log),
        **{f"ctl_{k}": int(v) for k, v in (log.meta.get("controller_counters") or {}).items()},
    }
