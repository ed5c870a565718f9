"""The unit of every run metric: the one table that outputs and reports read.

:data:`UNITS` maps each key of :func:`dfcoa_opt.metrics.summary` and of
:func:`dfcoa_opt.metrics.world.world_difficulty` to its unit, as
``docs/metrics.md`` defines them: ``m``, ``s``, ``m/s``, ``rad/s``, ``m^2``,
``1/m^2``, ``%``, ``steps`` (simulation steps), ``1`` (counts, fractions,
ratios, true/false) and ``""`` for the ``outcome`` word. The controllers' own
counters (``ctl_<name>``) are counts. A metric added without a unit fails ``tests/test_metrics.py``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

#: Prefix of the controllers' own counters in a summary (``ctl_replans``, ...), all counts.
COUNTER_PREFIX = "ctl_"

#: Metric key -> unit.
UNITS: dict[str, str] = {
    # formation accuracy, paper 000 eq 6-8
    "fce_rms": "m", "fce_mean": "m", "fce_max": "m", "fce_x_rms": "m", "fce_y_rms": "m",
    "fse_rms": "m", "fse_mean": "m", "fce_open_rms": "m", "fse_open_rms": "m",
    "open_pct": "%", "fste_max": "m", "fste_final": "m", "stability_pct": "%",
    # velocity, eq 9-10 (eq 9 combines m/s and rad/s in one norm)
    "vce_rms": "m/s, rad/s", "v_rms": "m/s", "w_rms": "rad/s",
    # risk, eq 11, and safety
    "risk_mean": "1", "risk_max": "1", "risk_clip_pct": "%",
    "risk_raw_mean": "1/m^2", "risk_raw_max": "1/m^2",
    "min_inter_robot_distance": "m", "min_obstacle_clearance": "m", "collisions": "1",
    "robot_contact_steps": "steps", "obstacle_contact_steps": "steps",
    "dynamic_contact_steps": "steps",
    # mission, outcome and safety filter
    "path_length_mean": "m", "time_to_goal": "s", "outcome": "", "success": "1",
    "reached": "1", "first_contact_time": "s", "deadlock_time": "s",
    "filter_interventions": "1", "filter_fallbacks": "1", "filter_solver_failures": "1",
    "filter_time_median": "s", "mse_mean": "m^2", "lf_error_mean": "m", "loc_rmse": "m",
    "steps": "1",
    # deployability (dfcoa_opt.metrics.deploy)
    "wheel_speed_peak": "rad/s", "wheel_speed_ratio": "1", "wheel_accel_peak": "m/s^2",
    "wheel_accel_ratio": "1",
    "saturated_pct": "%", "body_gap_min": "m", "robotarium_arena": "1",
    "robotarium_collision": "1", "robotarium_speed": "1", "robotarium_ok": "1",
    # the world's difficulty along the leader's path (dfcoa_opt.metrics.world)
    "world_clearance": "m", "world_visibility": "m", "world_dispersion": "1",
    "world_characteristic_dimension": "m", "world_tortuosity": "1",
    "world_narrowest_ratio": "1", "world_narrow_passages": "1", "world_crossings": "1",
    "world_difficulty": "1", "world_path_length": "m", "world_reference_time": "s",
}


def unit(key: str) -> str:
    """The unit of a metric key (``ctl_<name>`` counters: ``"1"``).

    Raises:
        KeyError: A key without a unit in :data:`UNITS`.
    """
    if key in UNITS:
        return UNITS[key]
    if key.startswith(COUNTER_PREFIX):
        return "1"
    raise KeyError(f"metric '{key}' has no unit in dfcoa_opt.metrics.units.UNITS")


def units(keys: Iterable[str]) -> dict[str, str]:
    """``{key: unit(key)}`` for the keys, in their order."""
    return {k: unit(k) for k in keys}


def with_unit(value: Any, key: str) -> str:
    """A metric value for people: four significant digits and the unit.

    ``"0.002747 m"``, ``"65.4 s"``, ``"1"`` (a count has no unit word),
    ``"inf 1/m^2"``; ``"n/a"`` for an undefined (NaN or None) value.
    """
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "n/a"
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return str(value)
    text = f"{value:.4g}" if isinstance(value, float) else str(value)
    u = unit(key)
    return text if u in ("", "1") else f"{text} {u}"
