"""The central planner of one run of ``reshape``: its mode, targets and assignment.

Every ``replan_period`` s the controller (:mod:`~comparisons.reshape.controller`)
hands each due run's own rows to that run's :class:`CentralPlanner`, which
picks the route, nominal or region mode (docs/methods/reshape.md, "The
programs") from the robots' positions as it hears them (:func:`heard_positions`:
their messages, ``Observation.team``, when messages are late or lost) and
leaves the run's targets, the assignment and the guidance waypoints. The three
modes are methods of the planner (they set its one plan state); the routes
themselves are :class:`~comparisons.reshape.routes.RoutePlanner`'s. Planning
is per run by nature: every run of a batch has its own planner, counters and
history, and runs of one static world share what is derived from that world
(:class:`RunMap`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from comparisons.reshape import planner
from comparisons.reshape.coordination import Coordination
from comparisons.reshape.region import grow_region, shape_segments, swept_disc_segments
from comparisons.reshape.routes import (
    ConfigurationSpace,
    Route,
    RoutePlanner,
    bin_heading,
    heading_bin,
)
from comparisons.reshape.tracking import Guidance, StuckMonitor
from dfcoa_opt.control.base import Observation
from dfcoa_opt.core.geometry import point_segment_distance, rotate
from dfcoa_opt.planning.pure_pursuit import PurePursuit
from dfcoa_opt.scenario.formation import line_offsets

if TYPE_CHECKING:
    from comparisons.reshape.params import ReshapeParams
    from dfcoa_opt.scenario.scenario import Scenario, World

FloatArray = NDArray[np.float64]
#: The nominal formation must also fit this far along the leader's path, m.
NOMINAL_AHEAD = 1.0
#: Smallest gap between two robots' discs in a template (sets the smallest scale), m.
GAP = 0.3


class LeaderPath(PurePursuit):
    """The leader's path as a polyline (only its geometry; the tracker's state is unused)."""

    def __init__(self, path: FloatArray) -> None:
        super().__init__(path, 0.0, 0.0, 0.0)

    def points_at(self, s: FloatArray) -> FloatArray:
        """``(K, 2)`` :meth:`point_at` of every arc length of ``s`` ``(K,)`` (m), at once."""
        s = np.asarray(s, dtype=float)
        if len(self.path) == 1:
            return np.repeat(self.path[:1], len(s), axis=0)
        s = np.minimum(np.maximum(s, 0.0), self.length)
        k = np.minimum(np.searchsorted(self._cum, s, side="right") - 1, len(self._seg_len) - 1)
        frac = (s - self._cum[k]) / self._seg_len[k]
        return self.path[k] + frac[:, None] * (self.path[k + 1] - self.path[k])


@dataclass(frozen=True)
class RunMap:
    """What a run's planner derives from its static world and leader path.

    Built once per scenario object: the runs of a batch share one unless the
    world follows the seed (a seeded clutter field). Every part answers the
    same whoever asks (the configuration spaces cache what they computed).

    Attributes:
        path: The leader's path (only its geometry is used).
        world: The static world.
        segments: ``(S, 2, 2)`` the static obstacles' edges, m.
        bounds: ``(xmin, xmax, ymin, ymax)`` of the map, m.
        guide: Free-segment tests and A* paths on the inflated map.
        cspace: Configuration space of the scenario's formation.
        single: That of one robot (single file), or None without the column.
    """

    path: LeaderPath
    world: World
    segments: FloatArray
    bounds: tuple[float, float, float, float]
    guide: Guidance
    cspace: ConfigurationSpace
    single: ConfigurationSpace | None

    @classmethod
    def build(cls, scenario: Scenario, offsets: FloatArray, rho: float, wide: float,
              column: bool, guide: float, goal_reach: float = 0.0,
              exact: bool = False) -> RunMap:
        """The map objects of ``scenario``.

        Args:
            scenario: The run's scenario.
            offsets: ``(N, 2)`` template offsets relative to the formation's centre, m.
            rho: Robot radius plus margin, m.
            wide: Extra clearance that routes keep where they can, m.
            column: Whether single file is a template (its configuration space).
            guide: The clearance of the guidance paths, m.
            goal_reach: :class:`~comparisons.reshape.tracking.Guidance`'s, m.
            exact: Measure the guidance clearance on the world's shapes, as the
                safety filter does, rather than between cell centres.
        """
        world = scenario.world
        grid = world.grid
        measure = (lambda p: world.clearance(p, cap=guide)) if exact else None
        return cls(LeaderPath(scenario.leader_path), world, shape_segments(world.shapes),
                   grid.extent, Guidance(grid, guide, goal_reach, measure),
                   ConfigurationSpace(grid, offsets, rho, wide),
                   ConfigurationSpace(grid, np.zeros((1, 2)), rho, wide) if column else None)


class CentralPlanner:
    """One run's planner (module docstring); its results are read by the controller.

    Args:
        p: The controller's parameters.
        scenario: The run's scenario.
        maps: Cache of :class:`RunMap` by scenario object (shared by a batch's runs).
        stuck: The batch's stuck-robot monitor.
        rows: This run's rows in ``stuck`` (``env * N`` on), robot order.
        pair_distance: Distance the safety filter keeps between two robots, m.
        obstacle_distance: Distance the safety filter keeps between a robot and an
            obstacle (``coordinate``: the least clearance of a guidance path), m.

    Attributes:
        counters: ``replans``, ``shrinks``, ``waits``, ``switches``, ``unsticks``
            (the last counted by the controller's tracking).
        plan_times: Wall time of every plan, s.
        history: ``(t, template, scale)`` of every plan (None when the formation waited).
    """

    def __init__(self, p: ReshapeParams, scenario: Scenario, maps: dict[int, RunMap],
                 stuck: StuckMonitor, rows: slice, pair_distance: float,
                 obstacle_distance: float = 0.0) -> None:
        self.p = p
        spec = scenario.spec
        self._n = scenario.n
        self._r = spec.robots.radius
        self._offsets = np.asarray(scenario.offsets, dtype=float)
        spacing = _spacing(self._offsets, self._r)
        column = np.column_stack([-spacing * np.arange(self._n), np.zeros(self._n)])
        every = {"scenario": self._offsets, "line": line_offsets(self._n, spacing),
                 "column": column}
        self._templates = {k: every[k] for k in p.templates if k in every}
        self._cost = {k: (0.0 if k == "scenario" else p.template_cost) for k in self._templates}
        half = 0.5 * (p.rotations - 1)
        self._rotations = (np.linspace(-p.rotation_max, p.rotation_max, p.rotations)
                           if half else np.zeros(1))
        floor = (2.0 * self._r + GAP) / _spacing(self._offsets, 0.0)  # 1 for a lone robot
        self._scales = np.linspace(1.0, min(1.0, max(p.s_min, floor)), p.scales)
        self._weights = planner.Weights(p.weight_progress, p.weight_scale, p.weight_rotation,
                                        p.switch_cost)
        self._spacing = spacing
        self._centre = self._offsets.mean(axis=0)
        if id(scenario) not in maps:
            rho = self._r + p.margin
            # reshape_passage's guidance keeps what the filter keeps, and reaches slots by walls
            guide, reach = (max(rho, obstacle_distance), 2.0 * rho) if p.coordinate else (rho, 0.0)
            maps[id(scenario)] = RunMap.build(scenario, self._offsets - self._centre, rho,
                                              p.route_clearance, "column" in self._templates,
                                              guide, reach, p.coordinate)
        m = maps[id(scenario)]
        self._path, self._world, self._segments = m.path, m.world, m.segments
        self._bounds, self._guide, self._cspace = m.bounds, m.guide, m.cspace
        self._extent = float(np.max(np.hypot(*(self._offsets - self._centre).T)))
        end = self._path.length
        self._goal_heading = self._tangent(end)
        self._goal_centre = self._path.point_at(end) + rotate(self._centre, self._goal_heading)
        self._routes = RoutePlanner(self._cspace, m.single, self._scales,
                                    self._spacing * (self._n - 1), self._goal_centre,
                                    p.route_detour, p.route_period, self._spacing)
        self._stuck, self._rows = stuck, rows
        self._keep = pair_distance + self._guide.inflated.cell_size
        self._targets = np.zeros((self._n, 2))
        self._nominal = True
        self._template: str | None = None
        self._assign = np.arange(self._n)
        self._waypoint: dict[int, FloatArray] = {}
        self._carried: FloatArray | None = None  # the targets in the leader's frame
        self.counters = {"replans": 0, "shrinks": 0, "waits": 0, "switches": 0, "unsticks": 0}
        self._coord = (Coordination(p.stuck_window, p.recover_time, p.lookahead, self._extent)
                       if p.coordinate else None)  # reshape_passage's layer
        if self._coord is not None:
            self.counters["recoveries"] = 0
        self.plan_times: list[float] = []
        self.history: list[tuple[float, str | None, float]] = []

    # ------------------------------------------------------------------- results
    @property
    def nominal(self) -> bool:
        """Whether every robot tracks its own slot on the leader (``goto_slot``)."""
        return self._nominal

    @property
    def targets(self) -> FloatArray:
        """``(N, 2)`` each robot's target, m (not used when :attr:`nominal`)."""
        return self._targets

    @property
    def carried(self) -> FloatArray | None:
        """``(N, 2)`` the targets in the leader's frame, m, when the plan moves with it."""
        return self._carried

    @property
    def waypoints(self) -> dict[int, FloatArray]:
        """Robot -> ``(2,)`` guidance waypoint (m) that replaces its target."""
        return self._waypoint

    # ------------------------------------------------------------------ planning
    def _tangent(self, s: float) -> float:
        """Heading (rad) of the leader's path around arc length ``s`` (m)."""
        a = self._path.point_at(max(0.0, min(s, self._path.length) - 0.5))
        b = self._path.point_at(min(self._path.length, max(s, 0.0) + 0.5))
        return math.atan2(b[1] - a[1], b[0] - a[0]) if np.any(b != a) else 0.0

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

    def plan(self, obs: Observation) -> None:
        """Choose the mode and set the targets, the assignment and the waypoints.

        Args:
            obs: The observation of this run alone: every robot, in robot order,
                and ``leader`` ``(5,)``. The robots' positions are read from
                ``team`` when it is given (:func:`heard_positions`).
        """
        t0 = time.perf_counter()
        self.counters["replans"] += 1
        pos = heard_positions(obs)
        centroid = pos.mean(axis=0)
        s_c = float(self._path.arc_length(centroid[None])[0])
        s_l = float(self._path.arc_length(obs.leader[None, :2])[0])
        k = heading_bin(self._tangent(s_c + self.p.lookahead))
        coord = self._coord
        if coord is not None and coord.watch(obs.t, s_c, pos, bool(obs.obstacles.mask.any())):
            self.counters["recoveries"] += 1
        # ahead of its leader (along the leader's path, or along its own way): to the slots
        past_leader = coord is not None and (s_c > s_l or coord.rejoining(obs.t))
        if not past_leader and (self._path_blocked(s_c, k) or (
                coord is not None and coord.holding(obs.t, s_c)
                and not coord.released(obs.slot, centroid))):
            if self._follow_route(obs, pos, centroid, k):
                self.plan_times.append(time.perf_counter() - t0)
                return
            past_leader = coord is not None and coord.rejoining(obs.t)
        self._routes.clear()
        if past_leader or (s_c + self.p.lookahead >= s_l and self._nominal_fits(obs, s_l)):
            self._nominal_plan(obs, pos)  # nothing in the way: the scenario's formation
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

    # ---------------------------------------------------------------- route mode
    def _path_blocked(self, s_c: float, k: int) -> bool:
        """Whether the scenario's formation, rigid at scale 1, hits a static obstacle ahead.

        Its centre is placed on the leader's path (heading bin ``k``) from the
        formation's progress ``s_c`` to ``lookahead`` plus its extent beyond.
        """
        end = min(s_c + self.p.lookahead + self._extent, self._path.length)
        s = np.append(np.arange(max(s_c, 0.0), end, 2.0 * self._guide.inflated.cell_size), end)
        lead = self._path.points_at(s)
        centres = lead + rotate(self._centre, bin_heading(k))
        free = self._cspace.free_at(centres, float(self._scales[-1]), k)
        if self._coord is not None and not free.all():  # on the route past the last block
            self._coord.blocked_to(float(s[~free][-1]))
        return not bool(free.all())

    def _follow_route(self, obs: Observation, pos: FloatArray, centroid: FloatArray,
                      k: int) -> bool:
        """Targets along the formation's route; False when there is none.

        The rigid formation at the route's scale, or single file, along the route
        of :class:`~comparisons.reshape.routes.RoutePlanner` (docs/methods/reshape.md,
        "1. Route"); the goal's formation once the goal is within reach.
        """
        way, way_scale = self._routes.update(obs.t, centroid, k)
        if way is None:
            return False
        here = way.project(centroid)
        head = 0.0 if way_scale is not None else 0.5 * self._spacing * (self._n - 1)
        coord = self._coord
        if coord is not None and way_scale is None:  # the column led by its front robot
            here = way.front(pos, self._spacing, here + head) - head
        centre, leader_near = self._route_centre(
            way, here, obs.leader, coord is not None and coord.uncapped(obs.t, obs.slot, centroid))
        if centre is None:  # less way left than its leader: it rejoins the slots
            assert coord is not None
            coord.rejoin(obs.t)
            return False
        ahead = centre + head
        at_goal = here + self.p.route_lead + head >= way.length and leader_near
        if at_goal:
            template, scale = "scenario", 1.0
            if self.p.coordinate:  # the goal's formation where the leader stops
                slots = obs.slot.copy()
            elif not self._cspace.free_at(self._goal_centre[None], 1.0,
                                          heading_bin(self._goal_heading))[0]:
                return False  # the goal within reach: the formation of the goal, if free
            else:
                slots = self._goal_centre + rotate(self._offsets - self._centre,
                                                   self._goal_heading)
        elif way_scale is not None:  # the scenario's shape, rigid, at the route's scale
            template, scale = "scenario", way_scale
            slots = way.point_at(ahead) + scale * rotate(self._offsets - self._centre,
                                                         bin_heading(k))
        else:  # single file along the route
            template, scale = "column", 1.0
            slots = way.along(ahead - self._spacing * np.arange(self._n))
        if template != self._template and self._template is not None:
            self.counters["switches"] += 1
        self.history.append((obs.t, template, scale))
        # a recovering team's route slots: who stands nearest goes (the goal's: each its own)
        reorder = coord is not None and coord.recovering(obs.t) and not at_goal
        before, self._assign = self._assign, self._assignment(pos, slots, template, reorder)
        if reorder and template == self._template:  # traded targets: not stuck on them yet
            self._stuck.restart(obs.t, self._rows.start + np.flatnonzero(before != self._assign))
        self._template, self._nominal, self._carried = template, False, None
        self._targets = slots[self._assign]
        self._waypoint = self._waypoints(obs.t, pos)
        return True

    def _route_centre(self, way: Route, here: float, leader: FloatArray,
                      uncapped: bool = False) -> tuple[float | None, bool]:
        """Arc length (m) along the route where the formation's centre is sent.

        ``route_lead`` beyond ``here`` (the centroid's projection on the route,
        m), but not past the leader's progress: the route point's arc length
        along the leader's path stays at most that of the centre of the leader's
        formation (and at least ``here``, so the formation never goes back). A
        column that crossed a doorway at ``v_max`` would otherwise get ahead of
        the leader and stand there, waiting for its slots; a formation that
        reached the goal long before the leader would stand there too. Once the
        leader's formation is within ``route_lead`` of the goal (the leader
        stops up to its settle tolerance short of the path's end), the cap is off.

        ``uncapped`` (a recovering team far behind,
        :meth:`~comparisons.reshape.coordination.Coordination.uncapped`): the cap
        by the path's arc length is off, and the target only keeps at least as
        much of the route ahead as the leader's formation has of its path. A
        route of another way than the leader's path can then no longer hold
        the team where it stands, and the team still cannot overtake.

        Returns:
            The arc length, and whether the cap is off (so the formation may take
            its goal slots). The arc length is None when ``uncapped`` and the
            route has less way left than the leader's formation has path: the
            team would stand still there (it rejoins its slots instead).
        """
        nominal = leader[:2] + rotate(self._centre, float(leader[2]))
        cap = float(self._path.arc_length(nominal[None])[0])
        arcs = here + np.linspace(0.0, self.p.route_lead, 9)
        progress = self._path.arc_length(np.vstack([way.along(arcs), self._goal_centre]))
        if cap + self.p.route_lead >= progress[-1]:
            return float(arcs[-1]), True
        if uncapped:  # as much route ahead as the leader's formation has path
            behind = np.flatnonzero(way.length - arcs >= self._path.length - cap - 1e-9)
            if not behind.size:  # less way left than the leader: waiting would stall the team
                return None, False
            return float(arcs[behind[-1]]), False
        within = np.flatnonzero(progress[:-1] <= cap + 1e-9)
        return (float(arcs[within[-1]]) if within.size else here), False

    # -------------------------------------------------------------- nominal mode
    def _nominal_plan(self, obs: Observation, pos: FloatArray) -> None:
        """The scenario's formation on the virtual leader (``goto_slot`` with the CBF filter).

        Args:
            obs: The run's observation (:meth:`plan`).
            pos: ``(N, 2)`` the robots' positions as the planner hears them, m.
        """
        if self._template not in (None, "scenario"):
            self.counters["switches"] += 1
        self.history.append((obs.t, "scenario", 1.0))
        self._template, self._nominal, self._carried = "scenario", True, None
        self._assign = np.arange(self._n)
        self._targets = obs.slot.copy()
        self._waypoint = self._waypoints(obs.t, pos)

    # ------------------------------------------------------------ every mode's
    def _waypoints(self, t: float, pos: FloatArray) -> dict[int, FloatArray]:
        """Guidance waypoints towards the targets (stuck robots: around the others too)."""
        return self._guide.waypoints(pos, self._targets, self._stuck.stuck(t, self._rows),
                                     self._keep, self._stuck.freed(t, self._rows))

    def _assignment(self, pos: FloatArray, slots: FloatArray, template: str,
                    reorder: bool = False) -> NDArray[np.intp]:
        """Robot i -> slot index (:func:`~comparisons.reshape.planner.assign`)."""
        return planner.assign(pos, slots, template, self._template, self._assign,
                              self.p.hysteresis, reorder)


def heard_positions(obs: Observation) -> FloatArray:
    """``(N, 2)`` each robot's position as the planner at the virtual leader has it, m.

    The planner hears the robots through their messages: ``obs.team`` (each
    robot's last message that reached it, ``comms.latency`` old or older)
    when messages are late or lost, else every robot's believed pose
    ``obs.pose`` (what the messages carry when they arrive at once).
    """
    return obs.pose[:, :2] if obs.team is None else obs.team[:, :2]


def _spacing(offsets: FloatArray, radius: float) -> float:
    """Nearest-neighbour distance of the scenario's slots, at least 2 radii + GAP, m."""
    if len(offsets) < 2:
        return 2.0 * radius + GAP
    d = np.linalg.norm(offsets[:, None] - offsets[None], axis=2)
    np.fill_diagonal(d, np.inf)
    return float(max(d.min(), 2.0 * radius + GAP))
