"""The route mode of ``reshape``: the rigid formation, or single file, along a route.

A mixin of :class:`~comparisons.reshape.central.CentralPlanner`, one run's
planner (it uses the planner's map, leader path, templates and route planner,
set by its constructor). The mode is in docs/methods/reshape.md, "1. Route".
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from comparisons.reshape.routes import Route, bin_heading, heading_bin
from dfcoa_opt.control.base import Observation
from dfcoa_opt.core.geometry import rotate

FloatArray = NDArray[np.float64]


class RouteMode:
    """Route-mode methods of ``CentralPlanner`` (see the module docstring)."""

    def _tangent(self, s: float) -> float:
        """Heading (rad) of the leader's path around arc length ``s`` (m)."""
        a = self._path.point_at(max(0.0, min(s, self._path.length) - 0.5))
        b = self._path.point_at(min(self._path.length, max(s, 0.0) + 0.5))
        return math.atan2(b[1] - a[1], b[0] - a[0]) if np.any(b != a) else 0.0

    def _path_blocked(self, s_c: float, k: int) -> bool:
        """Whether the scenario's formation, rigid at scale 1, hits a static obstacle ahead.

        Its centre is placed on the leader's path (heading bin ``k``) from the
        formation's progress ``s_c`` to ``lookahead`` plus its extent beyond.
        """
        end = min(s_c + self.p.lookahead + self._extent, self._path.length)
        s = np.append(np.arange(max(s_c, 0.0), end, 2.0 * self._guide.inflated.cell_size), end)
        lead = self._path.points_at(s)
        centres = lead + rotate(self._centre, bin_heading(k))
        return not bool(self._cspace.free_at(centres, float(self._scales[-1]), k).all())

    def _follow_route(self, obs: Observation, pos: FloatArray, centroid: FloatArray,
                      k: int) -> bool:
        """Targets along the formation's route (module docstring); False when there is none."""
        way, way_scale = self._routes.update(obs.t, centroid, k)
        if way is None:
            return False
        here = way.project(centroid)
        head = 0.0 if way_scale is not None else 0.5 * self._spacing * (self._n - 1)
        centre, leader_near = self._route_centre(way, here, obs.leader)
        ahead = centre + head
        if here + self.p.route_lead + head >= way.length and leader_near:
            # the goal within reach: the formation of the goal, if free
            if not self._cspace.free_at(self._goal_centre[None], 1.0,
                                        heading_bin(self._goal_heading))[0]:
                return False
            template, scale = "scenario", 1.0
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
        self._assign = self._assignment(pos, slots, template)
        self._template, self._nominal, self._carried = template, False, None
        self._targets = slots[self._assign]
        self._waypoint = self._waypoints(obs.t, pos)
        return True

    def _route_centre(self, way: Route, here: float, leader: FloatArray) -> tuple[float, bool]:
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

        Returns:
            The arc length, and whether the cap is off (so the formation may take
            its goal slots).
        """
        nominal = leader[:2] + rotate(self._centre, float(leader[2]))
        cap = float(self._path.arc_length(nominal[None])[0])
        arcs = here + np.linspace(0.0, self.p.route_lead, 9)
        progress = self._path.arc_length(np.vstack([way.along(arcs), self._goal_centre]))
        if cap + self.p.route_lead >= progress[-1]:
            return float(arcs[-1]), True
        within = np.flatnonzero(progress[:-1] <= cap + 1e-9)
        return (float(arcs[within[-1]]) if within.size else here), False
