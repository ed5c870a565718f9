"""One ORCA velocity update for a batch of robots: lines + exact solve in one kernel.

:func:`orca_velocities` is the fast path shared by the RVO2-compatible crowd
(:mod:`comparisons.orca.crowd`), the safety filter and the navigator. Each
robot's constraint list is its hard lines first (static obstacles, safe-mode
lines; never relaxed), then one ORCA line per neighbour in the order given
(nearest first, like RVO2).
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

from comparisons.orca.lines import agent_lines
from comparisons.orca.lp import solve_one
from dfcoa_opt.core.runtime.threads import kernel_threads

FloatArray = NDArray[np.float64]


@numba.njit(cache=True, parallel=True)
def _kernel(pos, vel, radius, nbr_pos, nbr_vel, nbr_r, n_nbr, pref, v_max, inv_tau, inv_dt,
            hard_P, hard_D, n_hard, P, D, QP, QD, out, status, slack):  # pragma: no cover
    for r in numba.prange(pos.shape[0]):
        h = n_hard[r]
        for k in range(h):
            P[r, k, 0], P[r, k, 1] = hard_P[r, k, 0], hard_P[r, k, 1]
            D[r, k, 0], D[r, k, 1] = hard_D[r, k, 0], hard_D[r, k, 1]
        n = agent_lines(pos[r, 0], pos[r, 1], vel[r, 0], vel[r, 1], radius[r], nbr_pos[r],
                        nbr_vel[r], nbr_r[r], n_nbr[r], inv_tau, inv_dt, P[r], D[r], h)
        st, worst = solve_one(P[r], D[r], n, h, pref[r, 0], pref[r, 1], v_max[r], out[r],
                              QP[r], QD[r])
        status[r] = st
        slack[r] = worst


def orca_velocities(pos: FloatArray, vel: FloatArray, radius: FloatArray, nbr_pos: FloatArray,
                    nbr_vel: FloatArray, nbr_r: FloatArray, n_nbr: NDArray[np.integer],
                    pref: FloatArray, v_max: FloatArray, time_horizon: float, dt: float,
                    hard_points: FloatArray | None = None,
                    hard_directions: FloatArray | None = None,
                    n_hard: NDArray[np.integer] | None = None
                    ) -> tuple[FloatArray, NDArray[np.int8], FloatArray]:
    """New velocities of ``N`` robots by ORCA (exact solver, least violation if infeasible).

    Args:
        pos: ``(N, 2)`` own positions, m.
        vel: ``(N, 2)`` own velocities, m/s.
        radius: ``(N,)`` own radii, m.
        nbr_pos: ``(N, K, 2)`` neighbours' positions, nearest first, m.
        nbr_vel: ``(N, K, 2)`` neighbours' velocities, m/s.
        nbr_r: ``(N, K)`` neighbours' radii, m.
        n_nbr: ``(N,)`` neighbours used per robot.
        pref: ``(N, 2)`` preferred velocities, m/s.
        v_max: ``(N,)`` speed limits, m/s.
        time_horizon: ORCA horizon tau between robots, s.
        dt: Time step, s (horizon of already-overlapping pairs).
        hard_points: ``(N, H, 2)`` points of lines kept hard (obstacles), m/s.
        hard_directions: ``(N, H, 2)`` their unit directions.
        n_hard: ``(N,)`` hard lines used per robot.

    Returns:
        ``(velocity (N, 2), status (N,), slack (N,))`` as in
        :func:`comparisons.orca.lp.solve_lines`.
    """
    n = len(pos)
    k = nbr_pos.shape[1]
    if hard_points is None:
        hard_points = np.zeros((n, 0, 2))
        hard_directions = np.zeros((n, 0, 2))
        n_hard = np.zeros(n, np.int64)
    lines = hard_points.shape[1] + k
    P = np.empty((n, lines, 2))
    D = np.empty((n, lines, 2))
    QP = np.empty((n, lines, 2))
    QD = np.empty((n, lines, 2))
    out = np.empty((n, 2))
    status = np.empty(n, np.int8)
    slack = np.empty(n)
    f64 = np.float64
    with kernel_threads(n):
        _kernel(np.ascontiguousarray(pos, f64), np.ascontiguousarray(vel, f64),
                np.ascontiguousarray(np.broadcast_to(radius, (n,)), f64),
                np.ascontiguousarray(nbr_pos, f64), np.ascontiguousarray(nbr_vel, f64),
                np.ascontiguousarray(np.broadcast_to(nbr_r, (n, k)), f64),
                np.ascontiguousarray(n_nbr, np.int64), np.ascontiguousarray(pref, f64),
                np.ascontiguousarray(np.broadcast_to(v_max, (n,)), f64), 1.0 / time_horizon,
                1.0 / dt, np.ascontiguousarray(hard_points, f64),
                np.ascontiguousarray(hard_directions, f64),
                np.ascontiguousarray(n_hard, np.int64), P, D, QP, QD, out, status, slack)
    return out, status, slack
