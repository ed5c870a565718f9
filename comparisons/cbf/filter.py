"""``cbf``: a control-barrier-function QP safety filter over velocity commands.

Beyond the papers (the Robotarium's barrier certificates, and Ames et al.'s
CBF-QP). Each robot's velocity ``u_i`` is the closest one to the nominal
``u_hat_i`` whose barriers do not fall faster than ``-gamma h``:

    min sum_i ||u_i - u_hat_i||^2
    s.t. dh/dt >= -gamma h   for every barrier h,   |u_x|, |u_y| <= v_max.

Barriers (:mod:`comparisons.constraints.distance`, shared with ``nmpc``):

- robot pairs: ``h_ij = ||p_i - p_j||^2 - D_s^2``, ``D_s = 2 r + margin``;
- static circles and polygons (through the nearest boundary point ``q``) and
  sensed moving discs: ``h = delta |delta| - D_o^2``, ``D_o = r + margin``,
  i.e. ``||p - q||^2 - D_o^2`` outside; a moving disc's velocity enters
  ``dh/dt``.

Every row is divided by ``2 |delta|``, so it reads ``n . u >= ...`` in m/s and
its violation is in m/s. Modes: ``centralized`` solves one QP for all robots
(pair rows couple ``u_i`` and ``u_j``); ``distributed`` lets each robot solve
its own QP and take half of every pair's decrease (``gamma h_ij / 2`` each;
the two halves add up to the pair's condition). Unicycles use the
single-integrator-to-unicycle map of the simulator (the near-identity point
``robots.nid_distance`` ahead, which moves with the commanded velocity):
barriers are on those points, with ``D`` grown by the offset.

``discrete_time`` (default) uses ``gamma_eff = min(gamma, 1/dt)``: all these
barriers are convex in the positions outside the obstacle (squared distance to
a point, a disc or a convex polygon), so ``h(p + u dt) >= h + dt grad h . u
>= (1 - gamma dt) h >= 0``: a single integrator never crosses a barrier at a
sampling instant. It is a guarantee for convex obstacles and exact motion;
non-convex polygons, unicycles (the near-identity point moves along an arc)
and speed saturation make it approximate. Uniform speed saturation keeps it
(every right-hand side is <= 0 while h >= 0).

Infeasible programs (a robot already inside a margin, a moving disc too
fast) go to the ``infeasible`` policy and are counted (``STATUS_FALLBACK``):
``least_violation`` takes the velocity closest to the nominal one among
those whose largest row violation is least (an LP, then the QP with the rows
relaxed by it); ``keep_static`` does the same with the static obstacle rows
kept, as RVO2 keeps its obstacle lines (a robot squeezed between a moving disc
and a wall gives way to the disc, never to the wall; exact solver only);
``stop``; ``pass_through``.
A solver error is ``STATUS_SOLVER_FAIL`` with the ``stop`` command, or the
nominal one under ``pass_through``. Method notes: ``docs/methods/cbf.md``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Literal

import numpy as np

from comparisons.cbf.qp import (
    BarrierRows,
    solve_centralized,
    solve_distributed,
    solve_distributed_exact,
)
from comparisons.constraints.distance import (
    Nearest,
    StaticObstacles,
    barrier,
    disc_nearest,
    pair_geometry,
)
from comparisons.constraints.solvers import check_solver
from comparisons.constraints.world_shapes import WorldShapes
from dfcoa_opt.control.base import BatchedController, FilterResult, Observation
from dfcoa_opt.control.registry import register_filter
from dfcoa_opt.core.errors import ScenarioError
from dfcoa_opt.core.params import param

#: Distances below this are taken as this in the row normalisation, m.
MIN_DELTA = 1e-9


@register_filter("cbf")
class CbfFilter(BatchedController):
    """CBF-QP safety filter (see the module docstring); batched (one object for E runs)."""

    command = "velocity"
    uses_scan = False

    @dataclass(frozen=True)
    class Params:
        """Parameters of the ``cbf`` filter."""

        gamma: float = param(2.0, doc="Class-K gain gamma of dh/dt >= -gamma h.", unit="1/s",
                             gt=0.0, tune=(0.3, 10.0), scale="log")
        margin: float = param(0.05, doc="Extra distance kept beyond contact.", unit="m",
                              ge=0.0, tune=(0.0, 0.3))
        mode: Literal["distributed", "centralized"] = param(
            "distributed", doc="'distributed': one QP per robot, half of every pair's "
                               "decrease each; 'centralized': one QP for all robots.")
        discrete_time: bool = param(True, doc="Use gamma_eff = min(gamma, 1/dt), which keeps "
                                              "convex barriers at every sampling instant.")
        v_max: float | None = param(None, doc="Half-width of the speed box |u_x|, |u_y|; "
                                              "default the robots' v_max / sqrt 2 (the box "
                                              "inside the speed disc).", unit="m/s", gt=0.0)
        obstacle_range: float = param(3.0, doc="Static obstacles farther than this (signed "
                                               "distance) get no row.", unit="m", gt=0.0,
                                      tune=(1.0, 5.0))
        max_obstacles: int = param(6, doc="Most static obstacles per robot (nearest first); "
                                          "each is a QP row.", ge=0, le=1000)
        infeasible: Literal["least_violation", "keep_static", "stop", "pass_through"] = param(
            "least_violation", doc="Policy when the barrier rows have no common point "
                                   "('keep_static': the solver 'exact' only).")
        solver: str = param("auto", doc="'auto': 'exact' in distributed mode, 'osqp' in "
                                        "centralized mode; 'exact' (distributed mode only): "
                                        "ORCA's exact 2D solver, the QP's optimum, 47-146x "
                                        "faster than osqp on large_20/large_100; or a "
                                        "qpsolvers backend (e.g. 'osqp').")

    def __init__(self, params: Params, owner: str | None = None) -> None:
        """Build the filter.

        Args:
            params: The filter's parameters.
            owner: Controller id whose table holds ``params`` (for messages); default ``cbf``.
        """
        self.p = params
        self._owner = owner or self.name
        self._radius = 0.2
        self._offset = 0.0
        self._v_box = 1.0
        self._gamma = params.gamma
        self._solver = params.solver  # 'auto' resolved at reset
        self._statics = WorldShapes([StaticObstacles.from_shapes(())])
        self._static_of = np.zeros(1, dtype=np.intp)

    def reset_batch(self, scenarios, rngs) -> None:
        """Read the robots' size, model and limits, and each run's map shapes.

        Raises:
            ScenarioError: The ``solver`` backend is not installed.
        """
        scenario = scenarios[0]
        key = f"controllers.{self._owner}.solver"
        self._solver = self.p.solver
        if self._solver == "auto":
            self._solver = "exact" if self.p.mode == "distributed" else "osqp"
        if self._solver == "exact":
            if self.p.mode != "distributed":
                raise ScenarioError(scenario.source, key, "'exact' solves 2D programs: it "
                                                          "needs mode = 'distributed'")
        else:
            check_solver(self._solver, scenario.source, key)
            if self.p.infeasible == "keep_static":
                raise ScenarioError(scenario.source, f"controllers.{self._owner}.infeasible",
                                    "'keep_static' needs solver = 'exact' (mode = "
                                    f"'distributed'), not {self._solver!r}")
        rob = scenario.spec.robots
        self._radius = rob.radius
        self._offset = rob.nid_distance if rob.model == "unicycle" else 0.0
        self._v_box = self.p.v_max if self.p.v_max is not None else rob.v_max / np.sqrt(2.0)
        dt = scenario.spec.dt
        self._gamma = min(self.p.gamma, 1.0 / dt) if self.p.discrete_time else self.p.gamma
        worlds: dict[int, int] = {}  # runs of one world (all but a seeded clutter field) share
        for sc in scenarios:
            worlds.setdefault(id(sc.world), len(worlds))
        self._statics = WorldShapes([StaticObstacles.from_shapes(sc.world.shapes) for sc in
                                     {id(sc.world): sc for sc in scenarios}.values()])
        self._static_of = np.array([worlds[id(sc.world)] for sc in scenarios], dtype=np.intp)

    def _nearest(self, p: np.ndarray, env: np.ndarray | None) -> Nearest:
        """Each row's nearest static obstacles, in the world of its own run (one call)."""
        args = (self.p.max_obstacles, self.p.obstacle_range)
        if len(self._statics.maps) == 1:
            return self._statics.maps[0].nearest(p, *args)
        return self._statics.nearest(p[:, None, :], *args, world=self._static_of[env])

    @property
    def pair_distance(self) -> float:
        """Distance (m) the filter keeps between two robots' controlled points.

        ``2 (r + offset) + margin``: a gap narrower than this between two robots'
        centres (give or take the near-identity offsets) is closed to a third.
        """
        return 2.0 * (self._radius + self._offset) + self.p.margin

    @property
    def obstacle_distance(self) -> float:
        """Distance (m) the filter keeps between a robot's controlled point and an obstacle.

        ``r + offset + margin``: a gap narrower than twice this is closed to a robot.
        """
        return self._radius + self._offset + self.p.margin

    def _points(self, position: np.ndarray, heading: np.ndarray | None) -> np.ndarray:
        """The controlled points: centres, or the near-identity points of unicycles."""
        if self._offset == 0.0 or heading is None:
            return position
        return position + self._offset * np.stack([np.cos(heading), np.sin(heading)], -1)

    def rows(self, obs: Observation) -> tuple[BarrierRows, BarrierRows]:
        """Barrier rows ``n . u_i >= bound`` (m/s) of every robot: pairs, and obstacles.

        Returns:
            ``(pairs, obstacles)``. Pair rows hold the whole ``gamma h`` (the
            distributed mode halves it); obstacle rows (static, then moving) are
            each robot's alone.
        """
        g = self._gamma
        p = self._points(obs.pose[:, :2], obs.pose[:, 2])
        nb = obs.neighbours
        q = self._points(nb.position, nb.heading)
        delta, normal = pair_geometry(p, q)
        h, _ = barrier(delta, normal, self.pair_distance)
        pairs = BarrierRows(normal, -g * h / (2.0 * np.maximum(delta, MIN_DELTA)), nb.mask,
                            nb.index)
        near = self._nearest(p, obs.env)
        mv = obs.obstacles
        discs = np.concatenate([mv.position, mv.radius[..., None]], axis=-1)
        _, d_mv, n_mv = disc_nearest(p, discs)
        delta = np.concatenate([near.delta, d_mv], axis=1)
        normal = np.concatenate([near.normal, n_mv], axis=1)
        mask = np.concatenate([near.mask, mv.mask], axis=1)
        h, _ = barrier(np.where(mask, delta, 1.0), normal, self.obstacle_distance)
        # a moving disc's own velocity: dh/dt = grad . (u - v_o)
        v_obs = np.concatenate([np.zeros(near.normal.shape), mv.velocity], axis=1)
        bound = -g * h / (2.0 * np.maximum(np.abs(delta), MIN_DELTA)) \
            + np.einsum("nkc,nkc->nk", normal, v_obs)
        return pairs, BarrierRows(normal, np.where(mask, bound, -np.inf), mask, None)

    def filter(self, obs: Observation, nominal: np.ndarray) -> FilterResult:
        """Closest velocity to ``nominal`` (rows ``(vx, vy)``) within the barrier rows."""
        t0 = time.perf_counter()
        nominal = np.asarray(nominal, dtype=float)[:, :2]
        pairs, obstacles = self.rows(obs)
        if self.p.mode == "centralized":
            vel, status, slack = self._centralized(obs, nominal, pairs, obstacles)
        else:
            if self._solver == "exact":
                vel, status, slack = solve_distributed_exact(
                    nominal, pairs, obstacles, self._v_box, self._solver, self.p.infeasible,
                    self.p.max_obstacles)
            else:
                vel, status, slack = solve_distributed(nominal, pairs, obstacles, self._v_box,
                                                       self._solver, self.p.infeasible)
        per_robot = (time.perf_counter() - t0) / max(obs.n, 1)
        return FilterResult(vel, status, slack, np.full(obs.n, per_robot))

    def _centralized(self, obs: Observation, nominal: np.ndarray, pairs: BarrierRows,
                     obstacles: BarrierRows) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One centralized program per run (a batch's runs are solved apart)."""
        args = (self._v_box, self._solver, self.p.infeasible)
        if obs.env is None:
            return solve_centralized(nominal, pairs, obstacles, *args)
        out = []
        for e in np.unique(obs.env):
            rows = np.flatnonzero(obs.env == e)
            index = np.where(pairs.mask[rows], pairs.index[rows] - rows[0], -1)  # in the run
            out.append(solve_centralized(nominal[rows], _take(pairs, rows, index),
                                         _take(obstacles, rows, None), *args))
        vel, status, slack = (np.concatenate(part) for part in zip(*out, strict=True))
        return vel, status, slack


def _take(rows_of: BarrierRows, rows: np.ndarray, index: np.ndarray | None) -> BarrierRows:
    """The barrier rows of some robots, with ``index`` as their pair partners."""
    return BarrierRows(rows_of.normal[rows], rows_of.bound[rows], rows_of.mask[rows], index)
