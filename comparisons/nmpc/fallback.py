"""The ``nmpc`` controller's failure side (:mod:`comparisons.nmpc.controller`).

The ``goto`` fallback command, and the solve-time and failure statistics of a run.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.core.geometry import wrap_angle
from dfcoa_opt.sim.log import STATUS_SOLVER_FAIL, RunLog

if TYPE_CHECKING:
    from comparisons.nmpc.problem import ProblemSpec

FloatArray = NDArray[np.float64]


def goto_command(pose: FloatArray, slot: FloatArray, gain: float, spec: ProblemSpec
                 ) -> FloatArray:
    """Proportional unicycle command towards the slot (the ``goto`` fallback).

    ``v = k (e . heading)``, ``omega = 2 k wrap(atan2(e) - theta)``, clipped to the
    limits, with ``e = slot - p`` (m) and ``k = gain`` (1/s).

    Returns:
        ``(2,)`` (v m/s, omega rad/s).
    """
    e = np.asarray(slot, float) - pose[:2]
    th = float(pose[2])
    v = gain * (e[0] * math.cos(th) + e[1] * math.sin(th))
    err = float(wrap_angle(math.atan2(e[1], e[0]) - th)) if np.hypot(*e) > 1e-9 else 0.0
    return np.array([min(max(v, spec.v_min), spec.v_max),
                     min(max(2.0 * gain * err, -spec.w_max), spec.w_max)])


def solve_time_stats(log: RunLog) -> dict[str, float | int]:
    """Solve time per robot per step of an ``nmpc`` run, and its failures.

    Args:
        log: The run log (``filter_time`` and ``filter_status`` hold ``last_result``).

    Returns:
        ``median`` and ``p95`` solve time (s) over every (step, robot) entry,
        ``entries`` counted, ``failures`` (status ``STATUS_SOLVER_FAIL``) and
        ``failure_rate`` (failures / entries).
    """
    times = np.asarray(log.filter_time, float).ravel()
    fails = int(np.count_nonzero(np.asarray(log.filter_status) == STATUS_SOLVER_FAIL))
    if times.size == 0:
        return {"median": math.nan, "p95": math.nan, "entries": 0, "failures": fails,
                "failure_rate": math.nan}
    return {"median": float(np.median(times)), "p95": float(np.percentile(times, 95)),
            "entries": int(times.size), "failures": fails,
            "failure_rate": fails / times.size}
