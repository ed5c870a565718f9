"""The outcome of a run: success, collision, deadlock or timeout.

Every run ends in exactly one class, decided in this order:

1. ``collision``: at least one contact of any kind at any logged instant -- two
   robots overlapping, a robot touching a static obstacle or overlapping a
   moving one (``RunLog.robot_contacts``, ``obstacle_contacts``,
   ``dynamic_contacts``). A crashed run is never a success.
   :func:`first_contact_time` says when.
2. ``success``: the goal condition was reached (``reached``: the leader at its
   goal with the formation settled, the simulator's stop condition) with zero
   contacts.
3. ``deadlock``: not reached, no contact, and the run was *stalled* at its end
   (:func:`dfcoa_opt.sim.stall.stalled`): over the last ``metrics.deadlock_window`` seconds the
   formation's centroid advanced less than ``metrics.deadlock_advance`` along
   the leader's path, and every robot that was away from its slot moved less
   than ``metrics.deadlock_displacement``. :func:`deadlock_onset` is the start of
   that final stretch without progress.
4. ``timeout``: everything else -- the run ran out of time while it was still
   progressing (a slow formation, or a robot circling without settling).

The same test (:mod:`dfcoa_opt.sim.stall`) ends a run early when the scenario sets
``stop_on_deadlock``, so a run stopped that way is classified ``deadlock`` by
construction. Definitions and defaults: ``docs/metrics.md`` (outcomes).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.scenario.schema import MetricSpec
from dfcoa_opt.sim.log import RunLog
from dfcoa_opt.sim.stall import formation_progress, stalled

FloatArray = NDArray[np.float64]

#: The outcome classes, in the order of :func:`classify`'s rules.
OUTCOMES = ("success", "collision", "deadlock", "timeout")
#: Settle tolerance (m) assumed for logs that do not record it (``LeaderSpec`` default).
DEFAULT_SETTLE_TOLERANCE = 0.5


def contact_steps(log: RunLog) -> NDArray[np.bool_]:
    """``(T,)`` whether any contact (robot-robot, robot-static, robot-moving) exists at t[k]."""
    return (log.robot_contacts > 0) | (log.obstacle_contacts > 0) | (log.dynamic_contacts > 0)


def first_contact_time(log: RunLog) -> float:
    """Time of the first logged instant with a contact, s (NaN without contact)."""
    hit = np.flatnonzero(contact_steps(log))
    return float(log.t[hit[0]]) if hit.size else math.nan


def leader_path(log: RunLog) -> FloatArray:
    """``(P, 2)`` the leader's planned path (``meta["leader_path"]``), else its logged track, m."""
    path = log.meta.get("leader_path")
    if path is not None and len(path):
        return np.asarray(path, dtype=float).reshape(-1, 2)
    return np.asarray(log.leader[:, :2], dtype=float)


def window_steps(log: RunLog, cfg: MetricSpec) -> int:
    """``metrics.deadlock_window`` in steps of the log (at least 1)."""
    dt = float(log.meta.get("dt") or (log.t[1] - log.t[0] if len(log.t) > 1 else 1.0))
    return max(1, int(round(cfg.deadlock_window / dt)))


def stalled_steps(log: RunLog, cfg: MetricSpec) -> NDArray[np.bool_]:
    """:func:`stalled` for every instant of a log, with the settings of ``cfg``."""
    pos = log.pose[..., :2]
    return stalled(pos, log.slots, formation_progress(pos, leader_path(log)),
                   window_steps(log, cfg),
                   float(log.meta.get("settle_tolerance", DEFAULT_SETTLE_TOLERANCE)),
                   cfg.deadlock_advance, cfg.deadlock_displacement)


def deadlock_onset(log: RunLog, cfg: MetricSpec) -> float:
    """Start of the final stretch without progress, s; NaN when the run's end is not stalled.

    The last instants ``k0 .. T-1`` are all stalled and ``k0 - 1`` is not; the
    stretch without progress began one window before ``k0``.
    """
    st = stalled_steps(log, cfg)
    if not st.size or not st[-1]:
        return math.nan
    live = np.flatnonzero(~st)
    k0 = int(live[-1]) + 1 if live.size else 0
    return float(log.t[max(0, k0 - window_steps(log, cfg))])


def classify(log: RunLog, cfg: MetricSpec | None = None) -> dict[str, Any]:
    """The run's outcome and the facts behind it.

    Args:
        log: The run.
        cfg: Metric settings (the deadlock window and thresholds); default ``MetricSpec()``.

    Returns:
        ``outcome`` (one of :data:`OUTCOMES`), ``reached`` (the goal condition was
        met, whatever the contacts), ``first_contact_time`` (s, NaN without
        contact) and ``deadlock_time`` (s, the onset of the deadlock; NaN unless
        the outcome is ``deadlock``).
    """
    cfg = cfg or MetricSpec()
    reached = bool(log.meta.get("reached_goal", False))
    contact = first_contact_time(log)
    onset = math.nan
    if math.isfinite(contact):
        outcome = "collision"
    elif reached:
        outcome = "success"
    else:
        onset = deadlock_onset(log, cfg)
        outcome = "deadlock" if math.isfinite(onset) else "timeout"
    return {"outcome": outcome, "reached": reached, "first_contact_time": contact,
            "deadlock_time": onset}


def outcome_text(outcome: str, first_contact_time: Any = None, deadlock_time: Any = None,
                 what: str = "") -> str:
    """An outcome in words, for figure titles (the one wording of every figure).

    ``"collision at t = 12.30 s (robot 0 and robot 2)"``,
    ``"deadlock from t = 40.00 s"``, ``"success"``, ``"timeout"``. A collision or
    deadlock without a finite time is its bare name; other strings are returned
    as they are.

    Args:
        outcome: One of :data:`OUTCOMES` (as :func:`classify` gives it).
        first_contact_time: The first contact, s (a collision's time).
        deadlock_time: The deadlock's onset, s.
        what: What touched (e.g. :func:`dfcoa_opt.metrics.contacts.describe`), in brackets
            after a collision's time.
    """
    t = {"collision": first_contact_time, "deadlock": deadlock_time}.get(outcome)
    if not isinstance(t, (int, float)) or not math.isfinite(t):
        return outcome
    word = "at" if outcome == "collision" else "from"
    return f"{outcome} {word} t = {t:.2f} s" + (f" ({what})" if what else "")
