"""Exact 2D velocity selection over half-planes and a speed disc (the ORCA fast path).

Problem (paper 001 eq 12/16, RVO2's "new velocity")::

    v_new = argmin ||v - v_pref||  s.t.  ||v|| <= v_max,  v on the left of every line k

A line is a point ``p_k`` and a unit direction ``d_k``; its allowed side is the
left one, ``det(d_k, p_k - v) <= 0`` (``det(a, b) = a_x b_y - a_y b_x``). The
first ``n_hard`` lines of a robot (obstacles, or the safe discrete-time mode's
lines) are never relaxed.

Solved exactly by the randomised-incremental 2D LP in the manner of RVO2's
``linearProgram1/2/3`` (the same sequence of operations in double precision):
lines are added in order; when the current optimum violates line ``k`` the new
optimum lies on line ``k`` and is a 1D problem on that line clipped by the disc
and the earlier lines. If the lines are infeasible, the least-violation
fallback (``linearProgram3``) keeps the hard lines and minimises the largest
violation ``max_k det(d_k, p_k - v)`` of the others: for each violated line it
solves an LP over the bisectors of that line with the earlier ones, optimising
in the direction of the line's normal.

Batched over robots in one numba kernel (``prange``); every robot's lines are a
padded row of ``(N, K, 2)`` arrays with a count.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.core.runtime.threads import kernel_threads

#: Parallel-line test of the 1D step (RVO2's ``RVO_EPSILON``), dimensionless.
EPSILON = 1e-5

#: Offset below which two parallel lines count as one line, m/s. RVO2 calls line
#: ``k`` disjoint from a parallel earlier line at any negative offset, which makes
#: a line repeated up to rounding (two polygon edges meeting at a vertex give one
#: next-step line twice, offset ~1e-17) an infeasible program.
COINCIDENT = 1e-9

#: Per-robot outcome codes: :func:`solve_lines` returns the first two; the
#: qpsolvers path (:mod:`comparisons.orca.qp`) can also report a solver failure.
FEASIBLE, LEAST_VIOLATION, SOLVER_FAIL = 0, 1, 2

FloatArray = NDArray[np.float64]


@numba.njit(cache=True, inline="always")
def det(ax, ay, bx, by):  # pragma: no cover - numba
    """``det(a, b) = a_x b_y - a_y b_x``; > 0 when ``b`` is counter-clockwise of ``a``."""
    return ax * by - ay * bx


@numba.njit(cache=True)
def _on_line(P, D, k, radius, ox, oy, direction_opt, out):  # pragma: no cover - numba
    """Optimum on line ``k`` within the disc and lines ``0..k-1``; False if empty."""
    pkx, pky, dkx, dky = P[k, 0], P[k, 1], D[k, 0], D[k, 1]
    dot = pkx * dkx + pky * dky
    disc = dot * dot + radius * radius - (pkx * pkx + pky * pky)
    if disc < 0.0:
        return False  # the speed disc misses line k
    root = math.sqrt(disc)
    t_left = -dot - root
    t_right = -dot + root
    for i in range(k):
        den = det(dkx, dky, D[i, 0], D[i, 1])
        num = det(D[i, 0], D[i, 1], pkx - P[i, 0], pky - P[i, 1])
        if abs(den) <= EPSILON:  # (almost) parallel
            if num < -COINCIDENT:
                return False
            continue
        t = num / den
        if den >= 0.0:
            t_right = min(t_right, t)
        else:
            t_left = max(t_left, t)
        if t_left > t_right:
            return False
    if direction_opt:
        t = t_right if ox * dkx + oy * dky > 0.0 else t_left
    else:
        t = dkx * (ox - pkx) + dky * (oy - pky)
        if t < t_left:
            t = t_left
        elif t > t_right:
            t = t_right
    out[0] = pkx + t * dkx
    out[1] = pky + t * dky
    return True


@numba.njit(cache=True)
def _incremental(P, D, n, radius, ox, oy, direction_opt, out):  # pragma: no cover - numba
    """Add lines ``0..n-1`` in order; returns the first infeasible line or ``n``."""
    if direction_opt:  # (ox, oy) is a unit direction
        out[0] = ox * radius
        out[1] = oy * radius
    elif ox * ox + oy * oy > radius * radius:
        norm = math.sqrt(ox * ox + oy * oy)
        out[0] = ox / norm * radius
        out[1] = oy / norm * radius
    else:
        out[0] = ox
        out[1] = oy
    for i in range(n):
        if det(D[i, 0], D[i, 1], P[i, 0] - out[0], P[i, 1] - out[1]) > 0.0:
            keep_x, keep_y = out[0], out[1]
            if not _on_line(P, D, i, radius, ox, oy, direction_opt, out):
                out[0] = keep_x
                out[1] = keep_y
                return i
    return n


@numba.njit(cache=True)
def _least_violation(P, D, n, n_hard, begin, radius, out, QP, QD):  # pragma: no cover - numba
    """Minimise the largest violation of lines ``n_hard..n-1``, hard lines kept."""
    distance = 0.0
    for i in range(begin, n):
        if det(D[i, 0], D[i, 1], P[i, 0] - out[0], P[i, 1] - out[1]) <= distance:
            continue
        m = 0
        for j in range(n_hard):
            QP[m, 0], QP[m, 1], QD[m, 0], QD[m, 1] = P[j, 0], P[j, 1], D[j, 0], D[j, 1]
            m += 1
        for j in range(n_hard, i):
            det_ij = det(D[i, 0], D[i, 1], D[j, 0], D[j, 1])
            if abs(det_ij) <= EPSILON:
                if D[i, 0] * D[j, 0] + D[i, 1] * D[j, 1] > 0.0:
                    continue  # same direction: line j adds nothing
                px = 0.5 * (P[i, 0] + P[j, 0])
                py = 0.5 * (P[i, 1] + P[j, 1])
            else:
                s = det(D[j, 0], D[j, 1], P[i, 0] - P[j, 0], P[i, 1] - P[j, 1]) / det_ij
                px = P[i, 0] + s * D[i, 0]
                py = P[i, 1] + s * D[i, 1]
            bx = D[j, 0] - D[i, 0]
            by = D[j, 1] - D[i, 1]
            norm = math.sqrt(bx * bx + by * by)
            QP[m, 0], QP[m, 1], QD[m, 0], QD[m, 1] = px, py, bx / norm, by / norm
            m += 1
        keep_x, keep_y = out[0], out[1]
        if _incremental(QP, QD, m, radius, -D[i, 1], D[i, 0], True, out) < m:
            out[0] = keep_x  # only floating-point error can get here: keep the result
            out[1] = keep_y
        distance = det(D[i, 0], D[i, 1], P[i, 0] - out[0], P[i, 1] - out[1])


@numba.njit(cache=True)
def solve_one(P, D, n, n_hard, pref_x, pref_y, v_max, out, QP, QD):  # pragma: no cover - numba
    """One robot: writes the velocity into ``out``; returns (status, largest violation)."""
    fail = _incremental(P, D, n, v_max, pref_x, pref_y, False, out)
    status = FEASIBLE
    if fail < n:
        _least_violation(P, D, n, n_hard, fail, v_max, out, QP, QD)
        status = LEAST_VIOLATION
    worst = 0.0
    for k in range(n):
        worst = max(worst, det(D[k, 0], D[k, 1], P[k, 0] - out[0], P[k, 1] - out[1]))
    return status, worst


@numba.njit(cache=True, parallel=True)
def _solve_batch(P, D, count, hard, pref, v_max, vel, status, slack):  # pragma: no cover - numba
    n_robots, k_max = P.shape[0], P.shape[1]
    for r in numba.prange(n_robots):
        QP = np.empty((k_max, 2))
        QD = np.empty((k_max, 2))
        out = np.empty(2)
        st, worst = solve_one(P[r], D[r], count[r], hard[r], pref[r, 0], pref[r, 1], v_max[r],
                              out, QP, QD)
        vel[r, 0] = out[0]
        vel[r, 1] = out[1]
        status[r] = st
        slack[r] = worst


def solve_lines(points: FloatArray, directions: FloatArray, count: NDArray[np.integer],
                n_hard: NDArray[np.integer], pref: FloatArray, v_max: FloatArray
                ) -> tuple[FloatArray, NDArray[np.int8], FloatArray]:
    """Exact new velocities for a batch of robots.

    Args:
        points: ``(N, K, 2)`` a point of each line, m/s (rows padded past ``count``).
        directions: ``(N, K, 2)`` unit directions; the allowed side is the left.
        count: ``(N,)`` lines used per robot.
        n_hard: ``(N,)`` leading lines that are never relaxed (must be feasible
            together, e.g. contain v = 0).
        pref: ``(N, 2)`` preferred velocities, m/s.
        v_max: ``(N,)`` speed limits, m/s.

    Returns:
        ``(velocity (N, 2), status (N,) FEASIBLE | LEAST_VIOLATION, slack (N,))``;
        ``slack`` is the largest remaining violation ``max_k det(d_k, p_k - v)``
        over all lines (0 when feasible), m/s.
    """
    P = np.ascontiguousarray(points, dtype=np.float64)
    D = np.ascontiguousarray(directions, dtype=np.float64)
    n = P.shape[0]
    vel = np.empty((n, 2))
    status = np.empty(n, np.int8)
    slack = np.empty(n)
    with kernel_threads(n):
        _solve_batch(P, D, np.ascontiguousarray(count, dtype=np.int64),
                     np.ascontiguousarray(n_hard, dtype=np.int64),
                     np.ascontiguousarray(pref, dtype=np.float64),
                     np.ascontiguousarray(np.broadcast_to(v_max, (n,)), dtype=np.float64),
                     vel, status, slack)
    return vel, status, slack

