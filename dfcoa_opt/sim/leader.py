"""The virtual leader: a unicycle that follows the planned path by pure pursuit.

Its state ``(x, y, theta, v, omega)`` is broadcast to every robot. ``v`` and
``omega`` are the commands it applies during the current step, so followers
know the reference motion of the step they are planning.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.planning.pure_pursuit import PurePursuit
from dfcoa_opt.robots.unicycle_kernel import unicycle_arc
from dfcoa_opt.sim.scenario import Scenario

FloatArray = NDArray[np.float64]


class VirtualLeader:
    """Tracks the path planned when the scenario was loaded.

    Args:
        scenario: The scenario (uses ``spec.leader`` and the grid).
    """

    def __init__(self, scenario: Scenario) -> None:
        spec = scenario.spec.leader
        self.spec = spec
        self.goal = np.asarray(spec.goal, dtype=float)
        start = np.asarray(spec.start, dtype=float)
        self.path = scenario.leader_path
        self.tracker = PurePursuit(self.path, spec.speed, spec.lookahead, spec.w_max)
        self.pose = np.array([start[0], start[1], scenario.leader_heading])
        self.v = 0.0
        self.w = 0.0

    @property
    def at_goal(self) -> bool:
        """Whether the leader is within ``goal_radius`` of the goal."""
        return bool(np.hypot(*(self.pose[:2] - self.goal)) <= self.spec.goal_radius)

    def state(self) -> FloatArray:
        """Broadcast state ``(x, y, theta, v, omega)``; computes this step's command."""
        if self.at_goal:
            self.v, self.w = 0.0, 0.0
        else:
            self.v, self.w, _ = self.tracker.command(self.pose)
        return np.array([*self.pose, self.v, self.w])

    def advance(self, dt: float) -> None:
        """Move for ``dt`` seconds with the command of :meth:`state`."""
        self.pose = unicycle_arc(self.pose, float(self.v), float(self.w), float(dt))
