"""The coordination layer of one run of ``reshape_passage``: route holds and recoveries.

``reshape``'s central planner (:mod:`~comparisons.reshape.central`) asks it,
at every plan, whether the formation stays on a route and whether the route's
leader cap is off (docs/methods/reshape_passage.md, "The layer"):

- a formation whose leader path is blocked stays on its route until its
  progress passes the last blocked stretch by the formation's extent, so it
  does not switch between the route and a region at every plan;
- a team that is stuck (:class:`~comparisons.reshape.progress.ProgressMonitor`)
  follows a route for ``recover_time``; the route is searched over the whole
  map, so it leaves the pocket that a region cannot;
- a recovering team far behind its slots is not held by the leader cap;
- a held team back within reach of its slots is released to them, where the
  leader's path is free (:meth:`Coordination.released`);
- a recovering team with less way left than its leader heads for its slots
  (:meth:`Coordination.rejoin`).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from comparisons.reshape.progress import STUCK, ProgressMonitor

FloatArray = NDArray[np.float64]


class Coordination:
    """One run's route hold and recovery state (module docstring).

    Args:
        stuck_window: The progress test's window, s.
        recover_time: How long a stuck team follows a route, s.
        far: Distance from the centre of its slots beyond which a recovering
            team is far behind (the planner's ``lookahead``), m.
        extent: The formation's extent beyond its centre, m.
    """

    def __init__(self, stuck_window: float, recover_time: float, far: float,
                 extent: float) -> None:
        self.monitor = ProgressMonitor(stuck_window)
        self.recover_time, self.far, self.extent = recover_time, far, extent
        self._route_until = -math.inf  # on the route up to this progress, m
        self._recover_until = -math.inf  # on a route until then, s
        self._rejoin_until = -math.inf  # to the slots until then, s

    def blocked_to(self, s: float) -> None:
        """The leader's path is blocked for the formation up to arc length ``s`` (m)."""
        self._route_until = max(self._route_until, s + self.extent)

    def watch(self, t: float, s_c: float, positions: FloatArray, moving_near: bool) -> bool:
        """Judge the team at ``t`` (s); whether a recovery starts (the team is stuck).

        Args:
            t: Time, s.
            s_c: The team's progress along the leader's path, m.
            positions: ``(N, 2)`` the robots' positions, m.
            moving_near: Whether a moving disc is sensed.
        """
        if self.monitor.update(t, s_c, positions, moving_near) != STUCK:
            return False
        self._recover_until = t + self.recover_time
        self.monitor.clear()
        return True

    def recovering(self, t: float) -> bool:
        """Whether a recovery (:meth:`watch`) is under way at ``t`` (s)."""
        return t < self._recover_until

    def holding(self, t: float, s_c: float) -> bool:
        """Whether the formation stays on a route at ``t`` (s), at progress ``s_c`` (m)."""
        return s_c < self._route_until or self.recovering(t)

    def released(self, slots: FloatArray, centroid: FloatArray) -> bool:
        """Whether a held team is back at its slots ``(N, 2)`` (m): within ``far`` of them.

        Where the leader's path is free, the planner then lets the scenario's
        formation take over (if it fits) instead of a hold or a recovery: a
        route that keeps the team off its slots while the leader comes near
        would stand the team still beside them.
        """
        return float(np.hypot(*(slots.mean(axis=0) - centroid))) <= self.far

    def uncapped(self, t: float, slots: FloatArray, centroid: FloatArray) -> bool:
        """Whether the route's leader cap is off: a recovering team far behind its slots.

        Far: the centroid more than ``far`` from the centre of ``slots``
        ``(N, 2)`` (m). A team that near could only get ahead of its leader,
        and stand there.
        """
        return self.recovering(t) and not self.released(slots, centroid)

    def rejoin(self, t: float) -> None:
        """The team has less way left than its leader: it goes to its slots for ``recover_time``.

        A recovering team that took another way than its leader's path can reach
        the point where the leader cap (:meth:`uncapped`'s rule: as much way left
        as the leader has) holds it still; standing there until the leader
        catches up is a stall. It heads for its slots instead, each robot on its
        own guided path, for ``recover_time``.
        """
        self._rejoin_until = t + self.recover_time
        self._recover_until = -math.inf

    def rejoining(self, t: float) -> bool:
        """Whether the team goes to its slots at ``t`` (s) (:meth:`rejoin`)."""
        return t < self._rejoin_until
