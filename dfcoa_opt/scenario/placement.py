"""Checks of where things are in a scenario (:mod:`dfcoa_opt.scenario.loader`).

Simple polygons (no crossing or touching edges, no repeated vertex), no
obstacle wholly outside the map, the leader's start, goal and via points on
free cells inside the map, a goal in the start's free region, no goal slot
within a robot radius of an obstacle (:func:`final_leader_poses`), every robot
starting inside the map (formation slots too), no two robots starting
overlapping unless ``team.allow_start_contact``, and no robot starting on a
formation slot inside an obstacle. Each raises
:class:`~dfcoa_opt.core.errors.ScenarioError` (one line: the file, the key, the
problem).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from dfcoa_opt.core.errors import ScenarioError
from dfcoa_opt.core.geometry import points_in_polygon
from dfcoa_opt.core.polygons import polygon_defect, segments_intersect
from dfcoa_opt.planning.pure_pursuit import PurePursuit
from dfcoa_opt.scenario.formation import slot_positions
from dfcoa_opt.scenario.scenario import World
from dfcoa_opt.scenario.schema import ScenarioSpec
from dfcoa_opt.world.grid import OccupancyGrid
from dfcoa_opt.world.shapes import Circle, Rectangle, Shape, describe_defect
from dfcoa_opt.world.spec import ObstacleSpec


def check_start_clear(world: World, pose: Any, spec: ScenarioSpec, source: str) -> None:
    """No robot may start on a formation slot inside a static obstacle: an error, not a warning.

    With the default placement the robots start on their formation slots around
    ``leader.start``; a slot inside an obstacle would start the run inside it,
    which no controller can repair. Measured exactly on the shapes
    (``World.clearance``), not on the grid. A robot whose *body* merely
    overlaps an obstacle at the start is allowed (some tests start robots
    close to walls on purpose); the simulator counts that contact at t = 0.
    """
    if spec.team.placement == "explicit":
        return  # team.poses were checked on the (fatter) grid by check_free
    clear = world.clearance(np.asarray(pose, dtype=float)[:, :2])
    for i in np.flatnonzero(clear <= 0.0):
        x, y = pose[i][0], pose[i][1]
        raise ScenarioError(source, "formation", f"robot {i} starts on its slot ({x:g}, {y:g}), "
                                                 f"inside an obstacle; move leader.start or "
                                                 f"the formation")


def _formation_key(spec: ScenarioSpec) -> str:
    """The key that sets the slots' scale.

    ``formation.spacing`` (v, line, grid), ``formation.offsets`` (offsets,
    polar) or ``formation`` (a rectangle: its width and length).
    """
    shape = spec.formation.shape
    if shape in ("v", "line", "grid"):
        return "formation.spacing"
    return "formation.offsets" if shape in ("offsets", "polar") else "formation"


def _robots(index: np.ndarray) -> str:
    """``"robot 3"``, ``"robots 1, 2 and 4"``, ``"robots 1, 2, 3 and 97 more"``."""
    k = [str(int(i)) for i in index]
    if len(k) == 1:
        return f"robot {k[0]}"
    if len(k) <= 4:
        return f"robots {', '.join(k[:-1])} and {k[-1]}"
    return f"robots {', '.join(k[:3])} and {len(k) - 3} more"


def check_start_poses(grid: OccupancyGrid, pose: Any, spec: ScenarioSpec, source: str) -> None:
    """Every robot starts inside the map, and no two overlap (unless the file allows it).

    The noise-free start poses (``team.start_noise`` only moves a robot to a
    free cell inside the map at run time, :meth:`~dfcoa_opt.scenario.scenario.Scenario.start_pose`):

    - *inside the map*: on a cell of the grid, the rule of :func:`check_free`
      (explicit ``team.poses`` and ``team.start_behind`` are checked by it in the
      loader; here, the formation slots around ``leader.start``), never allowed
      otherwise: outside the map the LiDAR sees nothing and the grid planners
      cannot help;
    - *no overlap*: no two centres closer than ``2 * robots.radius`` (the
      simulator's contact rule, the same distance formula: such a run starts
      with contacts at t = 0), unless ``team.allow_start_contact`` is true. Found
      through each robot's nearest neighbour (a k-d tree), so 100,000 robots on
      one point cost no more than spread ones.

    Args:
        grid: The map.
        pose: ``(N, 3)`` the noise-free start poses, m, m, rad.
        spec: The scenario.
        source: Name used in error messages.

    Raises:
        ScenarioError: Key ``formation.spacing`` / ``formation.offsets`` / ``formation``
            for slots, ``team.poses[j]`` for explicit poses, naming the robots and the numbers.
    """
    xy = np.asarray(pose, dtype=float).reshape(-1, 3)[:, :2]
    explicit = spec.team.placement == "explicit"
    key = _formation_key(spec)
    if not explicit:
        out = np.flatnonzero(~grid.in_bounds(*grid.world_to_cell(xy)))
        if len(out):
            x0, x1, y0, y1 = grid.extent
            (x, y), (lx, ly) = xy[out[0]], spec.leader.start
            reach = float(np.max(np.hypot(*(xy - np.asarray(spec.leader.start)).T)))
            raise ScenarioError(source, key, f"{_robots(out)} would start outside the map "
                                f"[{x0:g}, {x1:g}] x [{y0:g}, {y1:g}] m (robot {out[0]} at "
                                f"({x:.6g}, {y:.6g}); the slots reach {reach:.6g} m from "
                                f"leader.start ({lx:g}, {ly:g})); shrink the formation or "
                                f"move leader.start")
    if spec.team.allow_start_contact or len(xy) < 2:
        return
    from scipy.spatial import cKDTree

    _, near = cKDTree(xy).query(xy, k=2)
    rows = np.arange(len(xy))
    other = np.where(near[:, 0] != rows, near[:, 0], near[:, 1])  # coincident: either order
    d = xy[other] - xy
    dist = np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1])  # the simulator's formula
    contact = 2.0 * spec.robots.radius
    hit = np.flatnonzero(dist < contact)
    if not len(hit):
        return
    i, j = sorted((int(hit[0]), int(other[hit[0]])))
    where = (f"at ({xy[i, 0]:.6g}, {xy[i, 1]:.6g}) and ({xy[j, 0]:.6g}, {xy[j, 1]:.6g}) "
             f"m, {dist[hit[0]]:.6g} m apart")
    also = f" ({len(hit)} robots overlap another)" if len(hit) > 2 else ""
    fix = ("move them apart" if explicit else
           "widen the formation" if key != "formation" else "widen formation.width/length")
    raise ScenarioError(source, f"team.poses[{j}]" if explicit else key,
                        f"robots {i} and {j} would start overlapping, "
                        f"{'' if explicit else 'on their slots '}{where}, closer than "
                        f"2 x robots.radius = {contact:g} m{also}; {fix}, or set "
                        f"team.allow_start_contact = true if they start in contact on purpose")


def check_via_points(grid: OccupancyGrid, spec: ScenarioSpec, source: str) -> None:
    """Each of ``leader.waypoints`` lies on a free cell inside the map (:func:`check_free`).

    The rule of ``leader.start`` and ``leader.goal``: the ``straight`` planner
    drives the leader through every via point, whatever the map.
    """
    for k, w in enumerate(spec.leader.waypoints):
        check_free(grid, w, source, f"leader.waypoints[{k}]")


def check_polygons(obstacles: Sequence[ObstacleSpec], source: str) -> None:
    """Every ``polygon`` obstacle is simple (:func:`~dfcoa_opt.core.polygons.polygon_defect`).

    A polygon whose edges cross or touch, or that repeats a vertex, is not
    the obstacle the file means: its signed area can still be positive (so
    the counter-clockwise check passes), while the rasterised grid (even-odd
    rule), the exact clearance and the velocity obstacles each see a
    different shape. Checked before the shapes are built
    (:class:`~dfcoa_opt.world.shapes.Polygon` refuses such a polygon too, without the key).

    Raises:
        ScenarioError: Key ``world.obstacles[i].vertices``, naming the edges and the points.
    """
    for i, o in enumerate(obstacles):
        if o.type != "polygon" or len(o.vertices) < 3:
            continue  # the too-short polygon is refused with the shape
        defect = polygon_defect(o.vertices)
        if defect is not None:
            raise ScenarioError(source, f"world.obstacles[{i}].vertices",
                                f"polygon is not simple: {describe_defect(o.vertices, defect)}")


def _disjoint(shape: Shape, extent: tuple[float, float, float, float]) -> bool:
    """Whether ``shape`` and the closed map rectangle ``(x0, x1, y0, y1)`` share no point."""
    x0, x1, y0, y1 = extent
    lo, hi = np.array([x0, y0]), np.array([x1, y1])
    if isinstance(shape, Circle):
        c = np.asarray(shape.center, dtype=float)
        return bool(np.hypot(*(c - np.clip(c, lo, hi))) > shape.radius)
    bx0, by0, bx1, by1 = shape.bounds()
    if bx1 < x0 or bx0 > x1 or by1 < y0 or by0 > y1:
        return True
    if isinstance(shape, Rectangle):
        return False  # its bounds are the shape
    v = shape.as_array()
    if np.any(np.all((v >= lo) & (v <= hi), axis=1)):
        return False  # a vertex on the map
    box = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
    if np.any(points_in_polygon(box, v)):
        return False  # the map's corner inside the polygon
    cross = segments_intersect(v[:, None], np.roll(v, -1, axis=0)[:, None], box[None],
                               np.roll(box, -1, axis=0)[None])
    return not bool(cross.any())


def check_obstacles_in_map(shapes: Sequence[Shape], extent: tuple[float, float, float, float],
                           source: str) -> None:
    """No ``world.obstacles[i]`` lies wholly outside the map (touching its border is inside).

    Such an obstacle is never met (robots, the LiDAR and the planners work on
    the map): a slip of units or of sign, not a world. Exact for every shape.

    Args:
        shapes: The file's obstacles, in file order (not clutter or generated ones).
        extent: The map's ``(x0, x1, y0, y1)``, m.
        source: Name used in error messages.

    Raises:
        ScenarioError: Key ``world.obstacles[i]``, with its bounds and the map's.
    """
    x0, x1, y0, y1 = extent
    for i, shape in enumerate(shapes):
        if _disjoint(shape, extent):
            bx0, by0, bx1, by1 = shape.bounds()
            kind = type(shape).__name__.lower()
            raise ScenarioError(source, f"world.obstacles[{i}]",
                                f"the {kind} spans [{bx0:.6g}, {bx1:.6g}] x [{by0:.6g}, "
                                f"{by1:.6g}] m, wholly outside the map [{x0:g}, {x1:g}] x "
                                f"[{y0:g}, {y1:g}] m: no robot would ever meet it")


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
