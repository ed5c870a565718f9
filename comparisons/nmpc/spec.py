"""What one robot's NMPC problem is made of (:mod:`comparisons.nmpc.problem`).

:class:`ProblemSpec` holds everything fixed for a run (shape, weights, limits,
solver) and the sizes of the problem's layout that follow from it; the casadi
expressions (:mod:`comparisons.nmpc.formulation`) and the problem
(:mod:`comparisons.nmpc.problem`) are built from it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

__all__ = ["NW", "Formulation", "ProblemSpec", "SolverName"]

SolverName = Literal["ipopt", "sqp"]
Formulation = Literal["condensed", "multiple-shooting"]

#: Variables per stage of the multiple-shooting formulation: v, omega, x, y, theta, slack.
NW = 6


@dataclass(frozen=True)
class ProblemSpec:
    """Everything fixed for a run: shape, weights, limits, solver.

    Attributes:
        horizon: Stages ``H``.
        tau: Prediction step, s.
        slots: Distance half-planes per stage ``C`` (obstacles + neighbours).
        w_track: Slot tracking weight of stages 1 .. H-1, 1/m^2.
        w_terminal: Slot tracking weight of stage H, 1/m^2.
        w_heading: Weight of ``1 - cos(theta_k - psi_k)`` per stage.
        w_effort: Weight of ``|u_k - u_ref_k|^2`` (v in m/s, omega in rad/s).
        w_rate: Weight of ``|u_k - u_{k-1}|^2``.
        w_slack: ``(L1 1/m, L2 1/m^2)`` weights of the slacks.
        v_min: Smallest forward speed, m/s.
        v_max: Largest forward speed, m/s.
        w_max: Largest turn rate, rad/s.
        wheel: ``(track width m, largest wheel rim speed m/s)``, or None without a limit.
        solver: ``"ipopt"`` or ``"sqp"`` (casadi ``sqpmethod``).
        qp_solver: QP solver of the SQP: ``"qrqp"`` or ``"daqp"``.
        hessian: SQP Hessian: ``"gauss-newton"`` (convex QPs) or ``"exact"`` (not convexified).
        max_iter: Iteration limit of the solver.
        tol: Solver tolerance (primal and dual).
        formulation: ``"condensed"`` (states eliminated) or ``"multiple-shooting"``.
        compiled: Compile the SQP solver to C (:mod:`comparisons.nmpc.compiled`);
            it falls back to the interpreted one without a compiler.
        rti: A real-time iteration (``sqp`` only; give ``max_iter = 1``): full SQP
            steps (no line search), and a solve succeeds when it returns without error
            and with finite values, whatever its KKT measures.
    """

    horizon: int
    tau: float
    slots: int
    w_track: float
    w_terminal: float
    w_heading: float
    w_effort: float
    w_rate: float
    w_slack: tuple[float, float]
    v_min: float
    v_max: float
    w_max: float
    wheel: tuple[float, float] | None
    solver: SolverName
    qp_solver: Literal["qrqp", "daqp"]
    hessian: Literal["gauss-newton", "exact"]
    max_iter: int
    tol: float
    formulation: Formulation = "condensed"
    compiled: bool = False
    rti: bool = False

    @property
    def nw(self) -> int:
        """Variables per stage: 3 condensed (v, omega, slack), 6 with the states."""
        return 3 if self.formulation == "condensed" else NW

    @property
    def dyn_rows(self) -> int:
        """Dynamics rows per stage (before the half-planes): 0 condensed, 3 otherwise."""
        return 0 if self.formulation == "condensed" else 3

    @property
    def rows(self) -> int:
        """Constraint rows per stage."""
        return self.dyn_rows + self.slots + (2 if self.wheel is not None else 0)

    @property
    def stage_params(self) -> int:
        """Parameters per stage: reference (5) and normals (2 C)."""
        return 5 + 2 * self.slots
