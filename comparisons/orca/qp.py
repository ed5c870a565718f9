"""The velocity selection of :mod:`comparisons.orca.lp` through ``qpsolvers`` (the slow path).

A second, independent solving path for the problem of :func:`comparisons.orca.lp.solve_lines`
(same arguments, same return convention, same line conventions)::

    v_new = argmin ||v - v_pref||  s.t.  ||v|| <= v_max,  det(d_k, p_k - v) <= 0 for all k

Every robot's problem goes to a general QP solver (``qpsolvers.solve_qp``, OSQP by default,
tolerances ``1e-10`` passed with each call) instead of the incremental 2D LP, so the two
paths share no solving code and check each other. One robot at a time, in Python,
typically one to ten solver calls per robot (mean 2.5 for feasible, 4-5 for infeasible
robots): over three orders of magnitude slower than the numba kernel; for tests and
cross-checks, not for the simulation loop.

**Lines** are linear rows: with ``g_k = (d_y, -d_x)``, ``det(d_k, p_k - v) = g_k . v -
g_k . p_k``, so line ``k`` is the row ``g_k . v <= g_k . p_k`` of ``G v <= h``, and its
violation ``det(d_k, p_k - v)`` is in m/s (``d_k`` is a unit vector). Every problem also
gets the square ``|v_x|, |v_y| <= v_max``, which contains the disc and so changes no
answer below, but keeps every sub-problem bounded (without it, lines that meet only far
outside the disc put the least-norm point hundreds of m/s away, where OSQP stalled).
``Pi`` is the polygon of the lines and the square.

**The speed disc** is not linear; it is handled exactly by a scalar root search over a
family of QPs whose solutions are piecewise affine in the parameter (no disc constraint is
ever given to the solver). For ``s`` in ``[0, 1]`` let ``v(s) = argmin_{v in Pi} ||v - s
v_pref||``. Then:

* *Optimality.* If ``||v(1)|| <= v_max``, ``v(1)`` is optimal (optimal over a superset
  and feasible). Otherwise, if ``||v(s*)|| = v_max`` for some ``s* > 0``, put ``mu =
  1/s* - 1 >= 0``; since ``||v - v_pref||^2 + mu ||v||^2 = (1 + mu) ||v - s* v_pref||^2 +
  const``, ``v* = v(s*)`` minimises ``L(v) = ||v - v_pref||^2 + mu (||v||^2 - v_max^2)``
  over ``Pi``. For every ``v`` in ``Pi ∩ disc``, ``||v - v_pref||^2 >= L(v) >= L(v*) =
  ||v* - v_pref||^2`` (weak duality): ``v*`` is the optimum, on the circle. (``s* = 0``:
  ``v(0)`` is the least-norm point of ``Pi``; with norm ``v_max`` it is the only feasible
  point.) That the optimum is on the circle whenever ``v(1)`` is outside is the
  projection-onto-a-convex-set statement: an optimum in the open disc would be a local,
  hence (convexity) global, minimiser over ``Pi``, i.e. the unique projection ``v(1)``.
* *Existence and search.* ``s -> ||v(s)||`` is continuous and non-decreasing (with ``s =
  1/(1 + mu)``, ``||v||^2 - v_max^2`` is the derivative of the concave dual function of
  ``mu``), so ``||v(0)|| <= v_max < ||v(1)||`` brackets the root. ``v(s)`` is piecewise
  affine in ``s`` (parametric QP: finitely many active sets, an affine solution on each),
  so the line through two solutions on the root's piece meets the circle exactly at the
  root (quadratic formula). The search (:func:`_search`) takes that crossing for the
  last two solutions, bisects when there is none in the bracket or the bracket stalls,
  and stops at ``| ||v|| - v_max | <= DISC_TOL``.
* ``||v(0)|| > v_max``: the lines miss the disc; the problem is infeasible.

Kelley-style tangent cuts (re-solve with ``n . v <= v_max`` at ``n = v / ||v||`` until the
solution is in the disc) are also exact at termination, by the superset argument, but
measured here they converge only linearly when ``v_pref`` is just outside the disc or a
line is active near the optimum (in one traced instance the error fell 7-fold per cut),
and the accumulating almost parallel cuts make OSQP degenerate (1e5 ADMM iterations, then
iteration-limit failures).

**Infeasible lines** (the solver returns ``None``, e.g. OSQP's primal-infeasibility
certificate, or ``||v(0)|| > v_max``): the least-violation problem, like RVO2's
``linearProgram3``: keep the first ``n_hard`` lines and minimise the largest soft
violation ``t`` within the disc, an LP in ``(v, t)`` but for the disc::

    min t  s.t.  det(d_k, p_k - v) <= t (soft lines),  <= 0 (hard lines),  t >= 0,
                 ||v|| <= v_max

1. If the lines are infeasible, the LP with the disc relaxed to the square gives ``(v_lo,
   t_lo)`` with ``t_lo <= t*``; if ``||v_lo|| <= v_max`` it is optimal (superset
   argument). It is solved by the proximal-point method (:func:`_lp_prox`: strictly
   convex QPs, finite termination on LPs): OSQP's ADMM on the plain LP (zero cost matrix)
   stalled at its iteration limit on 1 instance in 70. If the lines only miss the disc,
   ``t_lo = 0``.
2. Otherwise the disc is handled as above, with ``v(lam) = argmin ||v||^2 / 2 + lam t``
   over the LP's polyhedron (a QP, piecewise affine in ``lam``, ``||v(lam)||``
   non-decreasing). If ``||v(lam*)|| = v_max``, weak duality with ``mu = 1 / lam*`` gives
   ``t >= t + mu (||v||^2 - v_max^2) / 2 >= t(lam*)`` for every feasible ``(v, t)`` in
   the disc: optimal. ``lam = 0`` gives the least-norm point of the hard lines (in the
   disc by the precondition); ``lam`` grows 8-fold from ``v_max`` until ``||v(lam)|| >
   v_max`` (then :func:`_search` between the last two), or until ``v(lam)`` is in the disc
   with largest violation ``<= t_lo + LV_TOL``: optimal, as ``t_lo`` is a lower bound
   (this is the exact-penalty regime of the regularised LP, reached at a finite ``lam``).

The returned least-violation velocity is unique when the minimax optimum is (a vertex of
three active constraints, or one line's level set touching the circle), the generic case.
Where the minimax set is a segment (e.g. two opposite parallel lines) the solver returns
some point of it and RVO2's LP3 may return another, with the same largest violation.
Rejected: a search over ``t`` with the least-norm point of ``{violations <= t}``; that set
shrinks to a point as ``t -> t*`` and OSQP then reports infeasibility or stalls.

**Tolerances** (``DISC_TOL``, ``PROX_TOL``, ``LV_TOL``, ``FEASIBILITY_TOL``) are relative
to ``max(1 m/s, v_max)``. **Retries**: a sub-problem known to be feasible that gets no
answer is solved again with the :func:`retry_options` (OSQP stops at its iteration limit
on about 1 sub-problem in 1500 at ``1e-10``; other step settings solved each one met).
A first ``None`` that the least-violation stage shows wrong (a point of the disc violating
the lines by ``<= FEASIBILITY_TOL``) is retried the same way.

**Solver failures** (an exception, no answer to a feasible problem after the retries,
hard lines missing the disc, no convergence) are never hidden and never raised: the robot
gets status :data:`SOLVER_FAIL` and its preferred velocity *unchanged* (possibly outside
the disc and violating lines: the caller applies a policy), ``slack`` is the violation at
that velocity, and one warning per call is logged with the number of failed robots and
the first error.
"""

from __future__ import annotations

import contextlib
import io
import logging
import math
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np
import qpsolvers
import scipy.sparse as sp
from numpy.typing import NDArray

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


def _tol(relative: float, v_max: float) -> float:
    """A tolerance in m/s: ``relative * max(1 m/s, v_max)``."""
    return relative * max(1.0, v_max)


class SolveFailed(RuntimeError):
    """The QP solver did not produce a usable answer for a robot."""


def _osqp_polish_key() -> str:
    """OSQP >= 1.0 renamed ``polish`` to ``polishing`` (the old name warns)."""
    try:
        import osqp
    except ImportError:  # pragma: no cover - osqp is a dependency
        return "polishing"
    major = str(getattr(osqp, "__version__", "1")).split(".")[0]
    return "polish" if major.isdigit() and int(major) < 1 else "polishing"


def solver_options(solver: str) -> dict[str, Any]:
    """Tight tolerances for a ``qpsolvers`` backend, passed per call (no global settings).

    Args:
        solver: ``qpsolvers`` solver name, e.g. ``"osqp"``, ``"clarabel"``, ``"quadprog"``.

    Returns:
        Keyword arguments for ``qpsolvers.solve_qp``; empty for solvers without
        tolerances (the active-set ``quadprog``) or not in this table (their defaults).
    """
    if solver == "osqp":
        return {"eps_abs": 1e-10, "eps_rel": 1e-10, _osqp_polish_key(): True,
                "max_iter": 50_000}
    table: dict[str, dict[str, Any]] = {
        "clarabel": {"tol_gap_abs": 1e-10, "tol_gap_rel": 1e-10, "tol_feas": 1e-10},
        "proxqp": {"eps_abs": 1e-10, "eps_rel": 0.0},
        "piqp": {"eps_abs": 1e-10, "eps_rel": 1e-10},
        "cvxopt": {"abstol": 1e-10, "reltol": 1e-10, "feastol": 1e-10},
        "ecos": {"abstol": 1e-10, "reltol": 1e-10, "feastol": 1e-10},
        "daqp": {"primal_tol": 1e-10, "dual_tol": 1e-10},
        "highs": {"primal_feasibility_tolerance": 1e-10, "dual_feasibility_tolerance": 1e-10},
        "scs": {"eps_abs": 1e-10, "eps_rel": 1e-10},
    }
    return dict(table.get(solver, {}))


def retry_options(solver: str) -> list[dict[str, Any]]:
    """Further settings tried, in order, when a problem known to be feasible gets no answer.

    OSQP (ADMM) at ``1e-10`` occasionally stops at its iteration limit: measured on 9000
    random robots, 21 of 32437 sub-problems; without over-relaxation (``alpha = 1``) it
    solved 18 of them, with a fixed step ``rho = 0.1`` the other 3.

    Args:
        solver: ``qpsolvers`` solver name.

    Returns:
        Complete keyword-argument sets for ``qpsolvers.solve_qp`` (empty for solvers
        other than OSQP).
    """
    if solver != "osqp":
        return []
    tight = solver_options(solver)
    return [{**tight, "alpha": 1.0}, {**tight, "adaptive_rho": False, "rho": 0.1}]


class _Solver:
    """``qpsolvers.solve_qp`` with a fixed solver name, options and retries.

    Not thread-safe: each call briefly redirects ``sys.stdout`` (OSQP's polishing prints
    even when not verbose).
    """

    def __init__(self, solver: str) -> None:
        self.name = solver
        self.ladder = [solver_options(solver), *retry_options(solver)]
        self.sparse = solver in qpsolvers.sparse_solvers

    def __call__(self, P: FloatArray, q: FloatArray, G: FloatArray, h: FloatArray,
                 feasible: bool = True) -> FloatArray | None:
        """``argmin 1/2 x'Px + q'x  s.t.  Gx <= h``; ``None`` if the solver finds none.

        The solver's warnings and prints (OSQP warns on every infeasible problem, an
        expected outcome here) are silenced for this call only; exceptions propagate.

        Args:
            P: ``(n, n)`` cost matrix.
            q: ``(n,)`` cost vector.
            G: ``(m, n)`` inequality rows.
            h: ``(m,)`` right-hand sides.
            feasible: The problem is known to have a solution, so a ``None`` is a solver
                failure and the :func:`retry_options` are tried too.

        Returns:
            ``(n,)`` the solution, or ``None``.
        """
        if self.sparse:
            P, G = sp.csc_matrix(P), sp.csc_matrix(G)
        for options in self.ladder if feasible else self.ladder[:1]:
            with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()):
                warnings.simplefilter("ignore")
                x = qpsolvers.solve_qp(P, q, G if len(h) else None, h if len(h) else None,
                                       solver=self.name, **options)
            if x is not None:
                x = np.asarray(x, dtype=np.float64)
                if not np.all(np.isfinite(x)):
                    raise SolveFailed(f"{self.name} returned a non-finite solution {x}")
                return x
        return None


def _nearest(qp: _Solver, G: FloatArray, h: FloatArray, target: FloatArray,
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
        if abs(speed - v_max) <= _tol(DISC_TOL, v_max):
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


def _project(qp: _Solver, G: FloatArray, h: FloatArray, pref: FloatArray, v_max: float,
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
    if math.hypot(v1[0], v1[1]) <= v_max + _tol(DISC_TOL, v_max):
        return v1, True
    v0 = _nearest(qp, G, h, np.zeros(2))
    if v0 is None:
        raise SolveFailed("no least-norm point of lines found feasible before")
    speed0 = math.hypot(v0[0], v0[1])
    if speed0 > v_max + _tol(DISC_TOL, v_max):
        return None, True  # the lines miss the disc
    if speed0 >= v_max - _tol(DISC_TOL, v_max):
        return v0, True  # the only feasible point
    return _search(lambda s: _nearest(qp, G, h, s * pref), 0.0, v0, 1.0, v1, v_max)[0], True


def _lp_prox(qp: _Solver, A: FloatArray, b: FloatArray, v_max: float) -> FloatArray:
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
        if float(np.max(np.abs(x_next - x))) <= _tol(PROX_TOL, v_max):
            return x_next
        x = x_next
    raise SolveFailed(f"least-violation LP: no proximal fixed point in {MAX_SEARCH} steps")


def _least_violation(qp: _Solver, G: FloatArray, h: FloatArray, n_hard: int, v_max: float,
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
        if math.hypot(x[0], x[1]) <= v_max + _tol(DISC_TOL, v_max):
            return x[:2], t_lo  # optimal over the square, and in the disc
    v_in = np.zeros(2)
    if n_hard:
        v_in = _nearest(qp, np.vstack([G[:n_hard], _SQUARE]),
                        np.concatenate([h[:n_hard], np.full(4, v_max)]), np.zeros(2))
        if v_in is None or math.hypot(v_in[0], v_in[1]) > v_max + _tol(DISC_TOL, v_max):
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
        if speed > v_max + _tol(DISC_TOL, v_max):
            return _search(v_of, lam_in, v_in, lam, v, v_max)[0], t_lo
        worst = float(np.max(G[n_hard:] @ v - h[n_hard:], initial=0.0))
        if speed >= v_max - _tol(DISC_TOL, v_max) or worst <= t_lo + _tol(LV_TOL, v_max):
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
    qp = _Solver(solver)
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
            if lines_feasible or worst > _tol(FEASIBILITY_TOL, v_max):
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
