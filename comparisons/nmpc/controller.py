"""Distributed nonlinear MPC formation controller: ``nmpc`` (not from the papers).

Every robot solves its own small NLP each step (casadi, built once per parameter
set, :mod:`comparisons.nmpc.problem`) and applies the first control ``(v, omega)``
(``command = "unicycle"``):

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
  written at time ``t`` are visible from the next step on). A plan travels with its
  robot's state message: an entry ``a`` s old carries the plan of ``a`` s ago.
* **Batched.** One object steps every run of a batch (``batched = True``): the
  problems of every robot of every run are set up elementwise over the rows and
  solved in one compiled call; each run's rows give its numbers alone, bit for bit
  (plans by global id ``env * N + robot``, static shapes of each run's own world).
* **Solver.** ``"sqp"`` (default: casadi ``sqpmethod`` + ``daqp`` with a
  Gauss-Newton Hessian, at most 20 iterations, on the condensed problem (the states
  eliminated by the dynamics), compiled to C once per machine; re-solved by IPOPT on
  the multiple-shooting problem when it fails) or ``"ipopt"``; warm-started from the
  shifted previous solution and multipliers. A failed solve (no success, an
  exception, a non-finite value) applies ``on_failure`` and is logged with status
  ``STATUS_SOLVER_FAIL``; ``last_result.solve_time`` is the solver time per robot, s.
* **Real-time iteration** (``rti = true``, ``sqp`` only; Diehl, Bock and Schloeder
  2005): a robot whose plan was solved at the previous step makes one full SQP step
  from it (shifted plan and multipliers), applied whatever its KKT measures when it
  returns finite values without error; otherwise (first step, after a fallback) the
  full SQP solves its problem. Rescue and ``on_failure`` as above.

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
from comparisons.constraints.world_shapes import WorldShapes
from comparisons.nmpc.fallback import goto_command
from comparisons.nmpc.geometry import obstacle_halfplanes, robot_halfplanes, slot_reference
from comparisons.nmpc.model import rollout
from comparisons.nmpc.outputs import BatchOutput, SolveOutput
from comparisons.nmpc.plans import PlanBuffers
from comparisons.nmpc.spec import ProblemSpec
from dfcoa_opt.control.base import (
    STATUS_OK,
    STATUS_SOLVER_FAIL,
    BatchedController,
    FilterResult,
    Observation,
)
from dfcoa_opt.control.registry import register
from dfcoa_opt.core.errors import ScenarioError
from dfcoa_opt.core.params import param

if TYPE_CHECKING:
    from comparisons.nmpc.problem import NmpcProblem
    from dfcoa_opt.scenario.scenario import Scenario

FloatArray = NDArray[np.float64]
__all__ = ["SQP_MAX_ITER", "IPOPT_MAX_ITER", "Nmpc", "goto_command"]


@lru_cache(maxsize=8)
def _problem(spec: ProblemSpec) -> NmpcProblem:
    """The casadi problem of a spec (casadi Functions are stateless: shared by runs).

    casadi is imported here, at the first reset, not with the controller: listing
    or building controllers stays light.
    """
    from comparisons.nmpc.problem import NmpcProblem

    return NmpcProblem(spec)


#: Default iteration limits: SQP (Gauss-Newton converges linearly on hard problems, so a
#: failure is cut short and rescued) and IPOPT (also the rescue's limit).
SQP_MAX_ITER, IPOPT_MAX_ITER = 20, 100


@register("nmpc")
class Nmpc(BatchedController):
    """Distributed NMPC: each robot tracks its formation slot over a short horizon; batched.

    One object steps every run of a batch (:class:`BatchedController`): the
    set-up of every row's problem (references, shifted plans and multipliers,
    neighbour predictions, half-planes) is elementwise over all rows of all
    runs, and one compiled call solves them all; plans are kept by global id
    ``env * N + robot`` in :attr:`plans`.

    Attributes:
        last_result: The latest step's commands, status (``STATUS_OK`` or
            ``STATUS_SOLVER_FAIL``), largest slack (m) and solve time (s), one per row.
        last_iterations: ``(R,)`` iterations of the latest SQP solves, not of the IPOPT
            rescues (-1 when unknown: compiled solver, or an exception).
        last_rescued: ``(R,)`` which rows' SQP failed and IPOPT then succeeded.
        last_rti: ``(R,)`` which rows made one real-time iteration (``rti``; the others
            ran the full SQP).
        statics: The static shapes of the maps of the batch (``static``: the first map).
        plans: Every robot's last plan by global id
            (:class:`~comparisons.nmpc.plans.PlanBuffers`; made by the reset).
    """

    command = "unicycle"
    uses_scan = False  # obstacles from the map's exact shapes and obs.obstacles

    @dataclass(frozen=True)
    class Params:
        """Parameters of ``nmpc``."""

        horizon: int = param(10, doc="Prediction horizon H (stages).", ge=2, le=100,
                             tune=(5, 15))
        step: float | None = param(None, doc="Prediction step tau; default the scenario's dt.",
                                   unit="s", gt=0.0)
        w_track: float = param(1.0, doc="Slot tracking weight of stages 1..H-1.",
                               unit="1/m^2", ge=0.0, tune=(0.1, 10.0), scale="log")
        w_terminal: float = param(10.0, doc="Slot tracking weight of the last stage.",
                                  unit="1/m^2", ge=0.0, tune=(1.0, 100.0), scale="log")
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
                              unit="m", ge=0.0, tune=(0.0, 0.3))
        max_neighbours: int = param(4, doc="Neighbour constraints per stage K (nearest first).",
                                    ge=0, le=50)
        max_obstacles: int = param(4, doc="Obstacle constraints per stage M (nearest first).",
                                   ge=0, le=50)
        reach: float = param(1.5, doc="Obstacles and neighbours farther than this from the "
                                      "linearisation point are left out.", unit="m", gt=0.0,
                             tune=(0.8, 3.0))
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
        rti: bool = param(False, doc="Real-time iteration ('sqp' only): a robot with a plan "
                                     "solved at the previous step makes one full SQP step "
                                     "from it, applied when finite whatever its KKT "
                                     "measures; the full SQP on its first step and after "
                                     "a fallback.")
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
        self.last_rti: NDArray[np.bool_] = np.zeros(0, dtype=bool)
        self.problem: NmpcProblem | None = None
        self.rescuer: NmpcProblem | None = None
        self.iterate: NmpcProblem | None = None  # the real-time iteration's (rti)
        self.plans: PlanBuffers | None = None

    # ------------------------------------------------------------------ set-up
    def reset_batch(self, scenarios: list[Scenario], rngs: list[np.random.Generator]) -> None:
        """Build the casadi solver(s) (once per parameter set) and clear every plan.

        Args:
            scenarios: One per run of the batch (the same file and parameters; a
                seeded clutter field gives each run its own world).
            rngs: One per run (unused: ``nmpc`` draws nothing).
        """
        scenario = scenarios[0]
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
        self.iterate = None
        if p.rti:
            if p.solver != "sqp":
                raise ScenarioError(scenario.source, "controllers.nmpc.rti",
                                    "a real-time iteration needs solver = 'sqp'")
            self.iterate = _problem(replace(self.spec, max_iter=1, rti=True))
        self.rescuer = None
        if p.rescue and p.solver == "sqp":  # multiple shooting: IPOPT is faster on it
            self.rescuer = _problem(replace(self.spec, solver="ipopt", hessian="exact",
                                            qp_solver="qrqp", max_iter=IPOPT_MAX_ITER,
                                            formulation="multiple-shooting", compiled=False))
        self.radius = rob.radius
        worlds: dict[int, int] = {}  # runs of one world (all but a seeded clutter field) share
        for sc in scenarios:
            worlds.setdefault(id(sc.world), len(worlds))
        self.statics = WorldShapes([StaticObstacles.from_shapes(sc.world.shapes)
                                    for sc in {id(sc.world): sc for sc in scenarios}.values()])
        self._static_of = np.array([worlds[id(sc.world)] for sc in scenarios], dtype=np.intp)
        self.static = self.statics.maps[0]
        n = scenario.spec.team.n
        self.plans = PlanBuffers(self.spec, self.tau, n, len(scenarios) * n)
        self.last_result = None

    # ------------------------------------------------------------------ step
    def _problems(self, obs: Observation, u0: FloatArray, fresh: NDArray[np.bool_],
                  problem: NmpcProblem | None = None, nb_ids: NDArray[np.intp] | None = None
                  ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Initial guesses ``(R, nw H)``, parameter vectors and constraint lower bounds.

        Every row of every run at once (elementwise over rows). Linearisation
        points: the rollout of the shifted plan, or the current position for
        robots without a plan (``fresh``). Static obstacles of each row's own
        world; neighbours' plans by the global ids ``nb_ids`` (default: from
        ``obs``, :meth:`PlanBuffers.global_ids`). In ``problem``'s layout (default: the
        controller's problem).
        """
        problem = problem or self.problem
        if nb_ids is None:
            nb_ids = self.plans.global_ids(obs)[1]
        p, h, n = self.p, self.p.horizon, obs.n
        x0 = rollout(obs.pose, u0, self.tau)
        lin = np.where(fresh[:, None, None], obs.pose[:, None, :2], x0[:, 1:, :2])
        ref, psi, uref = slot_reference(obs.leader if obs.env is None else obs.row_leader(),
                                        obs.slot_offset, self.tau * np.arange(1, h + 1))
        world = None if obs.env is None or len(self.statics.maps) == 1 else \
            self._static_of[obs.env]
        on, oc = obstacle_halfplanes(lin, self.statics, obs.obstacles, self.tau,
                                     p.max_obstacles, self.radius + p.margin, p.reach, world)
        pred, mask = self.plans.predictions(obs, nb_ids, p.max_neighbours)
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
            from comparisons.nmpc.formulation import map_multipliers

            self.last_rescued[i] = True
            out.lam_x, out.lam_g = map_multipliers(out.lam_x, out.lam_g, self.rescuer.spec,
                                                   self.spec)
        return out

    def _inputs(self, i: int, step: dict, problem: NmpcProblem) -> tuple[FloatArray, ...]:
        """Row ``i``'s ``(w0, p, lbg, lam_x0, lam_g0)`` of this step in ``problem``'s layout."""
        from comparisons.nmpc.formulation import map_lbg, map_multipliers

        u0 = step["u0"][i:i + 1]
        x0 = rollout(step["obs"].pose[i:i + 1], u0, self.tau)
        lbg = map_lbg(step["lbg"][i], self.spec, problem.spec, problem.lbg_template)
        lam = map_multipliers(step["lam_x"][i], step["lam_g"][i], self.spec, problem.spec)
        return problem.guesses(u0, x0[:, 1:])[0], step["params"][i], lbg, *lam

    def _accept(self, rows: NDArray[np.intp], step: dict, u: FloatArray, x: FloatArray,
                slack: FloatArray, lam: tuple[FloatArray, FloatArray], out: dict) -> None:
        """Apply and store the solutions of ``rows``.

        Controls ``(R, H, 2)``, poses ``(R, H, 3)``, slacks ``(R, H)`` m, multipliers;
        ``out``: the step's commands and largest slacks, written in place.
        """
        obs = step["obs"]
        out["cmd"][rows] = u[:, 0]
        out["slack"][rows] = np.maximum(slack.max(axis=1), 0.0)
        self.plans.store(step["ids"][rows], float(obs.t), obs.pose[rows], u.copy(),
                         np.concatenate((obs.pose[rows, None], x), axis=1), lam)

    def _prepare(self, obs: Observation) -> tuple[FloatArray, dict]:
        """The packed inputs ``(R, n)`` of this step's problems, and the step's arrays.

        The step's arrays (observation, global ids, shifted controls and their age,
        parameters, bounds, shifted multipliers) are those a rescue's inputs are
        made from.
        """
        h, t = self.p.horizon, float(obs.t)
        self.plans.advance(t, None if obs.neighbours.age is None else float(obs.dt))
        ids, nb_ids = self.plans.global_ids(obs)
        u0, age = self.plans.shifted(t, ids)
        fresh = age >= h  # no plan: guess the goto command
        for i in np.flatnonzero(fresh):  # (the first step of a run, or a fallback run out)
            u0[i] = goto_command(obs.pose[i], obs.slot[i], self.p.goto_gain, self.spec)
        guess, params, lbg = self._problems(obs, u0, fresh, nb_ids=nb_ids)
        lam_x, lam_g = self.plans.shifted_multipliers(ids, age)
        rti = self.plans.solved_last_step(ids) & (self.iterate is not None)
        step = {"obs": obs, "ids": ids, "u0": u0, "age": age, "params": params, "lbg": lbg,
                "lam_x": lam_x, "lam_g": lam_g, "rti": rti}
        return self.problem.pack(guess, params, lbg, lam_x, lam_g), step

    def act(self, obs: Observation) -> FloatArray:
        """One solve per row (every robot of every run), one compiled call for all of them.

        Row i uses row i of ``obs`` and its neighbours' last plans.
        """
        assert self.problem is not None, "reset() first"
        n = obs.n
        z, step = self._prepare(obs)
        sol = self._solve(z, step["rti"])
        out = {"cmd": np.zeros((n, 2)), "slack": np.zeros(n)}
        status = np.full(n, STATUS_OK, dtype=np.int8)
        self.last_iterations = sol.iterations.copy()
        self.last_rescued = np.zeros(n, dtype=bool)
        self.last_rti = step["rti"].copy()
        ok = np.flatnonzero(sol.success)
        self._accept(ok, step, sol.u[ok], sol.x[ok], sol.slack[ok],
                     (sol.lam_x[ok], sol.lam_g[ok]), out)
        solve_time = sol.seconds.copy()
        for i in np.flatnonzero(~sol.success):
            t0 = time.perf_counter()
            rescue = self._rescue(i, step)
            solve_time[i] += time.perf_counter() - t0
            if rescue is not None and rescue.success:
                self._accept(np.array([i]), step, rescue.u[None], rescue.x[None],
                             rescue.slack[None], (rescue.lam_x[None], rescue.lam_g[None]), out)
            else:
                status[i] = STATUS_SOLVER_FAIL
                out["cmd"][i] = self._fallback(step, i)
        self.last_result = FilterResult(out["cmd"].copy(), status, out["slack"], solve_time)
        return out["cmd"]

    def _solve(self, z: FloatArray, rti: NDArray[np.bool_]) -> BatchOutput:
        """Solve packed inputs ``z`` ``(R, n)``: rows ``rti`` by one real-time iteration.

        The other rows run the full SQP; one compiled call per kind of row.
        """
        if not rti.any():
            return self.problem.solve_rows(z)
        assert self.iterate is not None
        full = np.flatnonzero(~rti)
        parts = [(np.flatnonzero(rti), self.iterate.solve_rows(z[rti]))]
        if len(full):
            parts.append((full, self.problem.solve_rows(z[full])))
        return BatchOutput.gather(len(z), parts)

    def _fallback(self, step: dict, i: int) -> FloatArray:
        """The ``on_failure`` command of row ``i``; stores the plan it implies."""
        obs, g, h = step["obs"], step["ids"][i:i + 1], self.p.horizon
        pose, policy = obs.pose[i], self.p.on_failure
        if policy == "shift" and step["age"][i] < h:
            # keep the previous plan (neighbours go on reading it); it runs out after H stages
            self.plans.keep(int(g[0]))
            return step["u0"][i][0].copy()
        if policy == "goto":
            u = goto_command(pose, obs.slot[i], self.p.goto_gain, self.spec)
        else:
            u = np.zeros(2)
        self.plans.store(g, float(obs.t), pose[None], np.tile(u, (h, 1))[None])
        return u
