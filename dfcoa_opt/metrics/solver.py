"""Solver statistics of a run: solve time per robot per step, and solver failures.

A pure function of a :class:`~dfcoa_opt.sim.log.RunLog`, for controllers and
safety filters that solve a program each step and log it through
``last_result`` (``filter_time``, ``filter_status``): ``nmpc``'s NLP, the
``cbf`` and ``orca`` filters' programs.
"""

from __future__ import annotations

import math

import numpy as np

from dfcoa_opt.control.base import STATUS_SOLVER_FAIL
from dfcoa_opt.sim.log import RunLog

__all__ = ["solve_time_stats"]


def solve_time_stats(log: RunLog) -> dict[str, float | int]:
    """Solve time per robot per step of a run (e.g. of ``nmpc``), and its solver failures.

    Args:
        log: The run log: ``filter_time`` ``(T, N)`` is the solve time of each robot
            at each logged step, s, and ``filter_status`` ``(T, N)`` its status
            (``dfcoa_opt.control.base.STATUS_*``), both from ``last_result``.

    Returns:
        ``median`` and ``p95`` solve time (s) over every (step, robot) entry (NaN
        without entries), ``entries`` counted, ``failures`` (entries with status
        ``STATUS_SOLVER_FAIL``) and ``failure_rate`` (failures / entries, NaN
        without entries).
    """
    times = np.asarray(log.filter_time, float).ravel()
    fails = int(np.count_nonzero(np.asarray(log.filter_status) == STATUS_SOLVER_FAIL))
    if times.size == 0:
        return {"median": math.nan, "p95": math.nan, "entries": 0, "failures": fails,
                "failure_rate": math.nan}
    return {"median": float(np.median(times)), "p95": float(np.percentile(times, 95)),
            "entries": int(times.size), "failures": fails,
            "failure_rate": fails / times.size}
