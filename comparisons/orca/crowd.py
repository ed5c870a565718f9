"""An ORCA crowd with RVO2's stepping semantics (the oracle-test and benchmark harness).

Every step: each agent takes its ``max_neighbors`` nearest other agents closer
than ``neighbor_dist`` (nearest first,
:func:`comparisons.orca.neighbours.knn_within`), builds one ORCA line per
neighbour, and solves for the velocity closest to its preferred one
(:func:`comparisons.orca.velocities.orca_velocities`); then all agents move
``p += v_new dt`` at once. These are RVO2's ``doStep`` semantics, in double
precision (RVO2 computes in single precision).

With static ``obstacles`` (polygons, counter-clockwise, or two-vertex
segments), each agent's obstacle ORCA lines
(:func:`comparisons.orca.obstacles.obstacle_lines`, horizon
``time_horizon_obst``) come first and are hard, as in RVO2.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from comparisons.orca.lines import agent_lines
from comparisons.orca.lp import solve_one
from comparisons.orca.neighbours import bin_points, buckets, knn_one, knn_within
from comparisons.orca.obstacle_set import ObstacleSet, prepare_obstacles
from comparisons.orca.obstacles import obstacle_lines
from comparisons.orca.velocities import orca_velocities
from dfcoa_opt.core.runtime.threads import kernel_threads

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
        obstacles: Static obstacles: polygons ``(M, 2)`` in m, counter-clockwise
            (or two-vertex segments), or a prepared
            :class:`~comparisons.orca.obstacles.ObstacleSet`; None for none.
        time_horizon_obst: ORCA horizon against obstacles, s.
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
    obstacles: ObstacleSet | Sequence[ArrayLike] | None = None
    time_horizon_obst: float = 10.0

    def __post_init__(self) -> None:
        self.positions = np.array(self.positions, dtype=float).reshape(-1, 2)
        if self.velocities is None:
            self.velocities = np.zeros_like(self.positions)
        if self.obstacles is not None and not isinstance(self.obstacles, ObstacleSet):
            self.obstacles = prepare_obstacles(self.obstacles)

    @property
    def n(self) -> int:
        """Number of agents."""
        return len(self.positions)

    def step(self, pref: ArrayLike) -> None:
        """Advance one step with preferred velocities ``pref`` ``(N, 2)`` m/s.

        Without obstacles the whole step (neighbour search, ORCA lines, exact
        solve, the move) is one compiled call (:func:`_step_kernel`), with the
        numbers of the functions it is made of.
        """
        pos, vel = self.positions, self.velocities
        if not (isinstance(self.obstacles, ObstacleSet) and self.obstacles.n_edges) \
                and self.n >= 2:
            pref = np.ascontiguousarray(pref, dtype=np.float64)
            new_pos, new, self.status = np.empty_like(pos), np.empty_like(pos), \
                np.empty(self.n, np.int8)
            with kernel_threads(self.n):
                _step_kernel(pos, vel, pref, self.max_neighbors, float(self.neighbor_dist),
                             buckets(self.n), float(self.radius), float(self.max_speed),
                             1.0 / self.time_horizon, 1.0 / self.dt, float(self.dt),
                             min(self.n, numba.get_num_threads()), new_pos, new, self.status)
            self.velocities, self.positions = new, new_pos
            return
        idx, count = knn_within(pos, self.max_neighbors, self.neighbor_dist)
        hard: tuple = (None, None, None)
        if isinstance(self.obstacles, ObstacleSet) and self.obstacles.n_edges:
            hard = obstacle_lines(pos, vel, self.radius, self.max_speed, self.time_horizon_obst,
                                  self.obstacles)
        new, self.status, _ = orca_velocities(
            # np.take: the same gather as pos[idx], ~7x faster for (N, K) indices
            pos, vel, np.full(self.n, self.radius), np.take(pos, idx, axis=0),
            np.take(vel, idx, axis=0),
            np.full(idx.shape, self.radius), count, np.asarray(pref, dtype=float),
            np.full(self.n, self.max_speed), self.time_horizon, self.dt, *hard)
        self.velocities = new
        self.positions = pos + new * self.dt


@numba.njit(cache=True, parallel=True)
def _step_kernel(pos, vel, pref, k, neighbor_dist, mask, radius, max_speed, inv_tau, inv_dt, dt,
                 chunks, new_pos, new_vel, status):  # pragma: no cover - numba
    """One crowd step without obstacles: :func:`knn_within`, the ORCA lines, the solve, the move.

    Each robot's row is computed as :func:`~comparisons.orca.neighbours.knn_within`
    and :func:`~comparisons.orca.velocities.orca_velocities` compute it, from the
    same compiled functions (:func:`~comparisons.orca.neighbours.knn_one`,
    :func:`~comparisons.orca.lines.agent_lines`, :func:`~comparisons.orca.lp.solve_one`).
    """
    n = pos.shape[0]
    x0, y0 = pos[0, 0], pos[0, 1]
    for i in range(1, n):
        x0 = min(x0, pos[i, 0])
        y0 = min(y0, pos[i, 1])
    order, start, cxs, cys = bin_points(pos, neighbor_dist, x0, y0, mask)
    idx = np.zeros((n, k), np.int64)
    dist_sq = np.empty((n, k))
    nbr_r = np.full(k, radius)
    for c in numba.prange(chunks):  # one scratch set per chunk: it stays in cache
        nbr_pos, nbr_vel = np.empty((k, 2)), np.empty((k, 2))
        P, D, QP, QD = np.empty((k, 2)), np.empty((k, 2)), np.empty((k, 2)), np.empty((k, 2))
        for r in range(c * n // chunks, (c + 1) * n // chunks):
            m = knn_one(r, pos, k, neighbor_dist, mask, order, start, cxs, cys, idx, dist_sq)
            for j in range(m):
                nbr_pos[j, 0], nbr_pos[j, 1] = pos[idx[r, j], 0], pos[idx[r, j], 1]
                nbr_vel[j, 0], nbr_vel[j, 1] = vel[idx[r, j], 0], vel[idx[r, j], 1]
            lines = agent_lines(pos[r, 0], pos[r, 1], vel[r, 0], vel[r, 1], radius, nbr_pos,
                                nbr_vel, nbr_r, m, inv_tau, inv_dt, P, D, 0)
            st, _worst = solve_one(P, D, lines, 0, pref[r, 0], pref[r, 1], max_speed,
                                   new_vel[r], QP, QD)
            status[r] = st
            new_pos[r, 0] = pos[r, 0] + new_vel[r, 0] * dt
            new_pos[r, 1] = pos[r, 1] + new_vel[r, 1] * dt


def circle_positions(n: int, radius: float) -> FloatArray:
    """RVO2's Circle example: ``n`` agents evenly on a circle, each heading to its antipode."""
    ang = np.arange(n) * (2.0 * np.pi / n)
    return radius * np.column_stack((np.cos(ang), np.sin(ang)))


def goal_velocities(pos: FloatArray, goals: FloatArray) -> FloatArray:
    """RVO2 examples' preferred velocity: towards the goal, unit length when farther than 1 m."""
    vec = goals - pos
    norm = np.linalg.norm(vec, axis=1, keepdims=True)
    return np.where(norm > 1.0, vec / np.where(norm > 0, norm, 1.0), vec)
