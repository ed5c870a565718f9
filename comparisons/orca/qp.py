"""The velocity selection of :mod:`comparisons.orca.lp` through ``qpsolvers`` (the slow path).

A second, independent solving path for the problem of :func:`comparisons.orca.lp.solve_lines`
(same arguments, same return convention, same line conventions)::

    v_new = argmin ||v - v_pref||  s.t.  ||v|| <= v_max,  det(d_k, p_k - v) <= 0 for all k

Every robot's problem goes to a general QP solver (``qpsolvers.solve_qp``, OSQP by default,
:mod:`comparisons.constraints.solvers`) instead of the incremental 2D LP, so the two paths share
no solving code and check each other; one robot at a time, for tests and cross-checks.

Lines are rows of ``G v <= h`` (plus the square ``|v_x|, |v_y| <= v_max``). The speed disc
is never given to the solver: a scalar search over the QPs ``v(s) = argmin ||v - s v_pref||``
(:func:`_search`) finds ``||v(s*)|| = v_max``, exact by weak duality. Infeasible lines get
the least-violation velocity (RVO2's ``linearProgram3`` problem; hard lines kept) from a
proximal-point LP (:func:`_lp_prox`) and, if the disc binds, the same search on
``argmin ||v||^2 / 2 + lam t``. Solver failures give :data:`SOLVER_FAIL` with the preferred
velocity unchanged, and one logged warning per call; nothing is raised. The derivations,
the rejected alternatives (tangent cuts) and the tolerances are in
``docs/methods/orca_qp.md``.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from comparisons.constraints.solvers import (  # noqa: F401 - solver_options is public here too
    SolveFailed,
    Solver,
    scaled_tol,
    solver_options,
)
from comparisons.orca.lp import FEASIBLE, LEAST_VIOLATION, SOLVER_FAIL

# The tolerances below are relative to max(1 m/s, v_max): m/s for v_max <= 1 m/s.

#: Tolerance of ``||v|| = v_max`` in the disc search.
DISC_TOL = 1e-10

#: Most QP solves of one disc search before giving up with :data:`SOLVER_FAIL`.
MAX_SEARCH = 100

#: Proximal step of the least-violation LP per m/s of ``v_max`` (dimensionless).
PROX_RHO = 100.0

#: Growth of the proximal step per iteration (long flat descents take few steps).
PROX_GROWTH = 2.0

#: Step below which a proximal-point iterate counts as a fixed point (the least violation
#: is then exact to about PROX_TOL / PROX_RHO).
PROX_TOL = 1e-8

#: Largest violation above the LP's lower bound at which a velocity in the disc is
#: accepted as a least-violation optimum.
LV_TOL = 1e-10

#: Least violation at or below which lines the solver called infeasible count as
#: feasible, i.e. the solver failed.
FEASIBILITY_TOL = 1e-9

FloatArray = NDArray[np.float64]

#: Rows of the square ``|v_x|, |v_y| <= v_max`` (times ``v_max``), added to every problem.
_SQUARE = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])

_LOG = logging.getLogger(__name__)


def _nearest(qp: Solver, G: FloatArray, h: FloatArray, target: FloatArray,
             feasible: bool = True) -> FloatArray | None:
    """``argmin ||v - target||  s.t.  G v <= h``.

    Args:
        qp: The solver.
        G: ``(K, 2)`` line normals ``g_k``.
        h: ``(K,)`` right-hand sides ``g_k . p_k``, m/s.
        target: ``(2,)`` the point to project, m/s.
        feasible: The lines are known to have a common point (retries on failure).

    Returns:
        ``(2,)`` velocity, m/s, or ``None`` if the solver finds no solution.
    """
    return qp(np.eye(2), -np.asarray(target, dtype=np.float64), G, h, feasible)


def _secant(a1: float, v1: FloatArray, a2: float, v2: FloatArray, v_max: float, lo: float,
            hi: float) -> float | None:
    """Where the line through two solutions crosses the circle ``||v|| = v_max``.

    Exact when both solutions lie on the affine piece of the root.

    Args:
        a1: Parameter of the older solution.
        v1: ``(2,)`` older solution, m/s.
        a2: Parameter of the newer solution.
        v2: ``(2,)`` newer solution, m/s.
        v_max: Speed limit, m/s.
        lo: Lower end of the bracket (parameter).
        hi: Upper end of the bracket (parameter).

    Returns:
        The crossing's parameter nearest ``a2`` strictly inside ``(lo, hi)``, or ``None``
        (no crossing there, or ``v1 = v2``).
    """
    if a1 == a2:
        return None
    u = v2 - v1  # per unit of tau, a = a2 + tau (a2 - a1)
    qa = float(u @ u)
    if qa <= 1e-30 * max(1.0, v_max * v_max):
        return None  # v constant on this piece
    qb = 2.0 * float(v2 @ u)
    qc = float(v2 @ v2) - v_max * v_max
    disc = qb * qb - 4.0 * qa * qc
    if disc < 0.0:
        return None
    root = math.sqrt(disc)
    q = -0.5 * (qb + math.copysign(root, qb))
    taus = [q / qa] + ([qc / q] if q != 0.0 else [])
    params = [a2 + tau * (a2 - a1) for tau in taus]
    inside = [a for a in params if lo < a < hi]
    return min(inside, key=lambda a: abs(a - a2)) if inside else None


def _search(evaluate: Callable[[float], FloatArray | None], a_in: float, v_in: FloatArray,
            a_out: float, v_out: FloatArray, v_max: float) -> tuple[FloatArray, float]:
    """Parameter ``a`` between ``a_in`` and ``a_out`` where ``||evaluate(a)|| = v_max``.

    ``evaluate`` must be continuous, piecewise affine and monotone in the norm, with
    ``||v_in|| <= v_max < ||v_out||`` at the bracket ends. Each step takes the circle
    crossing of the line through the last two evaluated points (the bracket ends at
    first), which is exact when both lie on the affine piece of the root; it bisects
    when that line does not cross the circle inside the bracket (e.g. both points on a
    piece where ``v`` is constant) or the bracket has not halved in three steps.

    Args:
        evaluate: Parameter to solution ``(2,)``, m/s (``None`` if the solver finds none).
        a_in: Bracket end whose solution is inside the disc.
        v_in: ``(2,)`` its solution, m/s.
        a_out: Bracket end whose solution is outside the disc.
        v_out: ``(2,)`` its solution, m/s.
        v_max: Speed limit, m/s.

    Returns:
        ``(v, a)``: ``v`` within ``DISC_TOL`` of the circle (m/s) and its parameter.
    """
    prev, last = (a_in, v_in), (a_out, v_out)
    width, stalled = abs(a_out - a_in), 0
    for _ in range(MAX_SEARCH):
        lo, hi = min(a_in, a_out), max(a_in, a_out)
        a = _secant(*prev, *last, v_max, lo, hi)
        if a is None or stalled >= 3:
            a = 0.5 * (a_in + a_out)
        if not lo < a < hi:  # bracket exhausted in floating point
            return v_in, a_in
        v = evaluate(a)
        if v is None:
            raise SolveFailed("no solution inside the bracket of the disc search")
        speed = math.hypot(v[0], v[1])
        if abs(speed - v_max) <= scaled_tol(DISC_TOL, v_max):
            return v, a
        if speed > v_max:
            a_out, v_out = a, v
        else:
            a_in, v_in = a, v
        prev, last = last, (a, v)
        if abs(a_out - a_in) <= 0.5 * width:
            width, stalled = abs(a_out - a_in), 0
        else:
            stalled += 1
    raise SolveFailed(f"disc search did not converge in {MAX_SEARCH} solves")


def _project(qp: Solver, G: FloatArray, h: FloatArray, pref: FloatArray, v_max: float,
             feasible: bool = False) -> tuple[FloatArray | None, bool]:
    """``argmin ||v - pref||`` over ``Pi ∩ disc`` (module docstring).

    Args:
        qp: The solver.
        G: ``(K, 2)`` line normals ``g_k``.
        h: ``(K,)`` right-hand sides ``g_k . p_k``, m/s.
        pref: ``(2,)`` preferred velocity, m/s.
        v_max: Speed limit, m/s.
        feasible: The lines are known to meet the square (retries on failure).

    Returns:
        ``(v, lines_feasible)``: the velocity, m/s, or ``None`` if ``Pi ∩ disc`` is empty;
        ``lines_feasible`` is False when the solver found no point of ``Pi`` at all.
    """
    G, h = np.vstack([G, _SQUARE]), np.concatenate([h, np.full(4, v_max)])
    v1 = _nearest(qp, G, h, pref, feasible)
    if v1 is None:
        return None, False
    if math.hypot(v1[0], v1[1]) <= v_max + scaled_tol(DISC_TOL, v_max):
        return v1, True
    v0 = _nearest(qp, G, h, np.zeros(2))
    if v0 is None:
        raise SolveFailed("no least-norm point of lines found feasible before")
    speed0 = math.hypot(v0[0], v0[1])
    if speed0 > v_max + scaled_tol(DISC_TOL, v_max):
        return None, True  # the lines miss the disc
    if speed0 >= v_max - scaled_tol(DISC_TOL, v_max):
        return v0, True  # the only feasible point
    return _search(lambda s: _nearest(qp, G, h, s * pref), 0.0, v0, 1.0, v1, v_max)[0], True


def _lp_prox(qp: Solver, A: FloatArray, b: FloatArray, v_max: float) -> FloatArray:
    """``min t  s.t.  A (v, t) <= b`` by the proximal-point method, from ``(0, 0, 0)``.

    Each step ``x' = argmin t + ||x - x_k||^2 / (2 rho_k)`` is a strictly convex QP, with
    ``rho_k = PROX_RHO v_max PROX_GROWTH^k`` (capped at ``k = 6``: a larger step leaves
    ``v`` loosely determined by the solver's residual tolerances). A fixed point is
    optimal (``0`` is then in the LP's subdifferential), and on LPs the method terminates
    finitely (Ferris 1991). A step ``d = x' - x_k`` with ``||d|| <= PROX_TOL`` is taken as
    the fixed point: ``x'`` is then optimal for the cost perturbed by ``d / rho_k``, i.e.
    within about ``||d|| / PROX_RHO`` of the least violation.

    Args:
        qp: The solver.
        A: ``(M, 3)`` constraint rows in ``(v, t)``.
        b: ``(M,)`` right-hand sides, m/s.
        v_max: Speed limit (sets the proximal step and the tolerance), m/s.

    Returns:
        ``(3,)`` an optimal ``(v, t)``, m/s.

    Raises:
        SolveFailed: No solution (the polyhedron is empty, or the solver failed), or no
            fixed point within ``MAX_SEARCH`` steps.
    """
    c = np.array([0.0, 0.0, 1.0])
    x = np.zeros(3)
    for k in range(MAX_SEARCH):
        step = PROX_RHO * v_max * PROX_GROWTH ** min(k, 6)
        x_next = qp(np.eye(3) / step, c - x / step, A, b)
        if x_next is None:
            raise SolveFailed("no solution of the least-violation LP (hard lines infeasible "
                              "within the square, or solver failure)")
        if float(np.max(np.abs(x_next - x))) <= scaled_tol(PROX_TOL, v_max):
            return x_next
        x = x_next
    raise SolveFailed(f"least-violation LP: no proximal fixed point in {MAX_SEARCH} steps")


def _least_violation(qp: Solver, G: FloatArray, h: FloatArray, n_hard: int, v_max: float,
                     lines_feasible: bool) -> tuple[FloatArray, float]:
    """A minimiser of the largest soft violation in the disc, hard lines kept.

    Args:
        qp: The solver.
        G: ``(K, 2)`` line normals ``g_k``.
        h: ``(K,)`` right-hand sides ``g_k . p_k``, m/s.
        n_hard: Leading lines that are never relaxed.
        v_max: Speed limit, m/s.
        lines_feasible: The lines have a common point in the square (then ``t_lo = 0``
            without the LP, which would have a whole face of optima).

    Returns:
        ``(v, t_lo)``: the velocity, m/s, and the LP lower bound of the least largest
        violation, m/s.
    """
    soft = (np.arange(len(h)) >= n_hard).astype(np.float64)
    # rows in (v, t): lines (t column -1 for the soft ones), t >= 0, the square
    A = np.vstack([np.column_stack([G, -soft]), [0.0, 0.0, -1.0],
                   np.column_stack([_SQUARE, np.zeros(4)])])
    b = np.concatenate([h, [0.0], np.full(4, v_max)])
    t_lo = 0.0
    if not lines_feasible:
        x = _lp_prox(qp, A, b, v_max)
        t_lo = max(0.0, float(x[2]))
        if math.hypot(x[0], x[1]) <= v_max + scaled_tol(DISC_TOL, v_max):
            return x[:2], t_lo  # optimal over the square, and in the disc
    v_in = np.zeros(2)
    if n_hard:
        v_in = _nearest(qp, np.vstack([G[:n_hard], _SQUARE]),
                        np.concatenate([h[:n_hard], np.full(4, v_max)]), np.zeros(2))
        if v_in is None or math.hypot(v_in[0], v_in[1]) > v_max + scaled_tol(DISC_TOL, v_max):
            raise SolveFailed("the hard lines miss the speed disc")
    P = np.diag([1.0, 1.0, 0.0])

    def v_of(lam: float) -> FloatArray | None:  # argmin |v|^2 / 2 + lam t
        x = qp(P, np.array([0.0, 0.0, lam]), A, b)
        return None if x is None else x[:2]

    lam_in, lam = 0.0, v_max
    for _ in range(MAX_SEARCH):
        v = v_of(lam)
        if v is None:
            raise SolveFailed(f"no solution of the regularised least-violation QP at "
                              f"lambda = {lam:.3g} m/s")
        speed = math.hypot(v[0], v[1])
        if speed > v_max + scaled_tol(DISC_TOL, v_max):
            return _search(v_of, lam_in, v_in, lam, v, v_max)[0], t_lo
        worst = float(np.max(G[n_hard:] @ v - h[n_hard:], initial=0.0))
        on_circle = speed >= v_max - scaled_tol(DISC_TOL, v_max)
        if on_circle or worst <= t_lo + scaled_tol(LV_TOL, v_max):
            return v, t_lo  # on the circle (weak duality), or at the LP's lower bound
        lam_in, v_in, lam = lam, v, 8.0 * lam
    raise SolveFailed(f"least-violation search did not converge in {MAX_SEARCH} solves")


def _violation(points: FloatArray, directions: FloatArray, v: FloatArray) -> float:
    """Largest ``det(d_k, p_k - v)`` over the lines, at least 0, m/s."""
    if len(points) == 0:
        return 0.0
    w = points - v
    return max(0.0, float(np.max(directions[:, 0] * w[:, 1] - directions[:, 1] * w[:, 0])))


def solve_one_qp(points: FloatArray, directions: FloatArray, n_hard: int, pref: FloatArray,
                 v_max: float, solver: str = "osqp") -> tuple[FloatArray, int, float]:
    """One robot through ``qpsolvers``; failures raise (see :func:`solve_lines_qp`).

    Args:
        points: ``(K, 2)`` a point of each line, m/s.
        directions: ``(K, 2)`` unit directions; the allowed side is the left.
        n_hard: Leading lines that are never relaxed.
        pref: ``(2,)`` preferred velocity, m/s.
        v_max: Speed limit, m/s.
        solver: ``qpsolvers`` solver name.

    Returns:
        ``(velocity (2,) m/s, FEASIBLE | LEAST_VIOLATION, slack m/s)``.

    Raises:
        SolveFailed: The solver gave no usable answer where one exists.
        Exception: Whatever the solver raises (e.g. an unknown solver name).
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    directions = np.asarray(directions, dtype=np.float64).reshape(-1, 2)
    pref = np.asarray(pref, dtype=np.float64).reshape(2)
    G = np.column_stack([directions[:, 1], -directions[:, 0]])
    h = np.einsum("ij,ij->i", G, points)
    qp = Solver(solver)
    v, lines_feasible = _project(qp, G, h, pref, v_max)
    if v is None:
        try:
            v_lv, _ = _least_violation(qp, G, h, n_hard, v_max, lines_feasible)
        except SolveFailed as exc:
            if lines_feasible:
                raise
            why = f"the least-violation stage failed too ({exc})"
        else:
            worst = _violation(points, directions, v_lv)
            if lines_feasible or worst > scaled_tol(FEASIBILITY_TOL, v_max):
                return v_lv, LEAST_VIOLATION, worst
            why = f"a point of the disc violates them by {worst:.3g} m/s only"
        # the solver may have called feasible lines infeasible: project with the retries
        v, _ = _project(qp, G, h, pref, v_max, feasible=True)
        if v is None:
            raise SolveFailed(f"{solver} found no solution of the lines, and {why}")
    return v, FEASIBLE, _violation(points, directions, v)


def solve_lines_qp(points: FloatArray, directions: FloatArray, count: NDArray[np.integer],
                   n_hard: NDArray[np.integer], pref: FloatArray, v_max: FloatArray,
                   solver: str = "osqp") -> tuple[FloatArray, NDArray[np.int8], FloatArray]:
    """New velocities for a batch of robots through a QP solver (slow reference path).

    Same problem, arguments and return convention as
    :func:`comparisons.orca.lp.solve_lines`, plus the status :data:`SOLVER_FAIL`.

    Args:
        points: ``(N, K, 2)`` a point of each line, m/s (rows padded past ``count``).
        directions: ``(N, K, 2)`` unit directions; the allowed side is the left.
        count: ``(N,)`` lines used per robot.
        n_hard: ``(N,)`` leading lines that are never relaxed (must be feasible
            together within the disc, e.g. contain v = 0; otherwise SOLVER_FAIL).
        pref: ``(N, 2)`` preferred velocities, m/s.
        v_max: ``(N,)`` (or scalar) speed limits, m/s.
        solver: ``qpsolvers`` solver name (see ``qpsolvers.available_solvers``), with
            the tolerances of :func:`solver_options`. The least-violation search's
            cost matrix ``diag(1, 1, 0)`` is singular, so solvers that need a definite
            one (``quadprog``) give :data:`SOLVER_FAIL` to robots whose least violation
            lies on the circle.

    Returns:
        ``(velocity (N, 2), status (N,) FEASIBLE | LEAST_VIOLATION | SOLVER_FAIL,
        slack (N,))``; ``slack`` is the largest remaining violation
        ``max_k det(d_k, p_k - v)`` over all lines of the returned velocity (0 when
        feasible), m/s. A :data:`SOLVER_FAIL` robot gets its ``pref`` unchanged (not
        clipped to the disc); failures are logged once per call, never raised.
    """
    P = np.asarray(points, dtype=np.float64)
    D = np.asarray(directions, dtype=np.float64)
    n = P.shape[0]
    count = np.broadcast_to(np.asarray(count, dtype=np.int64), (n,))
    hard = np.broadcast_to(np.asarray(n_hard, dtype=np.int64), (n,))
    pref = np.asarray(pref, dtype=np.float64).reshape(n, 2)
    vmax = np.broadcast_to(np.asarray(v_max, dtype=np.float64), (n,))
    vel = np.empty((n, 2))
    status = np.empty(n, np.int8)
    slack = np.empty(n)
    failures: list[tuple[int, Exception]] = []
    for r in range(n):
        k = int(count[r])
        try:
            v, st, worst = solve_one_qp(P[r, :k], D[r, :k], int(hard[r]), pref[r],
                                        float(vmax[r]), solver)
        except Exception as exc:  # reported as SOLVER_FAIL (see the module docstring)
            failures.append((r, exc))
            v, st = pref[r].copy(), SOLVER_FAIL
            worst = _violation(P[r, :k], D[r, :k], v)
        vel[r] = v
        status[r] = st
        slack[r] = worst
    if failures:
        r0, exc0 = failures[0]
        _LOG.warning("solve_lines_qp(solver=%r): %d of %d robots SOLVER_FAIL; first, robot "
                     "%d: %s: %s", solver, len(failures), n, r0, type(exc0).__name__, exc0)
    return vel, status, slack
