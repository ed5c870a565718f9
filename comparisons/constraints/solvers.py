"""The ``qpsolvers`` plumbing of the ``orca`` (:mod:`comparisons.orca.qp`) and ``cbf`` programs.

Options, retries and one call per program.

Tolerances are passed with every call (no global solver settings are changed);
a solve that returns nothing for a problem known to be feasible is retried with
other settings (:func:`retry_options`) before it counts as a failure.
"""

from __future__ import annotations

import contextlib
import io
import warnings
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.core.errors import ScenarioError, did_you_mean

FloatArray = NDArray[np.float64]


def scaled_tol(relative: float, v_max: float) -> float:
    """A tolerance in m/s: ``relative * max(1 m/s, v_max)``."""
    return relative * max(1.0, v_max)


def check_solver(solver: str, source: str, key: str) -> None:
    """Refuse a ``qpsolvers`` backend that is not installed, before any run.

    Args:
        solver: ``qpsolvers`` solver name from a scenario or sweep file.
        source: File name for the message.
        key: Key path of the setting, e.g. ``controllers.orca.qp_solver``.

    Raises:
        ScenarioError: ``solver`` is not in ``qpsolvers.available_solvers``.
    """
    import qpsolvers  # here: qpsolvers and the solvers it loads take ~0.2 s to import

    known = list(qpsolvers.available_solvers)
    if solver not in known:
        raise ScenarioError(source, key, f"qpsolvers backend {solver!r} is not installed "
                            f"(installed: {', '.join(known)}){did_you_mean(solver, known)}")


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


def pin_osqp_algebra() -> None:
    """Fix OSQP's algebra backend to the one it picks by default, once per process.

    Every ``osqp.OSQP()`` (one per ``qpsolvers`` call) otherwise looks for its
    preferred backends (CUDA, MKL) by importing them, and a failed import is not
    cached: 0.26 ms a call under the profiler, about 5 % of a ``goto_slot+cbf`` run
    with the default ``osqp`` on ``clutter`` (5.3 -> 5.0 s). This sets the module's
    ``OSQP_ALGEBRA_BACKEND`` (the variable that OSQP's environment variable of that
    name fills) to that same default backend, so the answers do not change. Nothing
    is done when the variable is already set or the installed OSQP has no such
    variable.
    """
    try:
        from osqp import interface
    except ImportError:  # pragma: no cover - osqp is a dependency
        return
    if hasattr(interface, "OSQP_ALGEBRA_BACKEND") and interface.OSQP_ALGEBRA_BACKEND is None:
        interface.OSQP_ALGEBRA_BACKEND = interface.default_algebra()


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


class Solver:
    """``qpsolvers.solve_qp`` with a fixed solver name, options and retries.

    Not thread-safe: each call briefly redirects ``sys.stdout`` (OSQP's polishing prints
    even when not verbose).
    """

    def __init__(self, solver: str) -> None:
        import qpsolvers  # here: qpsolvers and the solvers it loads take ~0.2 s to import

        self.name = solver
        self.ladder = [solver_options(solver), *retry_options(solver)]
        self.sparse = solver in qpsolvers.sparse_solvers
        if solver == "osqp":
            pin_osqp_algebra()

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
        import qpsolvers

        if self.sparse:
            import scipy.sparse as sp

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
