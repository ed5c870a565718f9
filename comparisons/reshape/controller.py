"""``reshape``: a formation that changes its shape, size and place to get through.

Beyond the papers (after Alonso-Mora, Baker & Rus, IJRR 2017: a formation
optimised inside a convex obstacle-free region). Every ``replan_period`` s a
central planner, from the robots' broadcast positions, takes the formation's
progress ``s_c`` along the leader's path (the centroid's nearest path point)
and picks one of three modes (docs/methods/reshape.md):

1. **route** -- the leader's path ahead is blocked for the scenario's
   formation even at the smallest scale (a wall, a circle on the line, a
   clutter field): the rigid formation follows an A* route in its own
   configuration space at the largest scale whose route is within
   ``route_detour`` of the quickest passage, or goes in single file along a
   one-robot route (:mod:`~comparisons.reshape.routes`);
2. **nominal** -- the formation keeps up with the leader and fits on it now
   and 1 m on: every robot to its own slot with the leader's feed-forward
   (``goto_slot`` through the filter);
3. **region** -- otherwise: a convex free region grown around the segment
   from the centroid to the look-ahead goal ``g``
   (:mod:`~comparisons.reshape.region`; static shapes and the sensed moving
   discs swept over ``horizon`` s), and the template, rotation, scale and
   position chosen in it (:mod:`~comparisons.reshape.planner`). When nothing
   fits, the look-ahead is halved (twice), then the formation waits on its
   previous plan: counted as ``shrinks`` and ``waits``.

Robots take their own slots in the scenario's shape (success is judged on
those) and the Hungarian assignment otherwise, kept unless a new one is
``hysteresis`` cheaper. Tracking is distributed
(:mod:`~comparisons.reshape.tracking`): each robot drives to its target (to a
waypoint of its A* path when its line is blocked) with a proportional velocity
through the ``cbf`` filter; a robot held still away from its target has its
command turned (``unsticks``). Broadcast per plan: the mode and template id,
``t`` (2 floats), ``theta``, ``s`` and the assignment (N integers) -- 4 N + 24
bytes. The counters are in the run's metrics as ``ctl_*``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment

from comparisons.cbf.filter import CbfFilter
from comparisons.reshape import planner
from comparisons.reshape.region import grow_region, shape_segments, swept_disc_segments
from comparisons.reshape.route_mode import RouteMode
from comparisons.reshape.routes import ConfigurationSpace, RoutePlanner, heading_bin
from comparisons.reshape.tracking import Guidance, StuckMonitor
from dfcoa_opt.control.base import FilterResult, Observation, slot_velocity
from dfcoa_opt.control.registry import register
from dfcoa_opt.formation import line_offsets
from dfcoa_opt.geometry import point_segment_distance, rotate
from dfcoa_opt.params import param
from dfcoa_opt.planning.pure_pursuit import PurePursuit

FloatArray = NDArray[np.float64]
#: The nominal formation must also fit this far along the leader's path, m.
NOMINAL_AHEAD = 1.0
#: Smallest gap between two robots' discs in a template (sets the smallest scale), m.
GAP = 0.3


@register("reshape")
class Reshape(RouteMode):
    """Reshaping formation: free region, template choice, assignment, CBF tracking."""

    command = "velocity"
    uses_scan = False

    @dataclass(frozen=True)
    class Params:
        """Parameters of ``reshape`` (``[controllers.reshape]``)."""

        replan_period: float = param(0.5, doc="Time between two plans.", unit="s", gt=0.0)
        lookahead: float = param(3.0, doc="Look-ahead along the leader's path beyond the "
                                          "formation's progress.", unit="m", gt=0.0)
        s_min: float = param(0.5, doc="Smallest scale of a template (raised so that the "
                                      "scaled slots keep 0.3 m between robots).", gt=0.0, le=1.0)
        scales: int = param(4, doc="Scales tried in [s_min, 1].", ge=1)
        rotation_max: float = param(math.pi / 3, doc="Largest rotation tried either side of "
                                                     "the look-ahead direction.", unit="rad",
                                    ge=0.0)
        rotations: int = param(5, doc="Rotations tried (odd: includes 0).", ge=1)
        templates: tuple[str, ...] = param(("scenario", "line", "column"),
                                           doc="Templates: 'scenario' (the file's shape), "
                                               "'line' (abreast), 'column' (single file).")
        template_cost: float = param(1.0, doc="Cost of a template other than the scenario's.")
        margin: float = param(0.1, doc="Clearance kept beyond the robot radius in the region.",
                              unit="m", ge=0.0)
        horizon: float = param(2.0, doc="Moving discs are swept over this time.", unit="s",
                               ge=0.0)
        hysteresis: float = param(0.1, doc="A new assignment must be this fraction cheaper.",
                                  ge=0.0, lt=1.0)
        gamma: float = param(5.0, doc="Class-K gain of the CBF tracking filter (the filter "
                                      "caps it at 1/dt).", unit="1/s", gt=0.0)
        kp: float = param(1.0, doc="Proportional gain towards the target.", unit="1/s", gt=0.0)
        weight_progress: float = param(1.0, doc="Cost weight of |t - g|^2.", unit="1/m^2",
                                       ge=0.0)
        weight_scale: float = param(4.0, doc="Cost weight of (1 - s)^2.", ge=0.0)
        weight_rotation: float = param(0.5, doc="Cost weight of the rotation squared.",
                                       unit="1/rad^2", ge=0.0)
        switch_cost: float = param(0.5, doc="Cost of changing template.", ge=0.0)
        route_detour: float = param(0.1, doc="A route of a larger scale may be this fraction "
                                             "longer than the quickest passage.", ge=0.0)
        route_clearance: float = param(0.3, doc="Extra distance a formation route keeps from "
                                                "obstacles where it can.", unit="m", ge=0.0)
        route_lead: float = param(1.0, doc="On a route, the slots lead the formation's centre "
                                           "(single file: its middle) by this much.", unit="m",
                                  gt=0.0)
        unstick_time: float = param(3.0, doc="A robot that stayed within 0.1 m of one point "
                                            "this long, away from its target, is stuck.",
                                    unit="s", gt=0.0)
        unstick_angle: float = param(math.pi / 3, doc="A stuck robot's command is turned by "
                                                      "this (counter-clockwise).", unit="rad")
        route_period: float = param(2.0, doc="Time between two route searches while the "
                                             "formation stays on its route.", unit="s", gt=0.0)

    def __init__(self, params: Params) -> None:
        self.p = params
        self.safety: CbfFilter | None = None  # built by reset (it needs the robots' v_max)
        self.last_result: FilterResult | None = None
        self.counters: dict[str, int] = {}
        self.plan_times: list[float] = []
        #: ``(t, template, scale)`` of every plan (None when the formation waited).
        self.history: list[tuple[float, str | None, float]] = []

    # ---------------------------------------------------------------------- set-up
    def reset(self, scenario, rng: np.random.Generator) -> None:
        """Read the team, the map and the leader's path; build the templates."""
        spec = scenario.spec
        # the box |u_x|, |u_y| <= v_max (the filter's default, v_max / sqrt 2, would hold
        # a formation moving along an axis to 71 % of its speed), the result clipped to
        # |u| <= v_max afterwards: a uniform saturation, which keeps every barrier row
        self.safety = CbfFilter(CbfFilter.Params(solver="exact", v_max=spec.robots.v_max,
                                                 gamma=self.p.gamma), owner="reshape")
        self.safety.reset(scenario, rng)
        self._n = scenario.n
        self._r = spec.robots.radius
        self._v_max = spec.robots.v_max
        self._offsets = np.asarray(scenario.offsets, dtype=float)
        spacing = _spacing(self._offsets, self._r)
        column = np.column_stack([-spacing * np.arange(self._n), np.zeros(self._n)])
        every = {"scenario": self._offsets, "line": line_offsets(self._n, spacing),
                 "column": column}
        self._templates = {k: every[k] for k in self.p.templates if k in every}
        self._cost = {k: (0.0 if k == "scenario" else self.p.template_cost)
                      for k in self._templates}
        self._path = PurePursuit(scenario.leader_path, 0.0, 0.0, 0.0)
        self._world = scenario.world
        self._segments = shape_segments(scenario.world.shapes)
        self._bounds = scenario.world.grid.extent
        self._guide = Guidance(scenario.world.grid, self._r + self.p.margin)
        half = 0.5 * (self.p.rotations - 1)
        self._rotations = (np.linspace(-self.p.rotation_max, self.p.rotation_max,
                                       self.p.rotations) if half else np.zeros(1))
        floor = (2.0 * self._r + GAP) / _spacing(self._offsets, 0.0)  # 1 for a lone robot
        self._scales = np.linspace(1.0, min(1.0, max(self.p.s_min, floor)), self.p.scales)
        self._weights = planner.Weights(self.p.weight_progress, self.p.weight_scale,
                                        self.p.weight_rotation, self.p.switch_cost)
        self._spacing = spacing
        self._centre = self._offsets.mean(axis=0)
        rho = self._r + self.p.margin
        grid, wide = scenario.world.grid, self.p.route_clearance
        self._cspace = ConfigurationSpace(grid, self._offsets - self._centre, rho, wide)
        self._extent = float(np.max(np.hypot(*(self._offsets - self._centre).T)))
        end = self._path.length
        self._goal_heading = self._tangent(end)
        self._goal_centre = self._path.point_at(end) + rotate(self._centre, self._goal_heading)
        single = (ConfigurationSpace(grid, np.zeros((1, 2)), rho, wide)
                  if "column" in self._templates else None)
        self._routes = RoutePlanner(self._cspace, single, self._scales,
                                    self._spacing * (self._n - 1), self._goal_centre,
                                    self.p.route_detour, self.p.route_period, self._spacing)
        self._next = 0.0
        self._targets = np.zeros((self._n, 2))
        self._nominal = True
        self._template: str | None = None
        self._assign = np.arange(self._n)
        self._waypoint: dict[int, FloatArray] = {}
        self._carried: FloatArray | None = None  # the targets in the leader's frame
        self.counters = {"replans": 0, "shrinks": 0, "waits": 0, "switches": 0, "unsticks": 0}
        self._stuck = StuckMonitor(np.asarray(scenario.initial_pose, float)[:, :2],
                                   self.p.unstick_time, self.p.unstick_angle)
        self.plan_times = []
        self.history = []
        self.last_result = None

    # ------------------------------------------------------------------- planning
    @staticmethod
    def _moving(obs: Observation) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Position, velocity and radius of each sensed moving disc, once (m, m/s, m)."""
        m = obs.obstacles
        pos, vel, rad = m.position[m.mask], m.velocity[m.mask], m.radius[m.mask]
        keys = np.round(np.column_stack([pos, rad]), 6)  # several robots sense one disc
        _, first = np.unique(keys, axis=0, return_index=True)
        return pos[first], vel[first], rad[first]

    def _moving_segments(self, obs: Observation) -> FloatArray:
        if not obs.obstacles.mask.any():
            return np.zeros((0, 2, 2))
        return swept_disc_segments(*self._moving(obs), self.p.horizon)

    def _nominal_fits(self, obs: Observation, s_l: float) -> bool:
        """Whether the scenario's formation fits on the leader, now and ``NOMINAL_AHEAD`` on.

        Every slot keeps ``r + margin`` from the static obstacles and from each
        sensed moving disc's sweep over ``horizon``.
        """
        ahead = min(s_l + NOMINAL_AHEAD, self._path.length)
        later = self._path.point_at(ahead) + rotate(self._offsets, self._tangent(ahead))
        slots = np.concatenate([obs.slot, later])
        need = self._r + self.p.margin
        if not bool(np.all(self._world.clearance(slots, cap=need) >= need)):  # cap: same answer
            return False
        if not obs.obstacles.mask.any():
            return True
        pos, vel, rad = self._moving(obs)
        gap = point_segment_distance(slots[:, None], pos[None], (pos + self.p.horizon * vel)[None])
        return bool(np.all(gap >= need + rad[None]))

    def _plan(self, obs: Observation) -> None:
        t0 = time.perf_counter()
        self.counters["replans"] += 1
        pos = obs.pose[:, :2]
        centroid = pos.mean(axis=0)
        s_c = float(self._path.arc_length(centroid[None])[0])
        s_l = float(self._path.arc_length(obs.leader[None, :2])[0])
        k = heading_bin(self._tangent(s_c + self.p.lookahead))
        if self._path_blocked(s_c, k) and self._follow_route(obs, pos, centroid, k):
            self.plan_times.append(time.perf_counter() - t0)
            return
        self._routes.clear()
        if s_c + self.p.lookahead >= s_l and self._nominal_fits(obs, s_l):
            self._nominal_plan(obs)  # nothing in the way: the scenario's formation
            self.plan_times.append(time.perf_counter() - t0)
            return
        segments = np.concatenate([self._segments, self._moving_segments(obs)])
        start = centroid if self._guide.free(centroid, centroid, self._r) else \
            self._path.point_at(s_c)
        cand = None
        for shrink in (1.0, 0.5, 0.25):
            following = s_c + shrink * self.p.lookahead >= s_l
            goal = obs.leader[:2].copy() if following else \
                self._path.point_at(s_c + shrink * self.p.lookahead)
            if not self._guide.free(start, goal, self._r + self.p.margin):
                goal = self._guide.point_along(start, goal, shrink * self.p.lookahead)
            end = goal.copy()
            for _ in range(8):  # shorten the seed until it is free
                if self._guide.free(start, end, 0.5 * self._r):
                    break
                end = 0.5 * (start + end)
            seed = np.array([start, end])
            psi = (float(obs.leader[2]) if following or math.hypot(*(end - start)) < 0.2
                   else math.atan2(*(end - start)[::-1]))
            region = grow_region(seed, segments, self._bounds)
            cand = planner.choose(region, self._templates, self._cost, goal, psi, self._rotations,
                                  self._scales, self._r + self.p.margin, self._template,
                                  self._weights)
            if cand is not None:
                break
            self.counters["shrinks"] += 1
        self._carried = None
        if cand is None:
            self.counters["waits"] += 1
            self.history.append((obs.t, None, math.nan))
            if self._template is None:
                self._targets, self._nominal = pos.copy(), False
            self.plan_times.append(time.perf_counter() - t0)
            return
        self.history.append((obs.t, cand.template, cand.scale))
        slots = cand.slots(self._templates[cand.template])
        self._nominal = (cand.template == "scenario" and cand.scale == 1.0
                         and abs(cand.theta - float(obs.leader[2])) < 1e-12
                         and bool(np.allclose(cand.t, obs.leader[:2])))
        if cand.template != self._template and self._template is not None:
            self.counters["switches"] += 1
        self._assign = self._assignment(pos, slots, cand.template)
        self._template = cand.template
        self._targets = slots[self._assign]
        # keeping up with the leader: the plan moves with it until the next one
        self._carried = (rotate(self._targets - obs.leader[:2], -float(obs.leader[2]))
                         if following and not self._nominal else None)
        self._waypoint = self._waypoints(obs.t, pos)
        self.plan_times.append(time.perf_counter() - t0)

    def _nominal_plan(self, obs: Observation) -> None:
        """The scenario's formation on the virtual leader (``goto_slot`` with the CBF filter)."""
        if self._template not in (None, "scenario"):
            self.counters["switches"] += 1
        self.history.append((obs.t, "scenario", 1.0))
        self._template, self._nominal, self._carried = "scenario", True, None
        self._assign = np.arange(self._n)
        self._targets = obs.slot.copy()
        self._waypoint = self._waypoints(obs.t, obs.pose[:, :2])

    def _waypoints(self, t: float, pos: FloatArray) -> dict[int, FloatArray]:
        """Guidance waypoints towards the targets (stuck robots: around the others too)."""
        assert self.safety is not None, "reset() first"
        keep = self.safety.pair_distance + self._guide.inflated.cell_size
        return self._guide.waypoints(pos, self._targets, self._stuck.stuck(t), keep,
                                     self._stuck.freed(t))

    def _assignment(self, pos: FloatArray, slots: FloatArray, template: str) -> NDArray[np.intp]:
        """Robot i -> slot index: its own for the scenario's template, else Hungarian."""
        if template == "scenario":
            return np.arange(self._n)
        cost = np.sum((pos[:, None, :] - slots[None]) ** 2, axis=2)
        _, best = linear_sum_assignment(cost)
        keep = self._assign
        if template == self._template and \
                cost[np.arange(self._n), keep].sum() <= (1.0 + self.p.hysteresis) * \
                cost[np.arange(self._n), best].sum():
            return keep
        return best

    def act(self, obs: Observation) -> FloatArray:
        """Replan when due (central), then every robot to its target through the CBF filter."""
        if obs.t >= self._next - 1e-9:
            self._plan(obs)
            self._next = obs.t + self.p.replan_period
        pos = obs.pose[:, :2]
        ids = obs.robot_ids
        if self._nominal:
            target = obs.slot.copy()
            ff = slot_velocity(obs.leader, target)
        elif self._carried is None:
            target = self._targets[ids].copy()
            ff = np.zeros_like(target)
        else:  # a plan made while keeping up: carried along in the leader's frame
            target = obs.leader[:2] + rotate(self._carried[ids], float(obs.leader[2]))
            ff = slot_velocity(obs.leader, target)
        for row, i in enumerate(ids):
            if int(i) in self._waypoint:
                target[row], ff[row] = self._waypoint[int(i)], 0.0
        u = self.p.kp * (target - pos) + ff
        u, turned = self._stuck.turn(obs.t, ids, pos, target, u)
        self.counters["unsticks"] += turned
        speed = np.hypot(u[:, 0], u[:, 1])
        u = u * np.minimum(1.0, self._v_max / np.maximum(speed, 1e-12))[:, None]
        assert self.safety is not None, "reset() first"
        res = self.safety.filter(obs, u)
        speed = np.hypot(res.command[:, 0], res.command[:, 1])
        over = speed > self._v_max
        if over.any():
            res.command[over] *= (self._v_max / speed[over])[:, None]
        self.last_result = res
        return res.command


def _spacing(offsets: FloatArray, radius: float) -> float:
    """Nearest-neighbour distance of the scenario's slots, at least 2 radii + GAP, m."""
    if len(offsets) < 2:
        return 2.0 * radius + GAP
    d = np.linalg.norm(offsets[:, None] - offsets[None], axis=2)
    np.fill_diagonal(d, np.inf)
    return float(max(d.min(), 2.0 * radius + GAP))
