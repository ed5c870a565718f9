"""The casadi problem of one robot's NMPC (:mod:`comparisons.nmpc`), built once per run.

Two formulations of the same NLP over ``H`` stages of length ``tau`` (s), with the
controls ``u_k = (v_k, w_k)`` (m/s, rad/s) held over ``[k tau, (k+1) tau)``, the
predicted poses ``x_{k+1}`` (m, m, rad) and one slack ``s_{k+1} >= 0`` (m) shared by
the distance constraints of a stage. Decision vector, stage-major (``k = 0 .. H-1``):

* ``"condensed"`` (default): the states are eliminated by the dynamics (``x_{k+1} =
  f(x_k, u_k)`` from the current pose ``x_0``, single shooting)::

      w = [v_0, w_0, s_1,  v_1, w_1, s_2, ...]                 (3 H values)

* ``"multiple-shooting"``: the states are variables, tied by equality rows::

      w = [v_0, w_0, x_1, y_1, th_1, s_1,  v_1, ..., s_H]      (6 H values)

Parameter vector (both)::

    p = [x_0 (3), u_prev (2), stage 1 .. H: r_k (2), psi_k (1), u_ref_k (2), n_{k,c} (2 C)]

with the current pose ``x_0``, the last applied twist ``u_prev``, the slot reference
``r_k`` (m), its heading ``psi_k`` (rad), the feed-forward twist ``u_ref_k`` and the
unit normals of the ``C = M + K`` distance half-planes of the stage. Constraint
rows per stage ``k = 1 .. H`` (stage-major too, so a plan shifts by whole blocks)::

    x_k - f(x_{k-1}, u_{k-1}) = 0                      (3 rows, multiple shooting only)
    n_{k,c} . p_k + s_k >= c_{k,c}                      (C rows; c in lbg, -inf = off)
    |v_{k-1} +- d/2 w_{k-1}| <= r phi_max               (2 rows, only with a wheel limit)

Both have the same minimisers: eliminating an equality by its solution changes the
iterates of the solver, not the problem.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from comparisons.nmpc.compiled import CompiledFunction, compile_function
from comparisons.nmpc.formulation import (
    gauss_newton,
    map_lbg,
    map_multipliers,
    nlp,
    solver_options,
)
from comparisons.nmpc.model import arc_step, rollout
from comparisons.nmpc.outputs import BatchOutput, SolveOutput

if TYPE_CHECKING:
    from comparisons.nmpc.spec import ProblemSpec

__all__ = ["BatchOutput", "NmpcProblem", "SolveOutput", "arc_step", "map_lbg",
           "map_multipliers", "rollout"]

FloatArray = NDArray[np.float64]


class NmpcProblem:
    """One robot's NLP as a casadi ``nlpsol`` behind one packed Function.

    ``function`` maps the packed input ``z = [w0, p, lbg, lam_x0, lam_g0]`` to the
    packed output ``[w, lam_x, lam_g, x_1 .. x_H (3 H), pr_inf, du_inf]``: the
    solution, its multipliers, the planned poses and (``sqp``) the solver's own
    convergence measures at the solution (largest bound or constraint violation,
    largest entry of the Lagrangian's gradient). With ``spec.compiled`` (``sqp``
    only) it runs compiled (:func:`comparisons.nmpc.compiled.compile_function`); a
    solve then succeeds when both measures are below ``tol``, which is the test
    ``sqpmethod`` stops on (``stats()["success"]``, used by the interpreted solver).
    With ``spec.rti`` (one real-time iteration) a solve succeeds when it returns
    without error and with finite values, whatever those measures say.

    Args:
        spec: Shape, weights, limits and solver.
        options: Extra casadi solver options merged over the defaults (for experiments).
    """

    def __init__(self, spec: ProblemSpec, options: dict | None = None) -> None:
        self.spec = spec
        h, c = spec.horizon, spec.slots
        w, p, r, gv, states = nlp(spec)
        cost = ca.sumsqr(r) + spec.w_slack[0] * ca.sum1(w[spec.nw - 1::spec.nw])
        opts = solver_options(spec)
        if spec.solver == "sqp" and spec.hessian == "gauss-newton":
            opts["hess_lag"] = gauss_newton(w, p, r, gv.numel())
        plugin = "ipopt" if spec.solver == "ipopt" else "sqpmethod"
        self.solver = ca.nlpsol("nmpc", plugin, {"x": w, "p": p, "f": cost,
                                                  "g": gv}, {**opts, **(options or {})})
        self.lbx, self.ubx = self._bounds()
        inf, d = np.inf, spec.dyn_rows
        rim = spec.wheel[1] if spec.wheel is not None else inf
        stage_lbg = np.r_[np.zeros(d), np.full(c, -inf), np.full(spec.rows - d - c, -rim)]
        stage_ubg = np.r_[np.zeros(d), np.full(c, inf), np.full(spec.rows - d - c, rim)]
        self.lbg_template = np.tile(stage_lbg, h)
        self.ubg = np.tile(stage_ubg, h)
        self.sizes = (spec.nw * h, p.numel(), spec.rows * h)
        self.states = ca.Function("states", [w, p], [states])
        self.function = self._packed()
        self.compiled: CompiledFunction | None = None
        if spec.compiled and spec.solver == "sqp":
            self.compiled = compile_function(self.function, (spec.qp_solver,)
                                             if spec.qp_solver == "daqp" else ())

    def _bounds(self) -> tuple[FloatArray, FloatArray]:
        s, inf = self.spec, np.inf
        if s.formulation == "condensed":
            return (np.tile([s.v_min, -s.w_max, 0.0], s.horizon),
                    np.tile([s.v_max, s.w_max, inf], s.horizon))
        lo = np.tile([s.v_min, -s.w_max, -inf, -inf, -inf, 0.0], s.horizon)
        hi = np.tile([s.v_max, s.w_max, inf, inf, inf, inf], s.horizon)
        return lo, hi

    def _packed(self) -> ca.Function:
        """The solver behind one dense input and one dense output (class docstring)."""
        nx, n_p, ng = self.sizes
        z = ca.MX.sym("z", 2 * nx + n_p + 2 * ng)
        w0, p, lbg, lam_x0, lam_g0 = ca.vertsplit(
            z, [int(i) for i in np.cumsum([0, nx, n_p, ng, nx, ng])])
        sol = self.solver(x0=w0, p=p, lbx=self.lbx, ubx=self.ubx, lbg=lbg, ubg=self.ubg,
                          lam_x0=lam_x0, lam_g0=lam_g0)
        w, lam_x, lam_g = sol["x"], sol["lam_x"], sol["lam_g"]
        kkt = ca.MX.zeros(2)
        if self.spec.solver == "sqp":  # sqpmethod's own measures (same Function, same numbers)
            _, grad, g, jac = self.solver.get_function("nlp_jac_fg")(w, p)
            viol = ca.vertcat(w - self.ubx, self.lbx - w, g - self.ubg, lbg - g)
            kkt = ca.vertcat(ca.mmax(ca.fmax(viol, 0.0)),
                             ca.norm_inf(grad + ca.mtimes(jac.T, lam_g) + lam_x))
        out = ca.vertcat(w, lam_x, lam_g, self.states(w, p), kkt)
        return ca.Function("nmpc_solve", [z], [out])

    def pack(self, w0: FloatArray, p: FloatArray, lbg: FloatArray,
             lam_x0: FloatArray | None = None, lam_g0: FloatArray | None = None) -> FloatArray:
        """Packed inputs of ``function`` (``(..., n)`` rows; missing multipliers are 0)."""
        lead = np.shape(w0)[:-1]
        nx, _, ng = self.sizes
        lam_x0 = np.zeros((*lead, nx)) if lam_x0 is None else lam_x0
        lam_g0 = np.zeros((*lead, ng)) if lam_g0 is None else lam_g0
        return np.concatenate((w0, p, lbg, lam_x0, lam_g0), axis=-1)

    def guesses(self, u: FloatArray, x: FloatArray) -> FloatArray:
        """Initial guesses ``(N, nw H)`` from controls ``(N, H, 2)`` and poses ``(N, H, 3)``."""
        n, h = u.shape[:2]
        guess = np.zeros((n, h, self.spec.nw))
        guess[..., :2] = u
        if self.spec.formulation != "condensed":
            guess[..., 2:5] = x
        return guess.reshape(n, -1)

    def solve(self, w0: FloatArray, p: FloatArray, lbg: FloatArray,
              lam_x0: FloatArray | None = None, lam_g0: FloatArray | None = None) -> SolveOutput:
        """Solve once from the initial guess ``w0`` (and multipliers, for a warm start).

        Args:
            w0: ``(nw H,)`` initial guess.
            p: Parameter vector (module docstring).
            lbg: Lower constraint bounds (the half-plane offsets ``c``; ``-inf`` = off).
            lam_x0: Initial bound multipliers, or None (zeros).
            lam_g0: Initial constraint multipliers, or None (zeros).

        Returns:
            The solution; exceptions of the solver propagate.
        """
        return self.solve_packed(self.pack(w0, p, lbg, lam_x0, lam_g0))

    def solve_packed(self, z: FloatArray) -> SolveOutput:
        """Solve from packed inputs (:meth:`pack`); exceptions of the solver propagate."""
        if self.compiled is not None:  # an error flag raises
            out, ok, its = self.compiled(z), True, -1
        else:
            out, ok, its = self._interpreted(z)
        return self._unpack(out[None], np.array([ok]), np.array([its]), np.zeros(1)).row(0)

    def solve_rows(self, z: FloatArray) -> BatchOutput:
        """Solve every row of packed inputs ``z`` ``(N, n)``: one compiled call for all.

        Row ``i`` gives the numbers of :meth:`solve_packed` of ``z[i]``. A row whose
        solver raised (interpreted) or returned an error flag (compiled) is a failure
        with NaN values, as is one whose solver did not converge.
        """
        n = len(z)
        if self.compiled is not None:
            out, flags, seconds = self.compiled.batch(z)
            return self._unpack(out, flags == 0, np.full(n, -1), seconds)
        out = np.full((n, self.compiled_size), np.nan)
        ok, iterations, seconds = np.zeros(n, dtype=bool), np.full(n, -1), np.zeros(n)
        for i in range(n):
            t0 = time.perf_counter()
            try:
                out[i], ok[i], iterations[i] = self._interpreted(z[i])
            except RuntimeError:
                pass
            seconds[i] = time.perf_counter() - t0
        return self._unpack(out, ok, iterations, seconds)

    def restart(self, z: FloatArray, w0: FloatArray) -> FloatArray:
        """Packed inputs ``z`` ``(N, n)`` with the initial guesses ``w0`` and zero multipliers."""
        nx, n_p, ng = self.sizes
        out = z.copy()
        out[:, :nx] = w0
        out[:, nx + n_p + ng:] = 0.0
        return out

    @property
    def compiled_size(self) -> int:
        """Length of the packed output (class docstring)."""
        nx, _, ng = self.sizes
        return 2 * nx + ng + 3 * self.spec.horizon + 2

    def _interpreted(self, z: FloatArray) -> tuple[FloatArray, bool, int]:
        """The solver itself on one packed input (its stats are those of this call).

        Returns:
            The packed output (KKT measures NaN), ``stats()["success"]`` (True with
            ``rti``: it returned), iterations.
        """
        nx, n_p, ng = self.sizes
        w0, p, lbg, lam_x0, lam_g0 = np.split(z, np.cumsum([nx, n_p, ng, nx]))
        sol = self.solver(x0=w0, p=p, lbx=self.lbx, ubx=self.ubx, lbg=lbg, ubg=self.ubg,
                          lam_x0=lam_x0, lam_g0=lam_g0)
        stats = self.solver.stats()
        w = np.asarray(sol["x"], dtype=float).ravel()
        out = np.concatenate([w, *(np.asarray(sol[k], dtype=float).ravel()
                                   for k in ("lam_x", "lam_g")),
                              np.asarray(self.states(w, p), dtype=float).ravel(),
                              np.full(2, np.nan)])
        ok = self.spec.rti or bool(stats.get("success", False))
        return out, ok, int(stats.get("iter_count", -1))

    def _unpack(self, out: FloatArray, ok: NDArray[np.bool_], iterations: NDArray[np.intp],
                seconds: FloatArray) -> BatchOutput:
        """Split packed outputs ``(N, compiled_size)``; success as the solver's own test.

        ``ok``: no error and (interpreted) ``stats()["success"]``. Compiled rows
        converge when both KKT measures are below ``tol`` (not tested with ``rti``).
        """
        nx, _, ng = self.sizes
        h = self.spec.horizon
        w = out[:, :nx]
        if self.compiled is not None and not self.spec.rti:
            ok = ok & (out[:, -2] < self.spec.tol) & (out[:, -1] < self.spec.tol)
        return BatchOutput(w, out[:, nx:2 * nx], out[:, 2 * nx:2 * nx + ng],
                           out[:, 2 * nx + ng:2 * nx + ng + 3 * h].reshape(-1, h, 3),
                           ok & np.all(np.isfinite(w), axis=1), iterations, seconds)
