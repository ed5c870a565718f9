"""Checks of a scenario being loaded (:mod:`dfcoa_opt.scenario.loader`), beyond the per-key ones.

Registered names, waypoints only where they are used, free start and goal
cells, a goal in the start's free region, no goal slot within a robot radius
of an obstacle (:func:`final_leader_poses`), and sizes that fit in memory: a
map of at most :data:`MAX_CELLS` cells, every position and length within
:data:`MAX_EXTENT` m of the origin. Where the robots start and what the map
holds (simple polygons, obstacles in the map, starts inside it and apart) is
checked by :mod:`dfcoa_opt.scenario.placement`. Each raises
:class:`~dfcoa_opt.core.errors.ScenarioError` (one line: the file, the key, the
problem).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from dfcoa_opt.core.errors import ScenarioError
from dfcoa_opt.core.registry import ESTIMATORS, check_tables
from dfcoa_opt.planning.pure_pursuit import PurePursuit
from dfcoa_opt.planning.registry import PLANNERS
from dfcoa_opt.scenario.budget import CELL_BYTES, MAX_RUN_BYTES
from dfcoa_opt.scenario.formation import slot_positions
from dfcoa_opt.scenario.scenario import World
from dfcoa_opt.scenario.schema import ScenarioSpec
from dfcoa_opt.world.grid import OccupancyGrid


def check_names(spec: ScenarioSpec, source: str) -> None:
    """Registered planner, localization mode and controller override tables.

    The catalogues are the registries of :mod:`dfcoa_opt.core.registry` and
    :mod:`dfcoa_opt.planning.registry`; each asks only the entry point of the
    id it is given.
    """
    PLANNERS.check_name(spec.leader.planner, source, "leader.planner")
    ESTIMATORS.check_name(spec.localization.mode, source, "localization.mode")
    ESTIMATORS.options(spec.localization.mode, spec.localization.options, source,
                       "localization.options")
    check_tables(spec.controllers, source, spec.team.n)


def check_waypoints(spec: ScenarioSpec, source: str) -> None:
    """``leader.waypoints`` only with the ``straight`` planner, the one that uses them.

    The searching planners plan their own path from ``leader.start`` to
    ``leader.goal`` and would silently ignore the via points.
    """
    if spec.leader.waypoints and spec.leader.planner != "straight":
        raise ScenarioError(source, "leader.waypoints", f"only the 'straight' planner uses them; "
                                                        f"planner '{spec.leader.planner}' plans "
                                                        f"its own path and would ignore them")


#: Leader positions checked on the final approach, from where the leader stops to the goal.
GOAL_SAMPLES = 5
#: A goal slot this close to one robot radius from an obstacle counts as touching it, m: at
#: exactly one radius, rounding decides whether the simulator sees a contact.
GOAL_TOLERANCE = 1e-6
#: Arc length over which the leader's arrival heading is measured, m.
ARRIVAL_STEP = 1e-3


def final_leader_poses(path: np.ndarray, spec: ScenarioSpec, heading: float) -> np.ndarray:
    """Leader poses at which a run can end: the formation settles around one of these.

    The virtual leader (:class:`~dfcoa_opt.sim.leader.VirtualLeader`) stops as
    soon as it is within ``leader.goal_radius`` of ``leader.goal``. A leader
    that starts there never moves: its only final pose is the start with its
    initial heading. Otherwise it stops on the path's final stretch, about
    ``goal_radius`` of arc length before the goal (exactly so on a straight
    last segment), heading along the path there: the direction of the path's
    last :data:`ARRIVAL_STEP` before the stop point (on a straight last
    segment, its direction; not the direction of a few-cm hop from the last
    A* cell centre or via point to the exact goal, which the leader never
    drives). The poses returned run from the goal back to that stop point
    along the path (:data:`GOAL_SAMPLES` of them), all with that heading.
    The simulated leader stops near, not exactly at, that pose (pure pursuit
    cuts corners and stops at a Euclidean, not an arc-length, distance): on
    the shipped scenarios within 0.11 m and 1.2 degrees (``dfcoa_s1``,
    ``dfcoa_s2``; ``tests/test_goal_slots.py``).

    Args:
        path: ``(P, 2)`` planned leader path from ``leader.start`` to ``leader.goal``, m.
        spec: The scenario.
        heading: The leader's initial heading, rad.

    Returns:
        ``(K, 3)`` leader poses ``(x, y, theta)`` in m, m, rad.
    """
    lead = spec.leader
    start = np.asarray(lead.start, dtype=float)
    if np.hypot(*(start - np.asarray(lead.goal, dtype=float))) <= lead.goal_radius:
        return np.array([[*start, heading]])
    track = PurePursuit(path, lead.speed, lead.lookahead, lead.w_max)
    stop = max(track.length - lead.goal_radius, 0.0)
    d = track.point_at(stop) - track.point_at(stop - ARRIVAL_STEP)
    arrive = math.atan2(d[1], d[0]) if np.any(d) else heading
    return np.array([[*track.point_at(s), arrive]
                     for s in np.linspace(track.length, stop, GOAL_SAMPLES)])


def check_goal_clear(world: World, leader: np.ndarray, offsets: np.ndarray, spec: ScenarioSpec,
                      source: str) -> None:
    """No formation slot may lie within (or at) a robot radius of a static obstacle at the goal.

    The run succeeds only when every robot settles on its slot around the
    leader's final pose; a slot whose centre is within the robot radius of an
    obstacle (``World.clearance < radius``, the simulator's contact rule; at
    exactly one radius, within :data:`GOAL_TOLERANCE`, rounding decides) cannot
    be occupied without a contact (a robot could at best settle beside it,
    within ``settle_tolerance``, which is not the formation the file asks
    for). The slots are checked for every pose of :func:`final_leader_poses`.

    Args:
        world: The world (exact shapes, clutter and raster map).
        leader: ``(K, 3)`` final leader poses, :func:`final_leader_poses`.
        offsets: ``(N, 2)`` formation slot offsets, m.
        spec: The scenario.
        source: Name used in error messages.

    Raises:
        ScenarioError: Key ``leader.goal``, naming the first robot whose slot is too close.
    """
    radius = spec.robots.radius
    for pose in leader:
        xy = slot_positions(pose, offsets)
        clear = world.clearance(xy)
        for i in np.flatnonzero(clear <= radius + GOAL_TOLERANCE):
            x, y = xy[i]
            raise ScenarioError(source, "leader.goal", f"robot {i}'s formation slot at the goal "
                                                       f"({x:.5g}, {y:.5g}) is {clear[i]:.3g} m "
                                                       f"from an obstacle, within the robot "
                                                       f"radius {radius:g} m: no controller can "
                                                       f"settle there; move the goal")


def check_connected(grid: OccupancyGrid, spec: ScenarioSpec, source: str) -> None:
    """The goal must lie in the free region of the start, whatever the leader's planner.

    A grid A* (8-connected, no corner cutting) on the map: a few ms. Planners
    that search (``astar``) fail on their own; this catches the ``straight``
    planner's line through a wall that closes the goal off.
    """
    from dfcoa_opt.planning.astar import search

    start = tuple(int(v) for v in grid.world_to_cell(np.asarray(spec.leader.start, float)))
    goal = tuple(int(v) for v in grid.world_to_cell(np.asarray(spec.leader.goal, float)))
    if not search(grid.occupied, start, goal).found:
        raise ScenarioError(source, "leader.goal", "unreachable from leader.start: no free "
                                                   "path on the map joins them")


def check_free(grid: OccupancyGrid, point: Any, source: str, key: str) -> None:
    """``point`` (m) lies on a free cell inside the map (``key`` names it in the error)."""
    p = np.asarray(point, dtype=float)[:2]
    row, col = grid.world_to_cell(p)
    if not bool(grid.in_bounds(row, col)):
        x0, x1, y0, y1 = grid.extent
        raise ScenarioError(source, key, f"({p[0]:g}, {p[1]:g}) is outside the map "
                                         f"[{x0:g}, {x1:g}] x [{y0:g}, {y1:g}] m")
    if grid.occupied[row, col]:
        raise ScenarioError(source, key, f"({p[0]:g}, {p[1]:g}) is inside an obstacle")


def check_extents(spec: ScenarioSpec, offsets: np.ndarray, source: str) -> None:
    """Every length and position of the file lies within :data:`MAX_EXTENT` of the origin.

    Far-away values are mistakes (a missing decimal point, a unit slip), and
    squaring them would overflow inside the geometry.

    Raises:
        ScenarioError: Names the first key with a value beyond the limit.
    """
    items: list[tuple[str, Any]] = [("leader.start", spec.leader.start),
                                    ("leader.goal", spec.leader.goal),
                                    ("team.poses", [p[:2] for p in spec.team.poses]),
                                    ("formation", offsets)]
    for i, o in enumerate(spec.world.obstacles):
        items += [(f"world.obstacles[{i}].{name}", getattr(o, name))
                  for name in ("center", "radius", "min", "max", "vertices")]
    for i, d in enumerate(spec.world.dynamic_obstacles):
        items += [(f"world.dynamic_obstacles[{i}].radius", d.radius),
                  (f"world.dynamic_obstacles[{i}].waypoints", d.waypoints)]
    for key, value in items:
        values = np.asarray(value if value is not None else (), dtype=float)
        if not np.all(np.abs(values) <= MAX_EXTENT):
            shown = value if key != "formation" else "the slot offsets"
            raise ScenarioError(source, key, f"{shown} reach beyond the {MAX_EXTENT:g} m "
                                             f"this toolkit accepts")


#: Largest map, in cells: what fits in a run's memory budget (2 GiB at
#: :data:`~dfcoa_opt.scenario.budget.CELL_BYTES` a cell: 33,554,432 cells, e.g. 579 m x 579 m at
#: 10 cells/m). A map file is held to it from its header, ``world.size`` by the budget.
MAX_CELLS = MAX_RUN_BYTES // CELL_BYTES
#: Largest coordinate of the map's corners, m.
MAX_EXTENT = 1e6


def check_cells(size: tuple[float, float], resolution: float, source: str) -> None:
    """Refuse a ``world.size`` whose grid would not fit in memory, before allocating it.

    Raises:
        ScenarioError: More than :data:`MAX_CELLS` cells.
    """
    cells = [s * resolution for s in size]
    total = math.prod(max(1.0, c) for c in cells)
    if not total <= MAX_CELLS:
        raise ScenarioError(source, "world.size", f"{size[0]:g} x {size[1]:g} m at "
                            f"{resolution:g} cells/m is {cells[0]:.3g} x {cells[1]:.3g} cells, "
                            f"more than the {MAX_CELLS:.0e} this toolkit accepts")
