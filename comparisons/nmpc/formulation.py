"""The casadi expressions of one robot's NMPC problem (:mod:`comparisons.nmpc.problem`).

:func:`nlp` builds the variables, parameters, weighted residuals, constraints and
planned poses in the layout described in :mod:`comparisons.nmpc.problem`;
:func:`gauss_newton` the SQP's Gauss-Newton Hessian; :func:`solver_options` the
solver options; :func:`map_multipliers` and :func:`map_lbg` carry multipliers and
bounds from one formulation's layout to the other's.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from comparisons.nmpc.model import arc_step

if TYPE_CHECKING:
    from comparisons.nmpc.spec import ProblemSpec

FloatArray = NDArray[np.float64]


def nlp(spec: ProblemSpec) -> tuple[ca.SX, ca.SX, ca.SX, ca.SX, ca.SX]:
    """Variables, parameters, weighted residuals, constraints and planned poses (3 H)."""
    h, c, nw = spec.horizon, spec.slots, spec.nw
    w = ca.SX.sym("w", nw * h)
    p = ca.SX.sym("p", 5 + h * spec.stage_params)
    x_prev, u_prev = p[0:3], p[3:5]
    res, g, states = [], [], []
    for k in range(h):
        base = nw * k
        u, s = w[base:base + 2], w[base + nw - 1]
        q = p[5 + k * spec.stage_params: 5 + (k + 1) * spec.stage_params]
        ref, psi, u_ref, normals = q[0:2], q[2], q[3:5], q[5:]
        wt = spec.w_terminal if k == h - 1 else spec.w_track
        if spec.formulation == "condensed":
            x = arc_step(x_prev, u, spec.tau)
        else:
            x = w[base + 2:base + 5]
            g.append(x - arc_step(x_prev, u, spec.tau))
        # squared residuals: 2 (1 - cos(th - psi)) = |(cos th - cos psi, sin th - sin psi)|^2
        res += [math.sqrt(wt) * (x[0:2] - ref),
                math.sqrt(0.5 * spec.w_heading) * ca.vertcat(ca.cos(x[2]) - ca.cos(psi),
                                                             ca.sin(x[2]) - ca.sin(psi)),
                math.sqrt(spec.w_effort) * (u - u_ref), math.sqrt(spec.w_rate) * (u - u_prev),
                math.sqrt(spec.w_slack[1]) * s]
        for j in range(c):
            g.append(normals[2 * j] * x[0] + normals[2 * j + 1] * x[1] + s)
        if spec.wheel is not None:
            half_track = 0.5 * spec.wheel[0]
            g.append(ca.vertcat(u[0] + half_track * u[1], u[0] - half_track * u[1]))
        states.append(x)
        x_prev, u_prev = x, u
    return w, p, ca.vertcat(*res), ca.vertcat(*g), ca.vertcat(*states)


def gauss_newton(w: ca.SX, p: ca.SX, r: ca.SX, ng: int) -> ca.Function:
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


def solver_options(spec: ProblemSpec) -> dict:
    """Silent solver options with warm starts.

    The condensed problem's solver leaves out casadi's post-processing (``lam_p`` and
    moving the solution onto its bounds), which the compiled code does not have.
    """
    common = {"print_time": False, "error_on_fail": False}
    if spec.formulation == "condensed":
        common.update(calc_lam_p=False, bound_consistency=False)
    if spec.solver == "ipopt":
        return {**common, "ipopt": {
            "print_level": 0, "sb": "yes", "max_iter": spec.max_iter, "tol": spec.tol,
            "acceptable_tol": math.sqrt(spec.tol), "warm_start_init_point": "yes",
            "warm_start_bound_push": 1e-6, "warm_start_mult_bound_push": 1e-6,
            "mu_init": 1e-3, "print_user_options": "no"}}
    qp_options = {"error_on_fail": False}
    if spec.qp_solver == "qrqp":
        qp_options.update(print_iter=False, print_header=False, print_info=False, max_iter=200)
    if spec.rti:  # real-time iteration: full steps, as Diehl et al. (2005) and acados
        common["max_iter_ls"] = 0
    return {**common, "qpsol": spec.qp_solver, "qpsol_options": qp_options,
            "max_iter": spec.max_iter, "tol_pr": spec.tol, "tol_du": spec.tol,
            "print_header": False, "print_iteration": False, "print_status": False}


def _map_rows(values: FloatArray, src: ProblemSpec, dst: ProblemSpec, fill: FloatArray
              ) -> FloatArray:
    """Constraint rows ``(rows H,)`` of ``src``'s layout in ``dst``'s.

    The dynamics rows of ``dst`` (if any) come from ``fill`` (``(dst.rows H,)``), the
    others are copied.
    """
    h = src.horizon
    out = fill.reshape(h, dst.rows).copy()
    out[:, dst.dyn_rows:] = values.reshape(h, src.rows)[:, src.dyn_rows:]
    return out.ravel()


def map_multipliers(lam_x: FloatArray, lam_g: FloatArray, src: ProblemSpec, dst: ProblemSpec
                    ) -> tuple[FloatArray, FloatArray]:
    """Multipliers of ``src``'s layout in ``dst``'s (those of the states and dynamics: 0).

    The bounds of the controls and slacks and the half-plane and wheel rows are the
    same constraints in both formulations.

    Args:
        lam_x: ``(nw H,)`` bound multipliers in ``src``'s layout.
        lam_g: ``(rows H,)`` constraint multipliers in ``src``'s layout.
        src: The layout of the given multipliers.
        dst: The layout wanted.

    Returns:
        ``(lam_x, lam_g)`` in ``dst``'s layout.
    """
    if src.formulation == dst.formulation:
        return lam_x.copy(), lam_g.copy()
    h = src.horizon
    lx = lam_x.reshape(h, src.nw)
    out_x = np.zeros((h, dst.nw))
    out_x[:, :2], out_x[:, -1] = lx[:, :2], lx[:, -1]
    return out_x.ravel(), _map_rows(lam_g, src, dst, np.zeros(dst.rows * h))


def map_lbg(lbg: FloatArray, src: ProblemSpec, dst: ProblemSpec, template: FloatArray
            ) -> FloatArray:
    """Lower constraint bounds ``(rows H,)`` of ``src``'s layout in ``dst``'s.

    The half-plane offsets (m) and wheel rows are copied; the dynamics rows come from
    ``dst``'s ``template`` (:attr:`NmpcProblem.lbg_template`, zeros).
    """
    return _map_rows(lbg, src, dst, template)
