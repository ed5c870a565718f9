"""The team's progress along the leader's path: moving, waiting, or stuck.

The coordination layer of ``reshape_passage`` (docs/methods/reshape_passage.md, "Deadlock")
asks, at every plan, whether the team is still getting somewhere. The generic
stall test of the metrics (:mod:`dfcoa_opt.sim.stall`) needs 10 s without
progress and only says "no progress"; a planner must know sooner, and must not
take a queue for a deadlock. Over the last ``window`` seconds:

- **moving**: the team's progress (the arc length along the leader's path of
  the point nearest its centroid) grew by at least ``advance``;
- **waiting**: it did not, but some robot moved at least ``displacement``
  (net), or a moving disc is near the team: a queue filing through a passage,
  or a team letting a walker by;
- **stuck**: neither. Every robot stands still, with nothing moving near it.

Before the history covers one window the team is ``moving``.
"""

from __future__ import annotations

from collections import deque

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

MOVING = "moving"
WAITING = "waiting"
STUCK = "stuck"


class ProgressMonitor:
    """Classifies the team's last ``window`` seconds (module docstring).

    Args:
        window: Length of the history judged, s.
        advance: Least growth of the team's progress that counts as moving, m
            (0.1: half the stall test's ``metrics.deadlock_advance``).
        displacement: Least net displacement of one robot that counts as
            waiting (someone is getting through), m.
    """

    def __init__(self, window: float, advance: float = 0.1, displacement: float = 0.1) -> None:
        self.window, self.advance, self.displacement = window, advance, displacement
        self._history: deque[tuple[float, float, FloatArray]] = deque()

    def clear(self) -> None:
        """Forget the history (after a recovery: judge the new behaviour afresh)."""
        self._history.clear()

    def update(self, t: float, progress: float, positions: FloatArray,
               moving_near: bool = False) -> str:
        """Add the instant ``t`` and classify the window that ends there.

        Args:
            t: Time, s.
            progress: The team's progress along the leader's path, m.
            positions: ``(N, 2)`` the robots' positions, m.
            moving_near: Whether a moving obstacle is near the team now.

        Returns:
            :data:`MOVING`, :data:`WAITING` or :data:`STUCK`.
        """
        self._history.append((t, progress, np.array(positions, dtype=float)))
        while len(self._history) > 1 and self._history[1][0] <= t - self.window + 1e-9:
            self._history.popleft()
        t0, s0, p0 = self._history[0]
        if t - t0 < self.window - 1e-9 or progress - s0 >= self.advance:
            return MOVING
        moved = np.hypot(*(np.asarray(positions, dtype=float) - p0).T)
        if moving_near or bool(np.any(moved >= self.displacement)):
            return WAITING
        return STUCK
