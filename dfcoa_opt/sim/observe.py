"""The observations a :class:`~dfcoa_opt.sim.stepper.Stepper` gives its controller.

A mixin of the stepper: the observation of every active run of a batch, or of
one run alone, from what :meth:`~dfcoa_opt.sim.stepper.Stepper.sense` saw.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from dfcoa_opt.control.base import Neighbours, Observation
from dfcoa_opt.core.errors import DfcoaError


class Observing:
    """Mixin of :class:`~dfcoa_opt.sim.stepper.Stepper`: its observations (see there)."""

    _s: dict[str, Any]
    n: int
    dt: float
    k: Any
    active: Any
    state: Any
    leaders: Any
    leaders_now: Any
    leader_ages: Any
    goal: Any
    comms: Any
    robot_ids: Any
    sim: Any

    def _row_constants(self) -> tuple[Any, ...]:  # the stepper's
        raise NotImplementedError

    def _scan(self, scans: Any, scan_all: Any, j: int) -> Any:  # the stepper's
        raise NotImplementedError

    def batch_observation(self, one_clock: bool = True) -> Observation:
        """The observation of every active run (``env`` = slot; ``leader`` one state a slot).

        Args:
            one_clock: Require the runs to share one clock (a batched controller sees
                one ``t``). With False, runs restarted at different steps give ``t`` NaN.

        Raises:
            DfcoaError: ``one_clock`` and the runs' clocks differ.
        """
        s, n, a = self._s, self.n, len(self.active)
        kk = self.k[self.active]
        same = a == 1 or bool((kk == kk[0]).all())
        if one_clock and not same:
            raise DfcoaError("a batched controller needs the runs of a batch on one clock")
        _, nb_pos, nb_vel, nb_heading, nb_dist, nb_age = s["nb"]
        rows = self._row_constants()
        return Observation(
            float(kk[0] * self.dt) if same else math.nan, self.dt, rows[2], s["est"],
            self.state.velocity, self.state.twist, s["scan_all"],
            Neighbours(s["row_index"], nb_pos, nb_vel, nb_dist, nb_heading, nb_age),
            s["moving"], self.leaders, self.goal, rows[4],
            np.ascontiguousarray(s["heard_slots"]).reshape(a * n, 2), env=rows[3],
            leader_age=self.leader_ages if self.comms is not None else 0.0,
            team=s["team"][0], team_age=s["team"][1], limits=self.sim.limits,
            **self._now(slice(None)))

    def run_observation(self, j: int) -> Observation:
        """The observation of the ``j``-th active run alone (today's single-run Observation)."""
        s, n, e = self._s, self.n, int(self.active[j])
        rows = slice(j * n, (j + 1) * n)
        nb_index, nb_pos, nb_vel, nb_heading, nb_dist, nb_age = s["nb"]
        st = self.state
        nb = Neighbours(nb_index[rows], nb_pos[rows], nb_vel[rows], nb_dist[rows],
                        nb_heading[rows], None if nb_age is None else nb_age[rows])
        return Observation(float(self.k[e] * self.dt), self.dt, self.robot_ids, s["est"][rows],
                           st.velocity[rows], st.twist[rows],
                           self._scan(s["scans"], s["scan_all"], j), nb,
                           s["moving"].take(rows), s["heard"][j], self.goal,
                           self.sim.scenarios[e].offsets, s["heard_slots"][j],
                           leader_age=float(self.leader_ages[e]),
                           team=None if s["team"][0] is None else s["team"][0][rows],
                           team_age=None if s["team"][1] is None else s["team"][1][rows],
                           limits=self.sim.limits, **self._now(j))

    def _now(self, j: int | slice) -> dict[str, Any]:
        """``leader_now`` and ``slot_now`` of the ``j``-th active run (a slice: all), or none."""
        if self.comms is None or not self.comms.leader_on:
            return {}
        s, n = self._s, self.n
        if isinstance(j, slice):  # the batch's: leaders by slot, slots by row
            return {"leader_now": self.leaders_now,
                    "slot_now": np.ascontiguousarray(s["slots"]).reshape(-1, 2)}
        return {"leader_now": s["lead"][j], "slot_now": s["slots"][j].reshape(n, 2)}

