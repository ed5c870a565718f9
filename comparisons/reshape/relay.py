"""How ``reshape``'s plans reach its robots: with the virtual leader's broadcast.

The central planner (:mod:`~comparisons.reshape.central`) runs at the virtual
leader, so its plan -- each run's tracking mode, fixed targets, targets carried
in the leader's frame and guidance waypoints -- travels with the leader's
broadcast (``comms.leader_latency``, ``comms.leader_dropout``): the robots of a
run whose broadcast is ``leader_age`` s old follow the plan the planner had at
that broadcast's step, ``round(leader_age / dt)`` steps ago.

A plan holds until the next one, so the plan in force at a past step is the
latest made at or before it. :class:`PlanRelay` keeps, per run, the last
``depth`` plans and the step of each; the controller sizes ``depth`` to cover
:data:`HISTORY` s at its ``replan_period``. A broadcast older than every kept
plan gets the oldest kept.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
#: The kept plans cover at least this much time before the newest one, s.
HISTORY = 10.0


def depth_for(replan_period: float) -> int:
    """Plans a run keeps: at least :data:`HISTORY` s of them, one every ``replan_period`` s."""
    return math.ceil(HISTORY / replan_period) + 1


@dataclass
class Plan:
    """A plan as some rows' robots follow it (one entry per row).

    Attributes:
        mode: ``(R,)`` int8, the tracking mode of each row's run (the
            controller's ``NOMINAL``, ``FIXED`` or ``CARRIED``).
        target: ``(R, 2)`` fixed targets, m (read in ``FIXED`` mode).
        carried: ``(R, 2)`` targets in the leader's frame, m (``CARRIED`` mode).
        guided: ``(R,)`` rows heading for a guidance waypoint instead.
        waypoint: ``(R, 2)`` those waypoints, m.
    """

    mode: NDArray[np.int8]
    target: FloatArray
    carried: FloatArray
    guided: NDArray[np.bool_]
    waypoint: FloatArray


class PlanRelay:
    """The last ``depth`` plans of every run of a batch, and the step each was made at.

    Args:
        runs: Runs of the batch (state by ``env``).
        n: Robots per run.
        depth: Plans kept per run (:func:`depth_for`).
    """

    def __init__(self, runs: int, n: int, depth: int) -> None:
        self.depth = depth
        self.step = np.full((runs, depth), -1, dtype=np.int64)  # -1: nothing kept there
        self.mode = np.zeros((runs, depth, n), dtype=np.int8)
        self.target = np.zeros((runs, depth, n, 2))
        self.carried = np.zeros((runs, depth, n, 2))
        self.guided = np.zeros((runs, depth, n), dtype=bool)
        self.waypoint = np.zeros((runs, depth, n, 2))
        self._newest = np.full(runs, -1, dtype=np.int64)  # ring index of each run's newest plan

    def keep(self, e: int, step: int, plan: Plan) -> None:
        """Keep run ``e``'s plan made at ``step`` (its ``N`` rows, robot order; copied).

        A second plan at the newest plan's step replaces it.
        """
        j = int(self._newest[e])
        if j < 0 or self.step[e, j] != step:
            j = (j + 1) % self.depth
        self._newest[e] = j
        self.step[e, j] = step
        self.mode[e, j] = plan.mode
        self.target[e, j] = plan.target
        self.carried[e, j] = plan.carried
        self.guided[e, j] = plan.guided
        self.waypoint[e, j] = plan.waypoint

    def heard(self, env: NDArray[np.intp], robot: NDArray[np.intp],
              step: NDArray[np.int64]) -> Plan:
        """The plan each row's robot follows: its run's plan in force at ``step``.

        Args:
            env: ``(R,)`` each row's run.
            robot: ``(R,)`` each row's robot within its run.
            step: ``(R,)`` the step of the broadcast each row holds (the same for
                the rows of one run).

        Returns:
            The latest kept plan made at or before ``step`` (the oldest kept when
            every kept plan is newer), gathered row by row.
        """
        kept = self.step[env]  # (R, depth)
        ok = (kept >= 0) & (kept <= step[:, None])
        latest = np.argmax(np.where(ok, kept, -1), axis=1)
        oldest = np.argmin(np.where(kept >= 0, kept, np.iinfo(np.int64).max), axis=1)
        j = np.where(ok.any(axis=1), latest, oldest)
        at = (env, j, robot)
        return Plan(self.mode[at], self.target[at], self.carried[at], self.guided[at],
                    self.waypoint[at])
