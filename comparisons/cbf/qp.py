"""The programs of the ``cbf`` filter (:mod:`comparisons.cbf`): rows, QPs, policies.

Rows are ``n . u >= bound`` (m/s). A robot whose nominal velocity already meets
all its rows and the box keeps it without a solve (it is the QP's optimum).
When every right-hand side allows ``u = 0`` the program is feasible by
construction, and a solve without an answer is a solver failure (after the
backend's retries). Otherwise a program without an answer gets its least
largest violation ``t`` from an LP (HiGHS) and is solved again with every row
relaxed by ``t``: the closest velocity among those of least violation (the
semantics of ORCA's fallback). ``t <= FEASIBLE_TOL`` means the first solve
failed on a feasible program and the answer stands; otherwise the program is
infeasible and the policy applies.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np
from numpy.typing import NDArray

from comparisons.constraints.solvers import Solver
from comparisons.orca import lp
from dfcoa_opt.control.base import (
    STATUS_FALLBACK,
    STATUS_MODIFIED,
    STATUS_OK,
    STATUS_SOLVER_FAIL,
    UNCHANGED_TOL,
)
from dfcoa_opt.core.geometry import take_rows

FloatArray = NDArray[np.float64]

#: A row or box bound met to this is met, m/s.
ROW_TOL = 1e-9
#: Largest slack of the relaxed program that still counts as feasible, m/s.
FEASIBLE_TOL = 1e-6
#: Extra relaxation of the rows beyond the least violation in the second solve, m/s.
LV_TOL = 1e-7


#: ``(velocity (N, 2) m/s, status (N,) int8, slack (N,) m/s)`` of a solve.
Answer = tuple[FloatArray, NDArray[np.int8], FloatArray]


@dataclass(frozen=True)
class BarrierRows:
    """Per-robot rows ``normal . u_i >= bound`` (padded).

    Attributes:
        normal: ``(N, K, 2)`` unit normals.
        bound: ``(N, K)`` right-hand sides, m/s (``-inf`` in unused slots).
        mask: ``(N, K)`` used slots.
        index: ``(N, K)`` the other robot of a pair row (global id), or None for
            obstacle rows.
    """

    normal: FloatArray
    bound: FloatArray
    mask: NDArray[np.bool_]
    index: NDArray[np.intp] | None


def _csr(*args: Any, **kwargs: Any) -> Any:
    """``scipy.sparse.csr_matrix`` (imported here: ~0.08 s, needed only by the QP paths)."""
    import scipy.sparse as sp

    return sp.csr_matrix(*args, **kwargs)


@lru_cache(maxsize=8)
def _solver(name: str) -> Solver:
    return Solver(name)


def _solve(name: str, G: Any, h: FloatArray, u_hat: FloatArray, v_box: float
           ) -> tuple[FloatArray | None, float]:
    """``argmin ||u - u_hat||^2`` s.t. ``G u <= h`` (barrier rows) and the box.

    Returns:
        ``(u, t)``: ``t = 0`` from the program itself; else ``t`` is the least largest
        violation of the rows (an LP, HiGHS) and ``u`` the closest velocity that
        violates no row by more; ``(None, inf)`` when no answer is found.

    Raises:
        Exception: Whatever the solver raises.
    """
    dim = len(u_hat)
    box = np.vstack([np.eye(dim), -np.eye(dim)])
    hb = np.full(2 * dim, v_box)
    G = G.toarray()
    solver = _solver(name)  # converts to sparse itself for sparse backends
    # u = 0 meets every row whose right-hand side is >= 0 (all barriers h >= 0 and no
    # moving disc closing in): then a missing answer is a solver failure, retried
    # with other settings, never an infeasible program
    known = bool(np.all(h >= 0.0))
    x = solver(2.0 * np.eye(dim), -2.0 * u_hat, np.vstack([G, box]), np.concatenate([h, hb]),
               feasible=known)
    if x is not None or known:
        return x, 0.0 if x is not None else np.inf
    from scipy.optimize import linprog  # here: scipy.optimize takes ~0.15 s to import

    lp_res = linprog(np.r_[np.zeros(dim), 1.0], A_ub=np.hstack([G, -np.ones((len(h), 1))]),
                     b_ub=h, bounds=[(-v_box, v_box)] * dim + [(0.0, None)], method="highs")
    if not lp_res.success:
        return None, np.inf
    t = max(0.0, float(lp_res.x[dim]))
    x = solver(2.0 * np.eye(dim), -2.0 * u_hat, np.vstack([G, box]),
               np.concatenate([h + t + LV_TOL, hb]))
    # the relaxed set can be a sliver the QP solver does not finish; the LP's own
    # point has the same least violation (it is just not the closest to u_hat)
    return (x if x is not None else np.clip(lp_res.x[:dim], -v_box, v_box)), t


def _meets(normal: FloatArray, bound: FloatArray, u: FloatArray, v_box: float) -> bool:
    return bool(np.all(normal @ u >= bound - ROW_TOL) and np.all(np.abs(u) <= v_box + ROW_TOL))


def _apply(u: FloatArray | None, t: float, u_hat: FloatArray, policy: str
           ) -> tuple[FloatArray, int, float]:
    """Velocity, status and slack of one program's answer under the policy."""
    if u is None:
        return (u_hat.copy() if policy == "pass_through" else np.zeros_like(u_hat),
                STATUS_SOLVER_FAIL, 0.0)
    if t <= FEASIBLE_TOL:
        changed = np.abs(u - u_hat).max(initial=0.0) > UNCHANGED_TOL
        return u, STATUS_MODIFIED if changed else STATUS_OK, 0.0
    if policy == "stop":
        return np.zeros_like(u_hat), STATUS_FALLBACK, t
    if policy == "pass_through":
        return u_hat.copy(), STATUS_FALLBACK, t
    return u, STATUS_FALLBACK, t


def _guarded(name, G, h, u_hat, v_box):
    try:
        return _solve(name, G, h, u_hat, v_box)
    except Exception:  # noqa: BLE001 - a solver error is a counted outcome, not a crash
        return None, np.inf


def solve_distributed(nominal: FloatArray, pairs: BarrierRows, obstacles: BarrierRows,
                      v_box: float, solver: str, policy: str) -> Answer:
    """One QP per robot: its obstacle rows and half of each pair row.

    Args:
        nominal: ``(N, 2)`` nominal velocities, m/s.
        pairs: Pair rows (whole ``gamma h``).
        obstacles: Obstacle rows.
        v_box: Speed box half-width, m/s.
        solver: qpsolvers backend.
        policy: ``least_violation``, ``stop`` or ``pass_through``.

    Returns:
        ``(velocity (N, 2) m/s, status (N,) int8, slack (N,) m/s)``.
    """
    n = len(nominal)
    vel = np.array(nominal, dtype=float)
    status = np.zeros(n, np.int8)
    slack = np.zeros(n)
    for i in range(n):
        pm, om = pairs.mask[i], obstacles.mask[i]
        normal = np.concatenate([pairs.normal[i, pm], obstacles.normal[i, om]])
        bound = np.concatenate([0.5 * pairs.bound[i, pm], obstacles.bound[i, om]])
        if _meets(normal, bound, vel[i], v_box):
            continue
        u, t = _guarded(solver, _csr(-normal.reshape(-1, 2)), -bound, nominal[i],
                        v_box)
        vel[i], status[i], slack[i] = _apply(u, t, nominal[i], policy)
    return vel, status, slack


def solve_distributed_exact(nominal: FloatArray, pairs: BarrierRows, obstacles: BarrierRows,
                            v_box: float, solver: str, policy: str,
                            static_rows: int = 0) -> Answer:
    """The distributed programs through the exact 2D solver of ORCA (:func:`lp.solve_lines`).

    The box is four hard lines (the speed disc, of radius ``sqrt 2 v_box``, never
    binds); barrier rows are soft lines. Feasible programs get the same optimum as
    the QP; an infeasible one gets the velocity of least largest violation with the
    box kept, as the QP path.

    Under the ``keep_static`` policy the static obstacle rows, with their bounds
    capped at 0 (never nearer to a static obstacle), are hard lines too, as
    RVO2 keeps its obstacle lines: an infeasible program relaxes the pair and
    moving-disc rows (and the static rows' push outwards) but never moves a
    robot towards a wall. ``u = 0`` meets every hard line, so they stay feasible.

    Args:
        nominal: ``(N, 2)`` nominal velocities, m/s.
        pairs: Pair rows (whole ``gamma h``).
        obstacles: Obstacle rows, the static ones first.
        v_box: Speed box half-width, m/s.
        solver: Unused (the exact solver).
        policy: ``least_violation``, ``keep_static``, ``stop`` or ``pass_through``.
        static_rows: The leading obstacle rows that are static obstacles
            (``keep_static`` only).

    Returns:
        ``(velocity (N, 2) m/s, status (N,) int8, slack (N,) m/s)``.
    """
    n = len(nominal)
    box_normal = np.broadcast_to(_BOX_NORMALS, (n, 4, 2))
    box_bound = np.full((n, 4), -v_box)
    box_used = np.ones((n, 4), bool)
    if policy == "keep_static":
        statics = slice(0, static_rows)
        box_normal = np.concatenate([box_normal, obstacles.normal[:, statics]], axis=1)
        box_bound = np.concatenate([box_bound, np.minimum(obstacles.bound[:, statics], 0.0)],
                                   axis=1)
        box_used = np.concatenate([box_used, obstacles.mask[:, statics]], axis=1)
    hard = box_used.sum(axis=1)
    normal = np.concatenate([box_normal, pairs.normal, obstacles.normal], axis=1)
    bound = np.concatenate([box_bound, 0.5 * pairs.bound, obstacles.bound], axis=1)
    used = np.concatenate([box_used, pairs.mask, obstacles.mask], axis=1)
    order = np.argsort(~used, axis=1, kind="stable")  # used rows first, hard ones leading
    normal = take_rows(normal, order)
    bound = take_rows(np.where(used, bound, 0.0), order)
    # n . u >= b  <=>  left of the line through b n with direction (n_y, -n_x)
    points = bound[..., None] * normal
    directions = np.stack([normal[..., 1], -normal[..., 0]], axis=-1)
    vel, st, slack = lp.solve_lines(points, directions, used.sum(axis=1), hard,
                                    nominal, np.full(n, np.sqrt(2.0) * v_box))
    status = np.where(np.abs(vel - nominal).max(axis=1) > UNCHANGED_TOL, STATUS_MODIFIED,
                      STATUS_OK).astype(np.int8)
    bad = st != lp.FEASIBLE
    status[bad] = STATUS_FALLBACK
    if policy == "stop":
        vel[bad] = 0.0
    elif policy == "pass_through":
        vel[bad] = nominal[bad]
    return vel, status, np.where(bad, slack, 0.0)


#: Inward normals of the speed box: u_x <= v, -u_x <= v, u_y <= v, -u_y <= v.
_BOX_NORMALS = np.array([[-1.0, 0.0], [1.0, 0.0], [0.0, -1.0], [0.0, 1.0]])


def solve_centralized(nominal: FloatArray, pairs: BarrierRows, obstacles: BarrierRows,
                      v_box: float, solver: str, policy: str) -> Answer:
    """One QP over all robots' velocities; every pair once, coupling ``u_i`` and ``u_j``.

    Needs the full observation (rows = global ids). Arguments and returns as
    :func:`solve_distributed`; a fallback or failure applies to every robot.
    """
    n = len(nominal)
    rows, cols, vals, rhs = [], [], [], []
    seen: set[tuple[int, int]] = set()
    for i, k in zip(*np.nonzero(pairs.mask), strict=True):
        j = int(pairs.index[i, k])  # type: ignore[index]
        if (min(i, j), max(i, j)) in seen:
            continue
        seen.add((min(i, j), max(i, j)))
        r = len(rhs)
        nx, ny = pairs.normal[i, k]
        rows += [r] * 4
        cols += [2 * i, 2 * i + 1, 2 * j, 2 * j + 1]
        vals += [-nx, -ny, nx, ny]
        rhs.append(-pairs.bound[i, k])
    for i, k in zip(*np.nonzero(obstacles.mask), strict=True):
        r = len(rhs)
        rows += [r, r]
        cols += [2 * i, 2 * i + 1]
        vals += list(-obstacles.normal[i, k])
        rhs.append(-obstacles.bound[i, k])
    G = _csr((vals, (rows, cols)), shape=(len(rhs), 2 * n))
    h = np.asarray(rhs, dtype=float)
    u_hat = np.asarray(nominal, dtype=float).reshape(-1)
    if np.all(G @ u_hat <= h + ROW_TOL) and np.all(np.abs(u_hat) <= v_box + ROW_TOL):
        return np.array(nominal, dtype=float), np.zeros(n, np.int8), np.zeros(n)
    u, t = _guarded(solver, G, h, u_hat, v_box)
    vel, st, sl = _apply(u, t, u_hat, policy)
    vel = vel.reshape(n, 2)
    if st in (STATUS_OK, STATUS_MODIFIED):
        changed = np.abs(vel - nominal).max(axis=1) > UNCHANGED_TOL
        status = np.where(changed, STATUS_MODIFIED, STATUS_OK).astype(np.int8)
    else:
        status = np.full(n, st, np.int8)
    return vel, status, np.full(n, sl)
