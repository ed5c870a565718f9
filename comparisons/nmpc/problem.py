"""The casadi problem of one robot's NMPC (:mod:`comparisons.nmpc`), built once per run.

Multiple shooting over ``H`` stages of length ``tau`` (s). Decision vector,
stage-major (stage ``k = 0 .. H-1``)::

    w = [v_0, w_0, x_1, y_1, th_1, s_1,  v_1, w_1, x_2, ..., s_H]      (6 H values)

with the controls ``u_k = (v_k, w_k)`` (m/s, rad/s) held over ``[k tau, (k+1) tau)``,
the predicted pose ``x_{k+1}`` (m, m, rad) and one slack ``s_{k+1} >= 0`` (m) shared by
the distance constraints of that stage. Parameter vector::

    p = [x_0 (3), u_prev (2), stage 1 .. H: r_k (2), psi_k (1), u_ref_k (2), n_{k,c} (2 C)]

with the current pose ``x_0``, the last applied twist ``u_prev``, the slot reference
``r_k`` (m), its heading ``psi_k`` (rad), the feed-forward twist ``u_ref_k`` and the
unit normals of the ``C = M + K`` distance half-planes of the stage. Constraint
rows per stage ``k = 1 .. H`` (stage-major too, so a plan shifts by whole blocks)::

    x_k - f(x_{k-1}, u_{k-1}) = 0                      (3 rows, exact unicycle arc)
    n_{k,c} . p_k + s_k >= c_{k,c}                      (C rows; c in lbg, -inf = off)
    |v_{k-1} +- d/2 w_{k-1}| <= r phi_max               (2 rows, only with a wheel limit)
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import casadi as ca
import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
SolverName = Literal["ipopt", "sqp"]

#: Variables per stage: v, omega, x, y, theta, slack.
NW = 6
#: Below this half turn angle (rad) the arc's sinc uses its Taylor series.
_SMALL = 1e-4


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
        solver: ``"ipopt"`` or ``"sqp"`` (casadi ``sqpmethod`` with ``qrqp``).
        qp_solver: QP solver of the SQP: ``"qrqp"`` or ``"daqp"``.
        hessian: SQP Hessian: ``"gauss-newton"`` (convex QPs) or ``"exact"`` (not convexified).
        max_iter: Iteration limit of the solver.
        tol: Solver tolerance (primal and dual).
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

    @property
    def rows(self) -> int:
        """Constraint rows per stage."""
        return 3 + self.slots + (2 if self.wheel is not None else 0)

    @property
    def stage_params(self) -> int:
        """Parameters per stage: reference (5) and normals (2 C)."""
        return 5 + 2 * self.slots


@dataclass
class SolveOutput:
    """One solve's result.

    Attributes:
        w: ``(6 H,)`` decision vector (see the module layout).
        lam_x: Bound multipliers.
        lam_g: Constraint multipliers.
        success: The solver reported success and every value is finite.
        iterations: Solver iterations.
    """

    w: FloatArray
    lam_x: FloatArray
    lam_g: FloatArray
    success: bool
    iterations: int


def _sinc(a: ca.SX) -> ca.SX:
    """``sin(a) / a``, smooth at 0."""
    small = ca.fabs(a) < _SMALL
    return ca.if_else(small, 1.0 - a * a / 6.0, ca.sin(a) / ca.if_else(small, 1.0, a))


def arc_step(x: ca.SX, u: ca.SX, tau: float) -> ca.SX:
    """Exact unicycle motion under constant (v, omega) for ``tau`` s (the simulator's model).

    The chord ``v tau sinc(omega tau / 2)`` points along ``theta + omega tau / 2``
    (:func:`dfcoa_opt.robots.models.integrate_unicycle`, without wrapping the heading).
    """
    half = 0.5 * u[1] * tau
    chord = u[0] * tau * _sinc(half)
    return ca.vertcat(x[0] + chord * ca.cos(x[2] + half), x[1] + chord * ca.sin(x[2] + half),
                      x[2] + 2.0 * half)


def rollout(pose: FloatArray, controls: FloatArray, tau: float) -> FloatArray:
    """Numpy twin of :func:`arc_step` over a horizon, batched over robots.

    Args:
        pose: ``(N, 3)`` start poses (m, m, rad).
        controls: ``(N, H, 2)`` (v m/s, omega rad/s) per stage.
        tau: Stage length, s.

    Returns:
        ``(N, H + 1, 3)`` poses, heading not wrapped.
    """
    n, h = controls.shape[:2]
    out = np.empty((n, h + 1, 3))
    out[:, 0] = pose
    for k in range(h):
        v, w = controls[:, k, 0], controls[:, k, 1]
        half = 0.5 * w * tau
        small = np.abs(half) < _SMALL
        sinc = np.where(small, 1.0 - half * half / 6.0,
                        np.sin(half) / np.where(small, 1.0, half))
        chord = v * tau * sinc
        th = out[:, k, 2]
        out[:, k + 1, 0] = out[:, k, 0] + chord * np.cos(th + half)
        out[:, k + 1, 1] = out[:, k, 1] + chord * np.sin(th + half)
        out[:, k + 1, 2] = th + 2.0 * half
    return out


class NmpcProblem:
    """One robot's NLP as a casadi ``nlpsol`` Function with a parameter vector.

    Args:
        spec: Shape, weights, limits and solver.
        options: Extra casadi solver options merged over the defaults (for experiments).
    """

    def __init__(self, spec: ProblemSpec, options: dict | None = None) -> None:
        self.spec = spec
        h, c = spec.horizon, spec.slots
        w = ca.SX.sym("w", NW * h)
        p = ca.SX.sym("p", 5 + h * spec.stage_params)
        x_prev, u_prev = p[0:3], p[3:5]
        res, g = [], []
        for k in range(h):
            base = NW * k
            u, x, s = w[base:base + 2], w[base + 2:base + 5], w[base + 5]
            q = p[5 + k * spec.stage_params: 5 + (k + 1) * spec.stage_params]
            ref, psi, u_ref, normals = q[0:2], q[2], q[3:5], q[5:]
            wt = spec.w_terminal if k == h - 1 else spec.w_track
            # squared residuals: 2 (1 - cos(th - psi)) = |(cos th - cos psi, sin th - sin psi)|^2
            res += [math.sqrt(wt) * (x[0:2] - ref),
                    math.sqrt(0.5 * spec.w_heading) * ca.vertcat(ca.cos(x[2]) - ca.cos(psi),
                                                                 ca.sin(x[2]) - ca.sin(psi)),
                    math.sqrt(spec.w_effort) * (u - u_ref), math.sqrt(spec.w_rate) * (u - u_prev),
                    math.sqrt(spec.w_slack[1]) * s]
            g.append(x - arc_step(x_prev, u, spec.tau))
            for j in range(c):
                g.append(normals[2 * j] * x[0] + normals[2 * j + 1] * x[1] + s)
            if spec.wheel is not None:
                half_track = 0.5 * spec.wheel[0]
                g.append(ca.vertcat(u[0] + half_track * u[1], u[0] - half_track * u[1]))
            x_prev, u_prev = x, u
        r, gv = ca.vertcat(*res), ca.vertcat(*g)
        slacks = w[NW - 1::NW]
        cost = ca.sumsqr(r) + spec.w_slack[0] * ca.sum1(slacks)
        opts = _options(spec)
        if spec.solver == "sqp" and spec.hessian == "gauss-newton":
            opts["hess_lag"] = _gauss_newton(w, p, r, gv.numel())
        plugin = "ipopt" if spec.solver == "ipopt" else "sqpmethod"
        self.solver = ca.nlpsol("nmpc", plugin, {"x": w, "p": p, "f": cost,
                                                  "g": gv}, {**opts, **(options or {})})
        self.lbx, self.ubx = self._bounds()
        inf = np.inf
        rim = spec.wheel[1] if spec.wheel is not None else inf
        stage_lbg = np.r_[np.zeros(3), np.full(c, -inf), np.full(spec.rows - 3 - c, -rim)]
        stage_ubg = np.r_[np.zeros(3), np.full(c, inf), np.full(spec.rows - 3 - c, rim)]
        self.lbg_template = np.tile(stage_lbg, h)
        self.ubg = np.tile(stage_ubg, h)

    def _bounds(self) -> tuple[FloatArray, FloatArray]:
        s, inf = self.spec, np.inf
        lo = np.tile([s.v_min, -s.w_max, -inf, -inf, -inf, 0.0], s.horizon)
        hi = np.tile([s.v_max, s.w_max, inf, inf, inf, inf], s.horizon)
        return lo, hi

    def solve(self, w0: FloatArray, p: FloatArray, lbg: FloatArray,
              lam_x0: FloatArray | None = None, lam_g0: FloatArray | None = None) -> SolveOutput:
        """Solve once from the initial guess ``w0`` (and multipliers, for IPOPT's warm start).

        Args:
            w0: ``(6 H,)`` initial guess.
            p: Parameter vector (module docstring).
            lbg: Lower constraint bounds (the half-plane offsets ``c``; ``-inf`` = off).
            lam_x0: Initial bound multipliers, or None (zeros).
            lam_g0: Initial constraint multipliers, or None (zeros).

        Returns:
            The solution; exceptions of the solver propagate.
        """
        args = {"x0": w0, "p": p, "lbx": self.lbx, "ubx": self.ubx, "lbg": lbg, "ubg": self.ubg}
        if lam_x0 is not None and lam_g0 is not None:
            args["lam_x0"], args["lam_g0"] = lam_x0, lam_g0
        out = self.solver(**args)
        stats = self.solver.stats()
        w = np.asarray(out["x"], dtype=float).ravel()
        lam_x = np.asarray(out["lam_x"], dtype=float).ravel()
        lam_g = np.asarray(out["lam_g"], dtype=float).ravel()
        ok = bool(stats.get("success", False)) and bool(np.all(np.isfinite(w)))
        return SolveOutput(w, lam_x, lam_g, ok, int(stats.get("iter_count", -1)))


def _gauss_newton(w: ca.SX, p: ca.SX, r: ca.SX, ng: int) -> ca.Function:
    """Gauss-Newton Hessian ``2 lam_f J^T J`` of ``f = |r|^2 + linear`` (convex QPs for SQP).

    The curvature of the dynamics constraints is left out; a ``1e-8`` diagonal keeps
    the QP strictly convex when a weight is 0.
    """
    lam_f = ca.SX.sym("lam_f")
    lam_g = ca.SX.sym("lam_g", ng)
    jac = ca.jacobian(r, w)
    hess = 2.0 * lam_f * ca.mtimes(jac.T, jac) + 1e-8 * ca.SX.eye(w.numel())
    return ca.Function("nlp_hess_l", [w, p, lam_f, lam_g], [hess],
                       ["x", "p", "lam_f", "lam_g"], ["hess_gamma_x_x"])


def _options(spec: ProblemSpec) -> dict:
    """Silent solver options with warm starts."""
    common = {"print_time": False, "error_on_fail": False}
    if spec.solver == "ipopt":
        return {**common, "ipopt": {
            "print_level": 0, "sb": "yes", "max_iter": spec.max_iter, "tol": spec.tol,
            "acceptable_tol": math.sqrt(spec.tol), "warm_start_init_point": "yes",
            "warm_start_bound_push": 1e-6, "warm_start_mult_bound_push": 1e-6,
            "mu_init": 1e-3, "print_user_options": "no"}}
    qp_options = {"error_on_fail": False}
    if spec.qp_solver == "qrqp":
        qp_options.update(print_iter=False, print_header=False, print_info=False, max_iter=200)
    return {**common, "qpsol": spec.qp_solver, "qpsol_options": qp_options,
            "max_iter": spec.max_iter, "tol_pr": spec.tol, "tol_du": spec.tol,
            "print_header": False, "print_iteration": False, "print_status": False}
