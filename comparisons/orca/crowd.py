"""An ORCA crowd with RVO2's stepping semantics (the oracle-test and benchmark harness).

Every step: each agent takes its ``max_neighbors`` nearest other agents closer
than ``neighbor_dist`` (nearest first,
:func:`comparisons.orca.neighbours.knn_within`), builds one ORCA line per
neighbour, and solves for the velocity closest to its preferred one
(:func:`comparisons.orca.velocities.orca_velocities`); then all agents move
``p += v_new dt`` at once. These are RVO2's ``doStep`` semantics, in double
precision (RVO2 computes in single precision).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from comparisons.orca.neighbours import knn_within
from comparisons.orca.velocities import orca_velocities

FloatArray = NDArray[np.float64]


@dataclass
class OrcaCrowd:
    """Agents with RVO2's parameters (``set_agent_defaults`` order).

    Attributes:
        positions: ``(N, 2)`` m.
        dt: Time step, s.
        neighbor_dist: Neighbour search radius, m.
        max_neighbors: Neighbours per agent.
        time_horizon: ORCA horizon between agents, s.
        radius: Agent radius, m.
        max_speed: Speed limit, m/s.
        velocities: ``(N, 2)`` m/s (zero at the start).
        status: Solver status of the last step (``lp.FEASIBLE`` / ``LEAST_VIOLATION``).
    """

    positions: FloatArray
    dt: float = 0.25
    neighbor_dist: float = 15.0
    max_neighbors: int = 10
    time_horizon: float = 10.0
    radius: float = 1.5
    max_speed: float = 2.0
    velocities: FloatArray = field(default=None)  # type: ignore[assignment]
    status: NDArray[np.int8] = field(default=None)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        self.positions = np.array(self.positions, dtype=float).reshape(-1, 2)
        if self.velocities is None:
            self.velocities = np.zeros_like(self.positions)

    @property
    def n(self) -> int:
        """Number of agents."""
        return len(self.positions)

    def step(self, pref: ArrayLike) -> None:
        """Advance one step with preferred velocities ``pref`` ``(N, 2)`` m/s."""
        pos, vel = self.positions, self.velocities
        idx, count = knn_within(pos, self.max_neighbors, self.neighbor_dist)
        new, self.status, _ = orca_velocities(
            pos, vel, np.full(self.n, self.radius), pos[idx], vel[idx],
            np.full(idx.shape, self.radius), count, np.asarray(pref, dtype=float),
            np.full(self.n, self.max_speed), self.time_horizon, self.dt)
        self.velocities = new
        self.positions = pos + new * self.dt


def circle_positions(n: int, radius: float) -> FloatArray:
    """RVO2's Circle example: ``n`` agents evenly on a circle, each heading to its antipode."""
    ang = np.arange(n) * (2.0 * np.pi / n)
    return radius * np.column_stack((np.cos(ang), np.sin(ang)))


def goal_velocities(pos: FloatArray, goals: FloatArray) -> FloatArray:
    """RVO2 examples' preferred velocity: towards the goal, unit length when farther than 1 m."""
    vec = goals - pos
    norm = np.linalg.norm(vec, axis=1, keepdims=True)
    return np.where(norm > 1.0, vec / np.where(norm > 0, norm, 1.0), vec)
