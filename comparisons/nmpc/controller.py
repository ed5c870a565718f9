"""Distributed nonlinear MPC formation controller: ``nmpc`` (not from the papers).

Every robot solves its own small NLP each step (casadi, built once per run in
:meth:`Nmpc.reset`, :mod:`comparisons.nmpc.problem`) and applies the first
control ``(v, omega)`` (``command = "unicycle"``):

* **Model.** The unicycle over ``H`` stages of ``tau`` s (default the scenario's
  ``dt``), integrated exactly along the arc like the simulator's model; bounds
  ``v_min <= v <= v_max``, ``|omega| <= w_max`` from ``[robots]`` (and the wheel
  limit when it is finite).
* **Cost.** Slot tracking (``w_track``, ``w_terminal`` at the last stage), the
  heading of the slot's path (``w_heading``), the deviation from the slot's
  feed-forward twist (``w_effort``) and the control rate (``w_rate``). The slot is
  predicted from the broadcast leader state moving at constant (v, omega)
  (:func:`comparisons.nmpc.geometry.slot_reference`).
* **Constraints.** At each stage, half-planes ``n . (p_k - q) >= D`` from the
  shared builders of :mod:`comparisons.constraints.distance`, linearised at the
  position the previous (shifted) plan predicts for that stage: the ``M``
  nearest static shapes and moving discs (constant velocity), ``D = radius +
  margin``, and the ``K`` nearest neighbours along their plans of the previous
  step, ``D = 2 radius + margin``. One slack per stage, with an exact L1 penalty.
* **Distributed.** The controller keeps every robot's last plan by global id;
  robot ``i`` reads only the plans of its neighbours in ``obs.neighbours`` (plans
  written at time ``t`` are visible from the next step on).
* **Solver.** ``"sqp"`` (default: casadi ``sqpmethod`` + ``daqp`` with a
  Gauss-Newton Hessian, at most 20 iterations, on the condensed problem (the states
  eliminated by the dynamics), compiled to C once per machine; re-solved by IPOPT on
  the multiple-shooting problem when it fails) or ``"ipopt"``; warm-started from the
  shifted previous solution and multipliers. A failed solve (no success, an
  exception, a non-finite value) applies ``on_failure`` and is logged with status
  ``STATUS_SOLVER_FAIL``; ``last_result.solve_time`` is the solver time per robot, s.

Formulation, measurements and limits: ``docs/methods/nmpc.md``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from functools import lru_cache
from typing import TYPE_CHECKING, Literal

import numpy as np
from numpy.typing import NDArray

from comparisons.constraints.distance import StaticObstacles
from comparisons.nmpc.fallback import goto_command, solve_time_stats
from comparisons.nmpc.geometry import (
    neighbour_predictions,
    obstacle_halfplanes,
    robot_halfplanes,
    slot_reference,
)
from comparisons.nmpc.problem import (
    NmpcProblem,
    ProblemSpec,
    SolveOutput,
    map_lbg,
    map_multipliers,
    rollout,
)
from dfcoa_opt.control.base import FilterResult, Observation
from dfcoa_opt.control.registry import register
from dfcoa_opt.geometry import take_rows
from dfcoa_opt.params import param
from dfcoa_opt.sim.log import STATUS_OK, STATUS_SOLVER_FAIL

if TYPE_CHECKING:
    from dfcoa_opt.sim.scenario import Scenario

FloatArray = NDArray[np.float64]
__all__ = ["SQP_MAX_ITER", "IPOPT_MAX_ITER", "Nmpc", "goto_command", "solve_time_stats"]


@lru_cache(maxsize=8)
def _problem(spec: ProblemSpec) -> NmpcProblem:
    """The casadi problem of a spec (casadi Functions are stateless: shared by runs)."""
    return NmpcProblem(spec)


#: Default iteration limits: SQP (Gauss-Newton converges linearly on hard problems, so a
#: failure is cut short and rescued) and IPOPT (also the rescue's limit).
SQP_MAX_ITER, IPOPT_MAX_ITER = 20, 100


@register("nmpc")
class Nmpc:
    """Distributed NMPC tracking the formation slot (module docstring).

    Attributes:
        last_result: The latest step's commands, status (``STATUS_OK`` or
            ``STATUS_SOLVER_FAIL``), largest slack (m) and solve time per robot (s).
        last_iterations: ``(N,)`` iterations of the latest SQP solves, not of the IPOPT
            rescues (-1 when unknown: compiled solver, or an exception).
        last_rescued: ``(N,)`` which robots' SQP failed and IPOPT then succeeded.
    """

    command = "unicycle"
    uses_scan = False  # obstacles from the map's exact shapes and obs.obstacles

    @dataclass(frozen=True)
    class Params:
        """Parameters of ``nmpc``."""

        horizon: int = param(10, doc="Prediction horizon H (stages).", ge=2, le=100)
        step: float | None = param(None, doc="Prediction step tau; default the scenario's dt.",
                                   unit="s", gt=0.0)
        w_track: float = param(1.0, doc="Slot tracking weight of stages 1..H-1.",
                               unit="1/m^2", ge=0.0)
        w_terminal: float = param(10.0, doc="Slot tracking weight of the last stage.",
                                  unit="1/m^2", ge=0.0)
        w_heading: float = param(0.1, doc="Weight of 1 - cos(heading error to the slot's "
                                          "path).", ge=0.0)
        w_effort: float = param(0.1, doc="Weight of the squared deviation of (v, omega) from "
                                         "the slot's feed-forward twist.",
                                unit="s^2/m^2, s^2/rad^2", ge=0.0)
        w_rate: float = param(0.1, doc="Weight of the squared change of (v, omega) between "
                                       "stages.", unit="s^2/m^2, s^2/rad^2", ge=0.0)
        slack_weight: float = param(1000.0, doc="L1 (and L2, per m^2) penalty on the slack of "
                                                "the distance constraints.", unit="1/m", gt=0.0)
        margin: float = param(0.1, doc="Extra distance kept from obstacles (beyond the robot "
                                       "radius) and between robots (beyond 2 radii).",
                              unit="m", ge=0.0)
        max_neighbours: int = param(4, doc="Neighbour constraints per stage K (nearest first).",
                                    ge=0, le=50)
        max_obstacles: int = param(4, doc="Obstacle constraints per stage M (nearest first).",
                                   ge=0, le=50)
        reach: float = param(1.5, doc="Obstacles and neighbours farther than this from the "
                                      "linearisation point are left out.", unit="m", gt=0.0)
        solver: Literal["sqp", "ipopt"] = param(
            "sqp", doc="'sqp' (casadi sqpmethod, faster) or 'ipopt' (interior point).")
        qp_solver: Literal["daqp", "qrqp"] = param(
            "daqp", doc="QP solver of the 'sqp' solver (casadi conic plugin).")
        sqp_hessian: Literal["gauss-newton", "exact"] = param(
            "gauss-newton", doc="Hessian of the 'sqp' solver: Gauss-Newton of the squared "
                                "residuals (convex QPs) or the exact, unconvexified one.")
        formulation: Literal["condensed", "multiple-shooting"] = param(
            "condensed", doc="'condensed' (the states eliminated by the dynamics: 3 H "
                             "variables) or 'multiple-shooting' (6 H); same minimisers.")
        compiled: bool = param(True, doc="Compile the 'sqp' solver to C once per machine "
                                         "(cached; falls back to casadi's interpreter, with "
                                         "the same results, without a C compiler).")
        rescue: bool = param(True, doc="When an 'sqp' solve fails, solve again with IPOPT "
                                       "before applying on_failure.")
        max_iter: int | None = param(None, doc="Iteration limit of the solver (hitting it is "
                                               "a failure); default 20 for 'sqp', 100 for "
                                               "'ipopt' and an IPOPT rescue.", ge=1, le=10_000)
        tol: float = param(1e-4, doc="Solver tolerance (primal and dual).", gt=0.0, lt=1.0)
        on_failure: Literal["shift", "stop", "goto"] = param(
            "shift", doc="After a failed solve: 'shift' applies the previous plan's next "
                         "control (stop without one), 'stop' applies zero, 'goto' a "
                         "proportional slot-tracking command.")
        goto_gain: float = param(1.0, doc="Gain of the 'goto' fallback (v = k e_forward, "
                                          "omega = 2 k heading error).", unit="1/s", gt=0.0)

    def __init__(self, params: Params) -> None:
        self.p = params
        self.last_result: FilterResult | None = None
        self.last_iterations: NDArray[np.intp] = np.zeros(0, dtype=np.intp)
        self.last_rescued: NDArray[np.bool_] = np.zeros(0, dtype=bool)
        self.problem: NmpcProblem | None = None
        self.rescuer: NmpcProblem | None = None

    # ------------------------------------------------------------------ set-up
    def reset(self, scenario: Scenario, rng: np.random.Generator) -> None:
        """Build the casadi solver(s) (once per parameter set) and clear every plan."""
        p, rob = self.p, scenario.spec.robots
        self.tau = p.step if p.step is not None else scenario.spec.dt
        wheel = None
        if math.isfinite(rob.wheel_speed_max):
            wheel = (rob.track_width, rob.wheel_radius * rob.wheel_speed_max)
        self.spec = ProblemSpec(
            horizon=p.horizon, tau=self.tau, slots=p.max_obstacles + p.max_neighbours,
            w_track=p.w_track, w_terminal=p.w_terminal, w_heading=p.w_heading,
            w_effort=p.w_effort, w_rate=p.w_rate, w_slack=(p.slack_weight, p.slack_weight),
            v_min=rob.v_lower, v_max=rob.v_max, w_max=rob.w_max, wheel=wheel,
            solver=p.solver, qp_solver=p.qp_solver, hessian=p.sqp_hessian,
            max_iter=p.max_iter or (SQP_MAX_ITER if p.solver == "sqp" else IPOPT_MAX_ITER),
            tol=p.tol, formulation=p.formulation, compiled=p.compiled)
        self.problem = _problem(self.spec)
        self.rescuer = None
        if p.rescue and p.solver == "sqp":  # multiple shooting: IPOPT is faster on it
            self.rescuer = _problem(replace(self.spec, solver="ipopt", hessian="exact",
                                            qp_solver="qrqp", max_iter=IPOPT_MAX_ITER,
                                            formulation="multiple-shooting", compiled=False))
        self.radius = rob.radius
        self.static = StaticObstacles.from_shapes(scenario.world.shapes)
        self._t: float | None = None
        self._alloc(scenario.spec.team.n)
        self.last_result = None

    def _alloc(self, n: int) -> None:
        """Plan buffers for ``n`` robots (by global id): written (``_w``) and read (``_r``)."""
        h, rows = self.p.horizon, self.spec.rows
        self._w = {"t": np.full(n, np.nan), "u": np.zeros((n, h, 2)),
                   "x": np.zeros((n, h + 1, 3)), "lam_x": np.zeros((n, self.spec.nw * h)),
                   "lam_g": np.zeros((n, rows * h)), "lam_ok": np.zeros(n, dtype=bool)}
        self._r = {k: v.copy() for k, v in self._w.items()}

    def _grow(self, n: int) -> None:
        """Make room for global ids below ``n`` (hand-made observations)."""
        have = len(self._w["t"])
        if n <= have:
            return
        for buf in (self._w, self._r):
            for k, v in buf.items():
                fill = np.nan if k == "t" else 0
                buf[k] = np.concatenate((v, np.full((n - have, *v.shape[1:]), fill, v.dtype)))

    # ------------------------------------------------------------------ plans
    def _age(self, t: float, ids: NDArray[np.intp]) -> FloatArray:
        """Age of the readable plans of ``ids`` at ``t``, in stages (``inf`` = none)."""
        age = (t - self._r["t"][ids]) / self.tau
        return np.where(np.isfinite(age) & (age >= -1e-9), np.maximum(age, 0.0), np.inf)

    def _shifted(self, t: float, ids: NDArray[np.intp]) -> tuple[FloatArray, FloatArray]:
        """Own previous controls shifted to ``t`` (zeros without a plan), and their age."""
        h = self.p.horizon
        age = self._age(t, ids)
        u = np.zeros((len(ids), h, 2))
        live = age < h
        if live.any():
            idx = np.minimum(np.floor(age[live][:, None] + 1e-6).astype(np.intp)
                             + np.arange(h), h - 1)
            u[live] = take_rows(self._r["u"][ids[live]], idx)
        return u, age

    def _shifted_multipliers(self, ids: NDArray[np.intp], age: FloatArray
                             ) -> tuple[FloatArray, FloatArray]:
        """The robots' last multipliers shifted by ``age`` stages (zeros without them)."""
        h, n = self.p.horizon, len(ids)
        live = (age < h) & self._r["lam_ok"][ids]
        shift = np.floor(np.where(live, age, 0.0) + 1e-6).astype(np.intp)
        idx = np.minimum(np.arange(h) + shift[:, None], h - 1)
        out = []
        for key in ("lam_x", "lam_g"):
            lam = take_rows(self._r[key][ids].reshape(n, h, -1), idx)
            lam[~live] = 0.0
            out.append(lam.reshape(n, -1))
        return out[0], out[1]

    def _store(self, g: NDArray[np.intp], t: float, pose: FloatArray, u: FloatArray,
               x: FloatArray | None = None,
               lam: tuple[FloatArray, FloatArray] | None = None) -> None:
        """Write the plans made at ``t`` of global ids ``g`` ``(R,)``.

        Controls ``u`` ``(R, H, 2)``; poses ``x`` ``(R, H + 1, 3)`` (rolled out from
        ``pose`` ``(R, 3)`` when not given); multipliers ``(lam_x, lam_g)`` or None.
        """
        w = self._w
        w["t"][g], w["u"][g] = t, u
        w["x"][g] = x if x is not None else rollout(pose, u, self.tau)
        w["lam_ok"][g] = lam is not None
        if lam is not None:
            w["lam_x"][g], w["lam_g"][g] = lam

    # ------------------------------------------------------------------ step
    def _problems(self, obs: Observation, u0: FloatArray, fresh: NDArray[np.bool_],
                  problem: NmpcProblem | None = None
                  ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Initial guesses ``(N, nw H)``, parameter vectors and constraint lower bounds.

        Linearisation points: the rollout of the shifted plan, or the current
        position for robots without a plan (``fresh``). In ``problem``'s layout
        (default: the controller's problem).
        """
        problem = problem or self.problem
        p, h, n = self.p, self.p.horizon, obs.n
        x0 = rollout(obs.pose, u0, self.tau)
        lin = np.where(fresh[:, None, None], obs.pose[:, None, :2], x0[:, 1:, :2])
        ref, psi, uref = slot_reference(obs.leader, obs.slot_offset,
                                        self.tau * np.arange(1, h + 1))
        on, oc = obstacle_halfplanes(lin, self.static, obs.obstacles, self.tau, p.max_obstacles,
                                     self.radius + p.margin, p.reach)
        every = np.arange(len(self._r["t"]))
        pred, mask = neighbour_predictions(obs.neighbours, p.max_neighbours, self._r["x"][..., :2],
                                           self._age(float(obs.t), every), self.tau, h)
        rn, rc = robot_halfplanes(lin, pred, mask, 2.0 * self.radius + p.margin, p.reach)
        normals = np.concatenate((on, rn), axis=2).reshape(n, h, -1)
        stage = np.concatenate((ref, psi[..., None], uref, normals), axis=2).reshape(n, -1)
        params = np.concatenate((obs.pose, obs.twist, stage), axis=1)
        lbg = np.tile(problem.lbg_template, (n, 1)).reshape(n, h, -1)
        d = problem.spec.dyn_rows
        lbg[:, :, d:d + self.spec.slots] = np.concatenate((oc, rc), axis=2)
        return problem.guesses(u0, x0[:, 1:]), params, lbg.reshape(n, -1)

    def _rescue(self, i: int, step: dict) -> SolveOutput | None:
        """A second solve of row ``i`` after its SQP failed: IPOPT (None without a rescuer).

        Its inputs are made only when it runs (from ``step``: the observation, shifted
        controls, parameters, bounds and shifted multipliers); its multipliers come
        back in the controller's layout. None when it raised.
        """
        if self.rescuer is None:
            return None
        try:
            out = self.rescuer.solve(*self._inputs(i, step, self.rescuer))
        except RuntimeError:
            return None
        if out.success:
            self.last_rescued[i] = True
            out.lam_x, out.lam_g = map_multipliers(out.lam_x, out.lam_g, self.rescuer.spec,
                                                   self.spec)
        return out

    def _inputs(self, i: int, step: dict, problem: NmpcProblem) -> tuple[FloatArray, ...]:
        """Row ``i``'s ``(w0, p, lbg, lam_x0, lam_g0)`` of this step in ``problem``'s layout."""
        u0 = step["u0"][i:i + 1]
        x0 = rollout(step["obs"].pose[i:i + 1], u0, self.tau)
        lbg = map_lbg(step["lbg"][i], self.spec, problem.spec, problem.lbg_template)
        lam = map_multipliers(step["lam_x"][i], step["lam_g"][i], self.spec, problem.spec)
        return problem.guesses(u0, x0[:, 1:])[0], step["params"][i], lbg, *lam

    def _accept(self, rows: NDArray[np.intp], obs: Observation, u: FloatArray, x: FloatArray,
                slack: FloatArray, lam: tuple[FloatArray, FloatArray], out: dict) -> None:
        """Apply and store the solutions of ``rows``.

        Controls ``(R, H, 2)``, poses ``(R, H, 3)``, slacks ``(R, H)`` m, multipliers;
        ``out``: the step's commands and largest slacks, written in place.
        """
        out["cmd"][rows] = u[:, 0]
        out["slack"][rows] = np.maximum(slack.max(axis=1), 0.0)
        ids = np.asarray(obs.robot_ids, dtype=np.intp)[rows]
        self._store(ids, float(obs.t), obs.pose[rows], u.copy(),
                    np.concatenate((obs.pose[rows, None], x), axis=1), lam)

    def _prepare(self, obs: Observation) -> tuple[FloatArray, dict]:
        """The packed inputs ``(N, n)`` of this step's problems, and the step's arrays.

        The step's arrays (observation, shifted controls and their age, parameters,
        bounds, shifted multipliers) are those a rescue's inputs are made from.
        """
        h, t = self.p.horizon, float(obs.t)
        if self._t is None or t > self._t + 1e-9:  # a new step: last step's plans become readable
            self._r = {k: v.copy() for k, v in self._w.items()}
            self._t = t
        ids = np.asarray(obs.robot_ids, dtype=np.intp)
        self._grow(int(max(ids.max(initial=-1), obs.neighbours.index.max(initial=-1))) + 1)
        u0, age = self._shifted(t, ids)
        fresh = age >= h  # no plan: guess the goto command
        for i in np.flatnonzero(fresh):
            u0[i] = goto_command(obs.pose[i], obs.slot[i], self.p.goto_gain, self.spec)
        guess, params, lbg = self._problems(obs, u0, fresh)
        lam_x, lam_g = self._shifted_multipliers(ids, age)
        step = {"obs": obs, "u0": u0, "age": age, "params": params, "lbg": lbg,
                "lam_x": lam_x, "lam_g": lam_g}
        return self.problem.pack(guess, params, lbg, lam_x, lam_g), step

    def act(self, obs: Observation) -> FloatArray:
        """One solve per robot, one compiled call for all of them.

        Row i uses row i of ``obs`` and its neighbours' last plans.
        """
        assert self.problem is not None, "reset() first"
        n = obs.n
        z, step = self._prepare(obs)
        sol = self.problem.solve_rows(z)
        out = {"cmd": np.zeros((n, 2)), "slack": np.zeros(n)}
        status = np.full(n, STATUS_OK, dtype=np.int8)
        self.last_iterations = sol.iterations.copy()
        self.last_rescued = np.zeros(n, dtype=bool)
        ok = np.flatnonzero(sol.success)
        self._accept(ok, obs, sol.u[ok], sol.x[ok], sol.slack[ok],
                     (sol.lam_x[ok], sol.lam_g[ok]), out)
        solve_time = sol.seconds.copy()
        for i in np.flatnonzero(~sol.success):
            t0 = time.perf_counter()
            rescue = self._rescue(i, step)
            solve_time[i] += time.perf_counter() - t0
            if rescue is not None and rescue.success:
                self._accept(np.array([i]), obs, rescue.u[None], rescue.x[None],
                             rescue.slack[None], (rescue.lam_x[None], rescue.lam_g[None]), out)
            else:
                status[i] = STATUS_SOLVER_FAIL
                out["cmd"][i] = self._fallback(obs, i, step["u0"][i], step["age"][i])
        self.last_result = FilterResult(out["cmd"].copy(), status, out["slack"], solve_time)
        return out["cmd"]

    def _fallback(self, obs: Observation, i: int, shifted: FloatArray, age: float) -> FloatArray:
        """The ``on_failure`` command of row ``i``; stores the plan it implies."""
        g, t, pose, h = int(obs.robot_ids[i]), float(obs.t), obs.pose[i], self.p.horizon
        policy = self.p.on_failure
        if policy == "shift" and age < h:
            # keep the previous plan (neighbours go on reading it); it runs out after H stages
            for key, buf in self._w.items():
                buf[g] = self._r[key][g]
            return shifted[0].copy()
        if policy == "goto":
            u = goto_command(pose, obs.slot[i], self.p.goto_gain, self.spec)
        else:
            u = np.zeros(2)
        self._store(np.array([g]), t, pose[None], np.tile(u, (h, 1))[None])
        return u
