"""Load scenario files (TOML, stdlib ``tomllib``) into a :class:`Scenario`.

Every problem raises :class:`~dfcoa_opt.errors.ScenarioError` whose text is one
line naming the file, the key path and the problem; the CLI prints it and exits
with code 2. Checks beyond the per-key ones of :mod:`dfcoa_opt.sim.schema`:
the map must load, polygons must be counter-clockwise, the leader's start and
goal and explicit robot poses must lie on free cells inside the map, the leader
planner, the localization mode and every ``[controllers.<id>]`` table must be
known, and the planner must find a path. Whatever the planner, the goal must
be in the start's free region of the map (a grid search), and no robot may
start on a formation slot inside an obstacle (an error; a robot body that only
overlaps an obstacle at the start is allowed and counted as a contact), and no
formation slot may lie within (or at) a robot radius of an obstacle at the goal
(:func:`final_leader_poses`: no robot could stand on it without a contact).
Values that would be silently ignored are errors too: ``leader.waypoints``
with a planner other than ``straight`` (and, in the schema, a formation key
its shape ignores, a moving disc that cannot move, ``range_min >= range_max``).
Sizes are bounded so that no legal-looking number exhausts memory or overflows:
a map of at most :data:`MAX_CELLS` cells, and every position and length within
:data:`MAX_EXTENT` m of the origin (``team.n`` <= 100,000 is a schema bound).
"""

from __future__ import annotations

import copy
import math
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from dfcoa_opt.errors import DfcoaError, ScenarioError, did_you_mean
from dfcoa_opt.formation import formation_offsets, slot_positions
from dfcoa_opt.params import build
from dfcoa_opt.planning.pure_pursuit import PurePursuit
from dfcoa_opt.sim.scenario import Scenario, World
from dfcoa_opt.sim.schema import ObstacleSpec, ScenarioSpec
from dfcoa_opt.world.clutter import random_discs
from dfcoa_opt.world.dynamic import DynamicObstacles, MovingDisc
from dfcoa_opt.world.grid import OccupancyGrid
from dfcoa_opt.world.shapes import Circle, Polygon, Rectangle, Shape

_INDEX = re.compile(r"^([A-Za-z_][A-Za-z0-9_]*)\[(\d+)\]$")

try:
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]


def read_toml(path: str | Path) -> dict[str, Any]:
    """Read a TOML file, turning every failure into a one-line :class:`ScenarioError`."""
    path = Path(path)
    src = str(path)
    try:
        text = path.read_bytes().decode("utf-8")
    except FileNotFoundError:
        raise ScenarioError(src, "", "file not found") from None
    except IsADirectoryError:
        raise ScenarioError(src, "", "is a directory, expected a .toml file") from None
    except PermissionError:
        raise ScenarioError(src, "", "permission denied") from None
    except UnicodeDecodeError as exc:
        raise ScenarioError(src, "", f"is not UTF-8 text ({exc.reason} at byte {exc.start})"
                            ) from None
    if not text.strip():
        raise ScenarioError(src, "", "file is empty")
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(src, "", f"not valid TOML: {exc}") from None


def load_scenario(path: str | Path, seed: int | None = None,
                  overrides: Mapping[str, Any] | None = None) -> Scenario:
    """Load and validate a scenario file.

    Args:
        path: The ``.toml`` file; relative paths inside it (``map_image``) are
            resolved against its folder.
        seed: Replaces the file's ``seed`` (seeded parts such as random clutter
            follow it).
        overrides: Dotted keys set before validation (:func:`apply_overrides`).

    Raises:
        ScenarioError: On any problem, with a one-line message.
    """
    path = Path(path)
    data = read_toml(path)
    data.setdefault("name", path.stem)
    if seed is not None:
        data["seed"] = seed
    apply_overrides(data, overrides or {}, str(path))
    return scenario_from_dict(data, str(path), path.parent)


def apply_overrides(data: dict[str, Any], overrides: Mapping[str, Any],
                    source: str = "<overrides>") -> dict[str, Any]:
    """Set dotted keys in a scenario dict (in place); returns ``data``.

    Args:
        data: Parsed scenario file.
        overrides: ``{"world.clutter.density": 0.1, "world.obstacles[0].radius": 1.0}``.
        source: Name used in error messages.

    Raises:
        ScenarioError: A path runs through a value that is not a table or an
            array of tables, or an index is out of range.
    """
    for dotted, value in overrides.items():
        node: Any = data
        parts = dotted.split(".")
        for i, part in enumerate(parts):
            last = i == len(parts) - 1
            m = _INDEX.match(part)
            name, idx = (m.group(1), int(m.group(2))) if m else (part, None)
            if not isinstance(node, dict):
                raise ScenarioError(source, dotted, f"'{'.'.join(parts[:i])}' is not a table")
            if idx is None:
                if last:
                    node[name] = value
                else:
                    node = node.setdefault(name, {})
                continue
            seq = node.get(name)
            if not isinstance(seq, list) or idx >= len(seq):
                size = len(seq) if isinstance(seq, list) else 0
                raise ScenarioError(source, dotted, f"index {idx} out of range ({name} has "
                                                    f"{size} entries)")
            if last:
                seq[idx] = value
            else:
                node = seq[idx]
    return data


def scenario_from_dict(data: Mapping[str, Any], source: str = "<dict>",
                       base_dir: str | Path = ".") -> Scenario:
    """Validate a scenario given as a dict (the parsed TOML).

    Args:
        data: Scenario contents.
        source: Name used in error messages.
        base_dir: Folder against which ``world.map_image`` is resolved.
    """
    if isinstance(data.get("localization"), str):  # shorthand: localization = "mcl"
        data = {**data, "localization": {"mode": data["localization"]}}
    spec = build(ScenarioSpec, data, source)
    offsets = formation_offsets(spec.formation, spec.team.n)
    _check_extents(spec, offsets, source)
    world = _build_world(spec, source, Path(base_dir), offsets)
    _check_free(world.grid, spec.leader.start, source, "leader.start")
    _check_free(world.grid, spec.leader.goal, source, "leader.goal")
    _check_names(spec, source)
    _check_waypoints(spec, source)

    from dfcoa_opt.planning.registry import get_planner, planner_options

    options = planner_options(spec.leader.planner, spec.leader.planner_options, source)
    try:
        path = get_planner(spec.leader.planner)(world.grid, np.asarray(spec.leader.start, float),
                                                np.asarray(spec.leader.goal, float), spec.leader,
                                                options)
    except DfcoaError as exc:
        raise ScenarioError(source, "leader.goal", str(exc)) from None
    if path is None or len(path) == 0:
        raise ScenarioError(source, "leader.goal", f"unreachable from leader.start with planner "
                                                   f"'{spec.leader.planner}'")
    heading = spec.leader.heading
    if heading is None:
        away = [p for p in np.asarray(path, float) if np.hypot(*(p - path[0])) > 1e-9]
        d = away[0] - path[0] if away else np.zeros(2)
        heading = math.atan2(d[1], d[0]) if np.any(d) else 0.0
    if spec.team.placement == "explicit":
        pose = np.asarray(spec.team.poses, dtype=float)
        for i, p in enumerate(pose):
            _check_free(world.grid, p[:2], source, f"team.poses[{i}]")
    else:
        leader0 = np.array([*spec.leader.start, heading])
        xy = slot_positions(leader0, offsets)
        if spec.team.start_behind:
            xy = xy - spec.team.start_behind * np.array([math.cos(heading), math.sin(heading)])
            for i, p in enumerate(xy):
                _check_free(world.grid, p, source, f"team.start_behind (robot {i})")
        pose = np.column_stack((xy, np.full(spec.team.n, heading)))
    _check_start_clear(world, pose, spec, source)
    _check_connected(world.grid, spec, source)
    _check_goal_clear(world, final_leader_poses(np.asarray(path, dtype=float), spec, heading),
                      offsets, spec, source)
    return Scenario(spec=spec, source=source, world=world, offsets=offsets, initial_pose=pose,
                    leader_heading=float(heading), leader_path=np.asarray(path, dtype=float),
                    data=copy.deepcopy(dict(data)), base_dir=Path(base_dir))


def _check_names(spec: ScenarioSpec, source: str) -> None:
    """Registered planner, localization mode and controller override tables."""
    from dfcoa_opt.control.registry import check_overrides
    from dfcoa_opt.localization import estimator_names, estimator_options
    from dfcoa_opt.planning.registry import planner_names

    if spec.leader.planner not in planner_names():
        raise ScenarioError(source, "leader.planner", f"unknown planner '{spec.leader.planner}'"
                            f"{did_you_mean(spec.leader.planner, planner_names())}; available: "
                            f"{', '.join(planner_names())}")
    if spec.localization.mode not in estimator_names():
        raise ScenarioError(source, "localization.mode", f"unknown mode '{spec.localization.mode}'"
                            f"{did_you_mean(spec.localization.mode, estimator_names())}; "
                            f"available: {', '.join(estimator_names())}")
    estimator_options(spec.localization.mode, spec.localization.options, source)
    check_overrides(spec.controllers, source)


def _check_waypoints(spec: ScenarioSpec, source: str) -> None:
    """``leader.waypoints`` only with the ``straight`` planner, the one that uses them.

    The searching planners plan their own path from ``leader.start`` to
    ``leader.goal`` and would silently ignore the via points.
    """
    if spec.leader.waypoints and spec.leader.planner != "straight":
        raise ScenarioError(source, "leader.waypoints", f"only the 'straight' planner uses them; "
                                                        f"planner '{spec.leader.planner}' plans "
                                                        f"its own path and would ignore them")


def _check_start_clear(world: World, pose: Any, spec: ScenarioSpec, source: str) -> None:
    """No robot may start on a formation slot inside a static obstacle: an error, not a warning.

    With the default placement the robots start on their formation slots around
    ``leader.start``; a slot inside an obstacle would start the run inside it,
    which no controller can repair. Measured exactly on the shapes
    (``World.clearance``), not on the grid. A robot whose *body* merely
    overlaps an obstacle at the start is allowed (some tests start robots
    close to walls on purpose); the simulator counts that contact at t = 0.
    """
    if spec.team.placement == "explicit":
        return  # team.poses were checked on the (fatter) grid by _check_free
    clear = world.clearance(np.asarray(pose, dtype=float)[:, :2])
    for i in np.flatnonzero(clear <= 0.0):
        x, y = pose[i][0], pose[i][1]
        raise ScenarioError(source, "formation", f"robot {i} starts on its slot ({x:g}, {y:g}), "
                                                 f"inside an obstacle; move leader.start or "
                                                 f"the formation")


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


def _check_goal_clear(world: World, leader: np.ndarray, offsets: np.ndarray, spec: ScenarioSpec,
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


def _check_connected(grid: OccupancyGrid, spec: ScenarioSpec, source: str) -> None:
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


def _check_free(grid: OccupancyGrid, point: Any, source: str, key: str) -> None:
    p = np.asarray(point, dtype=float)[:2]
    row, col = grid.world_to_cell(p)
    if not bool(grid.in_bounds(row, col)):
        x0, x1, y0, y1 = grid.extent
        raise ScenarioError(source, key, f"({p[0]:g}, {p[1]:g}) is outside the map "
                                         f"[{x0:g}, {x1:g}] x [{y0:g}, {y1:g}] m")
    if grid.occupied[row, col]:
        raise ScenarioError(source, key, f"({p[0]:g}, {p[1]:g}) is inside an obstacle")


def _check_extents(spec: ScenarioSpec, offsets: np.ndarray, source: str) -> None:
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


def _shape(spec: ObstacleSpec, source: str, key: str) -> Shape:
    try:
        if spec.type == "circle":
            return Circle(spec.center, spec.radius)  # type: ignore[arg-type]
        if spec.type == "rectangle":
            return Rectangle(spec.min, spec.max)  # type: ignore[arg-type]
        return Polygon(spec.vertices)
    except ValueError as exc:
        raise ScenarioError(source, key, str(exc)) from None


def _clutter(spec: ScenarioSpec, offsets: np.ndarray, extent: tuple[float, ...],
             source: str) -> tuple[Circle, ...]:
    """The ``[world.clutter]`` discs, kept clear of the start, the goal and explicit poses.

    ``extent`` is the grid's ``(x0, x1, y0, y1)``, the default region.
    """
    cl = spec.world.clutter
    if cl.density == 0.0:
        return ()
    region = cl.region if cl.region is not None else (extent[0], extent[2], extent[1], extent[3])
    tol = 1e-9 * max(1.0, *map(abs, extent))
    if (region[0] < extent[0] - tol or region[2] > extent[1] + tol or region[1] < extent[2] - tol
            or region[3] > extent[3] + tol):
        raise ScenarioError(source, "world.clutter.region", f"{list(region)} must lie inside the "
                            f"map [{extent[0]:g}, {extent[2]:g}, {extent[1]:g}, {extent[3]:g}]")
    reach = float(np.max(np.hypot(*offsets.T))) + spec.robots.radius
    points = [spec.leader.start, spec.leader.goal, *(p[:2] for p in spec.team.poses)]
    radius = [cl.keep_clear + reach, cl.keep_clear,
              *([cl.keep_clear + spec.robots.radius] * len(spec.team.poses))]
    rng = np.random.default_rng(spec.seed if cl.seed is None else cl.seed)
    return random_discs(rng, region, cl.density, cl.radius_min, cl.radius_max,
                        np.asarray(points, float), np.asarray(radius, float), cl.gap)


#: Largest map, in cells (a bool grid plus float distance fields: about 10 GB at the limit).
MAX_CELLS = 10**8
#: Largest coordinate of the map's corners, m.
MAX_EXTENT = 1e6


def _check_cells(size: tuple[float, float], resolution: float, source: str) -> None:
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


def _build_world(spec: ScenarioSpec, source: str, base_dir: Path, offsets: np.ndarray) -> World:
    ws = spec.world
    if ws.map_ascii is not None:
        try:
            grid = OccupancyGrid.from_ascii(ws.map_ascii, ws.resolution, ws.origin)
        except ValueError as exc:
            raise ScenarioError(source, "world.map_ascii", str(exc)) from None
    elif ws.map_image is not None:
        img = (base_dir / ws.map_image)
        if not img.is_file():
            raise ScenarioError(source, "world.map_image", f"image file '{img}' not found")
        try:
            grid = OccupancyGrid.from_image(img, ws.resolution, ws.image_threshold, ws.origin)
        except (OSError, ValueError, SyntaxError) as exc:
            raise ScenarioError(source, "world.map_image", f"cannot read image '{img}': "
                                                           f"{exc}") from None
    else:
        _check_cells(ws.size, ws.resolution, source)  # type: ignore[arg-type]
        grid = OccupancyGrid.empty(ws.size, ws.resolution, ws.origin)  # type: ignore[arg-type]
    x0, x1, y0, y1 = grid.extent
    if not max(abs(x0), abs(x1), abs(y0), abs(y1)) <= MAX_EXTENT:
        key = "world.origin" if max(map(abs, ws.origin)) > MAX_EXTENT else "world.resolution"
        raise ScenarioError(source, key, f"the map spans [{x0:g}, {x1:g}] x [{y0:g}, {y1:g}] m, "
                            f"beyond the {MAX_EXTENT:g} m this toolkit accepts")
    if ws.size is not None and (ws.map_ascii is not None or ws.map_image is not None):
        w, h = grid.size
        if abs(w - ws.size[0]) > grid.cell_size / 2 or abs(h - ws.size[1]) > grid.cell_size / 2:
            raise ScenarioError(source, "world.size", f"{list(ws.size)} m does not match the map, "
                                f"which is {w:g} x {h:g} m at {ws.resolution:g} cells/m")
    raster = grid if ws.map_ascii is not None or ws.map_image is not None else None
    shapes = tuple(_shape(o, source, f"world.obstacles[{i}]") for i, o in enumerate(ws.obstacles))
    shapes += _clutter(spec, offsets, grid.extent, source)
    grid = grid.with_shapes(shapes)
    discs = tuple(MovingDisc(d.radius, d.speed, d.waypoints, d.start_time, d.end)
                  for d in ws.dynamic_obstacles)
    return World(grid=grid, shapes=shapes, dynamic=DynamicObstacles(discs), raster=raster)
