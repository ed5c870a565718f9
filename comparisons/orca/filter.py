"""The ORCA / improved-VO safety filter (paper 001 eq 11-13, 16) and the ORCA navigator.

``orca`` (a :class:`~dfcoa_opt.control.base.SafetyFilter`, velocity commands)
replaces each robot's nominal velocity by the closest velocity inside its ORCA
half-planes (one per neighbour within communication range, responsibility 1/2,
horizon ``time_horizon``), the hard half-planes of the static obstacles (mode
``obstacles``) and the speed disc. Use it after any controller with the id
``"<controller>+orca"`` (e.g. ``dfcoa+orca``), or alone through the navigator
``orca_nav``, whose preferred velocity points at the robot's own formation slot.

Infeasible constraints go to the ``infeasible`` policy, and every use is
counted in the run log (``filter_status``): ``least_violation`` (default; the
velocity that minimises the largest violation, hard lines kept), ``stop``
(zero velocity) or ``pass_through`` (the nominal velocity). With
``safe_discrete`` the robots also keep hard next-step separation half-planes
(:mod:`comparisons.orca.safe`), so no two robots overlap at a sampling instant.
The guarantee needs both robots of a pair to apply their half: the
communication radius must cover one step's reach (checked at reset), and a
robot whose neighbour table is full with every entry within reach (it may miss
a robot) stops for that step, counted as a fallback.
Method notes: ``docs/methods/orca_ivo.md``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Literal

import numpy as np

from comparisons.constraints.solvers import check_solver
from comparisons.orca import lp, safe
from comparisons.orca.ivo import ivo_lines
from comparisons.orca.obstacles import obstacle_lines
from comparisons.orca.velocities import orca_velocities
from comparisons.orca.worlds import StaticWorlds
from dfcoa_opt.control.base import (
    STATUS_FALLBACK,
    STATUS_MODIFIED,
    STATUS_OK,
    STATUS_SOLVER_FAIL,
    UNCHANGED_TOL,
    BatchedController,
    Filtered,
    FilterResult,
    Observation,
    as_batch,
)
from dfcoa_opt.control.registry import register, register_filter
from dfcoa_opt.core.errors import ScenarioError
from dfcoa_opt.core.geometry import take_rows
from dfcoa_opt.core.params import param


@register_filter("orca")
class OrcaFilter(BatchedController):
    """ORCA safety filter over nominal velocities (see the module docstring); batched."""

    command = "velocity"
    uses_scan = False

    @dataclass(frozen=True)
    class Params:
        """Parameters of the ``orca`` filter."""

        time_horizon: float = param(2.0, doc="ORCA horizon tau between robots.", unit="s",
                                    gt=0.0, tune=(0.5, 6.0), scale="log")
        v_max: float | None = param(None, doc="Speed limit of the new velocity; default the "
                                              "robots' v_max.", unit="m/s", gt=0.0)
        infeasible: Literal["least_violation", "stop", "pass_through"] = param(
            "least_violation", doc="Policy when the half-planes have no common point.")
        solver: Literal["exact", "qp"] = param(
            "exact", doc="'exact': incremental 2D LP (fast path); 'qp': qpsolvers.")
        qp_solver: str = param("osqp", doc="qpsolvers backend when solver = 'qp'.")
        obstacles: Literal["orca", "ivo", "next_step", "none"] = param(
            "orca", doc="Static obstacles: 'orca': RVO2's obstacle ORCA lines (mode a, horizon "
                        "time_horizon_obst); 'ivo': paper 001's improved VO (mode b, eq 8-10, "
                        "comparisons/orca/ivo/; circles as exact discs); 'next_step': hard "
                        "half-planes that keep the robot off every polygon edge at the next step "
                        "(comparisons/orca/safe.py); 'none': ignored.")
        time_horizon_obst: float = param(2.0, doc="ORCA horizon of static obstacles (mode "
                                                  "'orca'); with v_max it also sets the 'ivo' "
                                                  "range.", unit="s", gt=0.0, tune=(0.3, 6.0),
                                         scale="log")
        ivo_tau: Literal["center", "gap"] = param(
            "center", doc="Eq 9 horizon of mode 'ivo': distance from the robot's centre "
                          "('center') or from its rim ('gap') to the ellipse, over the speed.")
        ivo_max_segment: float | None = param(
            None, doc="Mode 'ivo': split polygon edges into pieces no longer than this, each "
                      "with its own eq-8 ellipse; default: one ellipse per edge (facade). From "
                      "5 cm: shorter pieces add ellipses far below a robot's size, and their "
                      "count (edge length over this) sets the filter's memory.",
            unit="m", ge=0.05)
        safe_discrete: bool = param(False, doc="Add hard half-planes that forbid overlap at "
                                               "the next step (comparisons/orca/safe.py).")

    def __init__(self, params: Params, owner: str | None = None) -> None:
        """Build the filter.

        Args:
            params: The filter's parameters.
            owner: Controller id whose ``[controllers.<owner>]`` table holds ``params``
                (for error messages); default the filter's own id.
        """
        self.p = params
        self._owner = owner or self.name
        self._radius = 0.2
        self._v_max = 1.0
        self._worlds: StaticWorlds | None = None

    def reset_batch(self, scenarios, rngs) -> None:
        """Read the robots' radius and speed limit and the static obstacles of every run.

        Modes 'orca' and 'next_step' (and the safe mode) see every shape as a
        polygon (a circle as its circumscribed 32-gon); mode 'ivo' takes circles
        as exact discs (one line each, :mod:`comparisons.orca.ivo.discs`) and the
        other shapes as polygon edges. Runs with different worlds (a clutter
        field drawn from the seed) each keep their own.

        Raises:
            ScenarioError: ``solver = 'qp'`` with a ``qp_solver`` that is not installed,
                or ``safe_discrete`` with ``sensors.comm_radius`` below one step's reach.
        """
        scenario = scenarios[0]
        if self.p.solver == "qp":
            check_solver(self.p.qp_solver, scenario.source,
                         f"controllers.{self._owner}.qp_solver")
        rob = scenario.spec.robots
        v_max = self.p.v_max if self.p.v_max is not None else rob.v_max
        reach = 2.0 * rob.radius + 2.0 * v_max * scenario.spec.dt
        if self.p.safe_discrete and scenario.spec.sensors.comm_radius < reach:
            raise ScenarioError(scenario.source, "sensors.comm_radius", f"must be >= "
                                f"{reach:g} m (2 radius + 2 v_max dt) with "
                                f"controllers.{self._owner}.safe_discrete: a robot must see "
                                "every robot it could touch within one step")
        self._radius = rob.radius
        self._v_max = v_max
        self._worlds = StaticWorlds(scenarios, self.p.obstacles == "orca",
                                    self.p.ivo_max_segment)

    @property
    def _segments(self) -> np.ndarray:
        """``(S, 2, 2)`` the polygon edges of the first run's world, m."""
        return self._worlds.segments[0] if self._worlds else np.zeros((0, 2, 2))

    @property
    def _ivo_segments(self) -> np.ndarray:
        """``(S, 4)`` the polygon edges of mode 'ivo' in the first run's world, m."""
        return self._worlds.ivo_items[0][0] if self._worlds else np.zeros((0, 4))

    @property
    def _ivo_discs(self) -> np.ndarray:
        """``(C, 3)`` the discs (circles) of mode 'ivo' in the first run's world, m."""
        return self._worlds.ivo_items[0][1] if self._worlds else np.zeros((0, 3))

    def _hard_lines(self, obs: Observation):
        """Hard lines of every robot: static obstacles and, in safe mode, next-step separation.

        In safe mode the next-step edge half-planes are added whatever ``obstacles`` is,
        so that the no-overlap guarantee covers static obstacles too.
        """
        n = obs.n
        radius = np.full(n, self._radius)
        v_max = np.full(n, self._v_max)
        worlds = self._worlds
        mode = self.p.obstacles if worlds is not None else "none"  # not reset: no map
        world = worlds.row_world(obs.env) if worlds is not None else None
        pos = obs.pose[:, :2]
        groups = []
        if mode == "orca" and worlds.obstacles is not None:
            groups.append(obstacle_lines(pos, obs.velocity, radius, v_max,
                                         self.p.time_horizon_obst, worlds.obstacles, world))
        if mode == "ivo" and worlds.ivo.segments.shape[1] + worlds.ivo.discs.shape[1]:
            reach = v_max[0] * self.p.time_horizon_obst + self._radius
            groups.append(ivo_lines(pos, obs.velocity, radius, worlds.ivo, reach,
                                    tau=self.p.ivo_tau, tau_min=max(obs.dt, 0.1), world=world))
        if worlds is not None and (mode == "next_step" or self.p.safe_discrete):
            groups.append(safe.segment_safety_lines(pos, radius, v_max, obs.dt,
                                                    worlds.row_segments(world)))
        blind = np.zeros(n, dtype=bool)
        if self.p.safe_discrete:
            *pair, blind = self._pair_lines(obs, radius, v_max)
            groups.append(tuple(pair))
        if not groups:
            return np.zeros((n, 0, 2)), np.zeros((n, 0, 2)), np.zeros(n, np.int64), blind
        return (*concat_lines(groups), blind)

    def _pair_lines(self, obs: Observation, radius, v_max):
        """Next-step separation from the neighbours each robot knows (its own row only).

        Returns:
            ``(points, directions, count, blind)``: the lines, and which robots may not
            know every robot within one step's reach (a full neighbour table whose
            farthest entry is within reach), see :meth:`filter`.
        """
        nb = obs.neighbours
        rel = obs.pose[:, None, :2] - nb.position
        dist = np.linalg.norm(rel, axis=-1)
        reach = 2.0 * radius[:, None] + 2.0 * v_max[:, None] * obs.dt
        used = nb.mask & (dist < reach)
        blind = nb.mask.all(axis=1) & used.all(axis=1)
        order = np.argsort(np.where(used, dist, np.inf), axis=1, kind="stable")
        count = used.sum(axis=1)
        dist, rel = take_rows(dist, order), take_rows(rel, order)
        ok = np.arange(dist.shape[1])[None, :] < count[:, None]
        normal = rel / np.where(ok & (dist > 0), dist, 1.0)[..., None]
        bound = np.where(ok, (2.0 * radius[:, None] - dist) / (2.0 * obs.dt), 0.0)
        points, directions = safe.halfplane_lines(normal, bound)
        return points, directions, count, blind

    def filter(self, obs: Observation, nominal: np.ndarray) -> FilterResult:
        """Closest velocity to ``nominal`` (rows ``(vx, vy)``) within the constraints.

        Every row of every run of the batch in one pass (an observation without
        ``env`` is one run); row i from row i of ``obs`` and its own run's world.
        """
        t0 = time.perf_counter()
        obs = as_batch(obs)
        n = obs.n
        nominal = np.asarray(nominal, dtype=float)[:, :2]
        nb = obs.neighbours
        hp, hd, hc, blind = self._hard_lines(obs)
        count = nb.mask.sum(axis=1)
        radius = np.full(n, self._radius)
        v_max = np.full(n, self._v_max)
        if self.p.solver == "exact":
            vel, status, slack = orca_velocities(
                obs.pose[:, :2], obs.velocity, radius, nb.position, nb.velocity,
                np.full(nb.index.shape, self._radius), count, nominal, v_max,
                self.p.time_horizon, obs.dt, hp, hd, hc)
        else:
            vel, status, slack = self._qp(obs, nominal, radius, v_max, hp, hd, hc, count)
        out_status = np.where(np.linalg.norm(vel - nominal, axis=1) > UNCHANGED_TOL,
                              STATUS_MODIFIED, STATUS_OK).astype(np.int8)
        bad = status != lp.FEASIBLE
        failed = status == lp.SOLVER_FAIL
        if bad.any():
            out_status[bad] = np.where(failed[bad], STATUS_SOLVER_FAIL, STATUS_FALLBACK)
            if self.p.infeasible == "stop":
                vel[bad] = 0.0
            elif self.p.infeasible == "pass_through":
                vel[bad] = nominal[bad]
        if self.p.safe_discrete:
            vel, scaled = safe.scale_into(vel, hp, hd, hc)
            out_status[scaled & (out_status == STATUS_OK)] = STATUS_MODIFIED
            # a robot whose table may miss a robot in reach stops: v = 0 meets its half of
            # every pair constraint, and its neighbours keep theirs (fallback, counted)
            vel[blind] = 0.0
            out_status[blind] = STATUS_FALLBACK
        per_robot = (time.perf_counter() - t0) / max(n, 1)
        return FilterResult(vel, out_status, np.where(bad, slack, 0.0), np.full(n, per_robot))

    def _qp(self, obs, nominal, radius, v_max, hp, hd, hc, count):
        """The qpsolvers path: same lines, solved one robot at a time."""
        from comparisons.orca.lines import agent_lines
        from comparisons.orca.qp import solve_lines_qp

        n, k = obs.n, obs.neighbours.index.shape[1]
        points = np.zeros((n, hp.shape[1] + k, 2))
        directions = np.zeros_like(points)
        total = np.zeros(n, np.int64)
        nb = obs.neighbours
        for i in range(n):
            points[i, :hc[i]], directions[i, :hc[i]] = hp[i, :hc[i]], hd[i, :hc[i]]
            total[i] = agent_lines(obs.pose[i, 0], obs.pose[i, 1], obs.velocity[i, 0],
                                   obs.velocity[i, 1], radius[i], nb.position[i],
                                   nb.velocity[i], np.full(k, self._radius), count[i],
                                   1.0 / self.p.time_horizon, 1.0 / obs.dt, points[i],
                                   directions[i], hc[i])
        return solve_lines_qp(points, directions, total, hc, nominal, v_max,
                              solver=self.p.qp_solver)


def concat_lines(groups):
    """Join per-robot padded line groups ``[(points, directions, count), ...]`` row by row."""
    n = len(groups[0][2])
    width = sum(g[0].shape[1] for g in groups)
    points = np.zeros((n, width, 2))
    directions = np.zeros((n, width, 2))
    count = np.zeros(n, np.int64)
    for p, d, c in groups:
        rows, cols = np.nonzero(np.arange(p.shape[1])[None, :] < np.asarray(c)[:, None])
        points[rows, count[rows] + cols] = p[rows, cols]
        directions[rows, count[rows] + cols] = d[rows, cols]
        count = count + c
    return points, directions, count


class _TowardsSlot(BatchedController):
    """Preferred velocity of the navigator: towards the own slot at up to ``speed`` (m/s).

    Row-wise and stateless, so batched: the rows of every run in one call.
    """

    command = "velocity"
    name = "pref"
    uses_scan = False

    def __init__(self, speed: float) -> None:
        self.speed = speed

    def reset_batch(self, scenarios, rngs) -> None:
        """Stateless."""

    def act(self, obs: Observation) -> np.ndarray:
        """``speed`` towards the slot, slower within ``speed`` (1 s) of it (RVO2's examples)."""
        vec = obs.slot - obs.pose[:, :2]
        dist = np.linalg.norm(vec, axis=1, keepdims=True)
        return np.where(dist > self.speed, vec * (self.speed / np.maximum(dist, 1e-12)), vec)


@register("orca_nav")
class OrcaNavigator(Filtered):
    """Standalone ORCA: preferred velocity towards the own slot, then the ``orca`` filter.

    Batched (both parts are): one object for every run of a batch.
    """

    @dataclass(frozen=True)
    class Params(OrcaFilter.Params):
        """Parameters of the ``orca_nav`` navigator (the filter's, plus the preferred speed)."""

        speed: float = param(0.3, doc="Preferred speed towards the slot.", unit="m/s", gt=0.0,
                             tune=(0.15, 0.6))

    def __init__(self, params: Params) -> None:
        fields = {k: getattr(params, k) for k in OrcaFilter.Params.__dataclass_fields__}
        super().__init__(_TowardsSlot(params.speed), OrcaFilter(OrcaFilter.Params(**fields),
                                                                  owner=self.name))
