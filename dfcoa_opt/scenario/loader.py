"""Load scenario files (TOML, stdlib ``tomllib``) into a :class:`Scenario`.

Every problem raises :class:`~dfcoa_opt.core.errors.ScenarioError` whose text is one
line naming the file, the key path and the problem; the CLI prints it and exits
with code 2. Checks beyond the per-key ones of :mod:`dfcoa_opt.scenario.schema`:
the map must load, polygons must be simple (no crossing or touching edges, no
repeated vertex) and counter-clockwise, no ``world.obstacles[i]`` may lie wholly
outside the map, the leader's start and goal, its via points
(``leader.waypoints``) and explicit robot poses must lie on free cells inside
the map, the leader planner, the localization mode and every
``[controllers.<id>]`` table must be known, and the planner must find a path.
Whatever the planner, the goal must be in the start's free region of the map
(a grid search). Every robot must start inside the map (formation slots
too), no two robots may start overlapping (centres closer than
``2 * robots.radius``, unless ``team.allow_start_contact``), and no robot may
start on a formation slot inside an obstacle (an error; a robot body that only
overlaps an obstacle at the start is allowed and counted as a contact), and no
formation slot may lie within (or at) a robot radius of an obstacle at the goal
(:func:`~dfcoa_opt.scenario.placement.final_leader_poses`: no robot could stand on it without a
contact).
Values that would be silently ignored are errors too: ``leader.waypoints``
with a planner other than ``straight`` (and, in the schema, a formation key
its shape ignores, a moving disc that cannot move, ``range_min >= range_max``).
A ``[world.generate]`` world is drawn until a passage one robot wide joins the
leader's start and goal and the planner finds its path (:func:`_generated`).
Sizes are bounded so that no legal-looking number exhausts memory or overflows:
a map of at most :data:`~dfcoa_opt.scenario.budget.MAX_CELLS` cells, and every position
and length within :data:`~dfcoa_opt.scenario.budget.MAX_EXTENT` m of the origin (``team.n``
<= 100,000 is a schema bound).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from dfcoa_opt.core.errors import DfcoaError, ScenarioError
from dfcoa_opt.core.params import build
from dfcoa_opt.scenario.budget import MAX_EXTENT, check_budget, check_cells, check_extents
from dfcoa_opt.scenario.formation import formation_offsets, slot_positions
from dfcoa_opt.scenario.map_files import grid_cells, map_file
from dfcoa_opt.scenario.names import check_names, check_waypoints
from dfcoa_opt.scenario.overrides import apply_overrides, read_toml
from dfcoa_opt.scenario.placement import (
    check_connected,
    check_free,
    check_goal_clear,
    check_obstacles_in_map,
    check_polygons,
    check_start_clear,
    check_start_poses,
    check_via_points,
    final_leader_poses,
)
from dfcoa_opt.scenario.scenario import Scenario, World
from dfcoa_opt.scenario.schema import ScenarioSpec
from dfcoa_opt.world.clutter import random_discs
from dfcoa_opt.world.dynamic import DynamicObstacles, MovingDisc
from dfcoa_opt.world.grid import OccupancyGrid
from dfcoa_opt.world.shapes import Circle, Polygon, Rectangle, Shape
from dfcoa_opt.world.spec import ObstacleSpec, check_map_yaml_keys


def load_scenario(path: str | Path, seed: int | None = None,
                  overrides: Mapping[str, Any] | None = None,
                  overrides_source: str | None = None) -> Scenario:
    """Load and validate a scenario file.

    Args:
        path: The ``.toml`` file; relative paths inside it (``map_image``, ``map_yaml``) are
            resolved against its folder.
        seed: Replaces the file's ``seed`` (seeded parts such as random clutter
            follow it).
        overrides: Dotted keys set before validation (:func:`apply_overrides`).
        overrides_source: What gave the overrides (``--set``): an error about one
            of their keys names it instead of the file. None: the file.

    Raises:
        ScenarioError: On any problem, with a one-line message.
    """
    path = Path(path)
    data = read_toml(path)
    data.setdefault("name", path.stem)
    if seed is not None:
        data["seed"] = seed
    apply_overrides(data, overrides or {}, overrides_source or str(path))
    try:
        return scenario_from_dict(data, str(path), path.parent)
    except ScenarioError as exc:
        if overrides_source and any(exc.key == k or exc.key.startswith((f"{k}.", f"{k}["))
                                    for k in overrides or {}):
            raise ScenarioError(overrides_source, exc.key, exc.problem) from None
        raise


def scenario_from_dict(data: Mapping[str, Any], source: str = "<dict>",
                       base_dir: str | Path = ".") -> Scenario:
    """Validate a scenario given as a dict (the parsed TOML).

    Args:
        data: Scenario contents.
        source: Name used in error messages.
        base_dir: Folder against which ``world.map_image``/``map_yaml`` are resolved.
    """
    if isinstance(data.get("localization"), str):  # shorthand: localization = "mcl"
        data = {**data, "localization": {"mode": data["localization"]}}
    spec = build(ScenarioSpec, with_profile(data, source), source)
    check_map_yaml_keys(data.get("world"), source)
    offsets = formation_offsets(spec.formation, spec.team.n)
    check_extents(spec, offsets, source)
    check_names(spec, source)
    check_budget(spec, source, grid_cells(spec.world))
    check_waypoints(spec, source)
    world, path = _build_world(spec, source, Path(base_dir), offsets)
    heading = spec.leader.heading
    if heading is None:
        away = [p for p in np.asarray(path, float) if np.hypot(*(p - path[0])) > 1e-9]
        d = away[0] - path[0] if away else np.zeros(2)
        heading = math.atan2(d[1], d[0]) if np.any(d) else 0.0
    if spec.team.placement == "explicit":
        pose = np.asarray(spec.team.poses, dtype=float)
        for i, p in enumerate(pose):
            check_free(world.grid, p[:2], source, f"team.poses[{i}]")
    else:
        leader0 = np.array([*spec.leader.start, heading])
        xy = slot_positions(leader0, offsets)
        if spec.team.start_behind:
            xy = xy - spec.team.start_behind * np.array([math.cos(heading), math.sin(heading)])
            for i, p in enumerate(xy):
                check_free(world.grid, p, source, f"team.start_behind (robot {i})")
        pose = np.column_stack((xy, np.full(spec.team.n, heading)))
    check_start_poses(world.grid, pose, spec, source)
    check_start_clear(world, pose, spec, source)
    check_connected(world.grid, spec, source)
    check_goal_clear(world, final_leader_poses(np.asarray(path, dtype=float), spec, heading),
                      offsets, spec, source)
    return Scenario(spec=spec, source=source, world=world, offsets=offsets, initial_pose=pose,
                    leader_heading=float(heading), leader_path=np.asarray(path, dtype=float),
                    data=copy.deepcopy(dict(data)), base_dir=Path(base_dir))


#: Profile keys that only an actuated robot has (a kinematic one ignores them).


def reseed(scenario: Scenario, seed: int) -> Scenario:
    """``scenario`` as loaded with ``seed``: what the seed draws is drawn again.

    The one meaning of a run's seed, whatever the entry point: a run with
    seed ``s`` gets the world of ``load_scenario(file, s)``, so a loaded
    scenario can be run with any seed.

    Args:
        scenario: A loaded scenario.
        seed: The run's seed.

    Returns:
        ``scenario`` when ``seed`` is its own or nothing in it depends on the
        seed; else the scenario built again from its ``data`` with ``seed``
        (the same overrides).

    Raises:
        DfcoaError: The world depends on the seed and the scenario was not
            built from a file or a dict (no ``data``).
        ScenarioError: The scenario does not load with ``seed`` (e.g. a
            clutter field that closes the way).
    """
    if int(seed) == scenario.spec.seed or not scenario.seed_dependent:
        return scenario
    if scenario.data is None:
        raise DfcoaError(f"{scenario.source}: its world follows the seed, so load it with "
                         f"seed {seed} (dfcoa_opt.load(path, seed={seed})) to run that seed")
    return scenario_from_dict({**scenario.data, "seed": int(seed)}, scenario.source,
                              scenario.base_dir)


ACTUATED_KEYS = ("wheel_accel_max", "motor_time_constant")


def with_profile(data: Mapping[str, Any], source: str) -> Mapping[str, Any]:
    """``data`` with its robot profile's values under the keys it does not set itself.

    ``robots.profile`` names one of ``dfcoa_opt.world.robots.profiles.PROFILES``
    (docs/robots.md). Its ``[robots]`` values fill the keys the scenario leaves
    out (its acceleration limit and motor time constant only with
    ``dynamics = "actuated"``), and its LiDAR values those of
    ``[sensors.lidar]``. ``data`` itself is not changed.

    Raises:
        ScenarioError: An unknown profile, naming the known ones.
    """
    robots = data.get("robots")
    if not isinstance(robots, dict) or robots.get("profile") is None:
        return data
    from dfcoa_opt.world.robots.profiles import PROFILES  # data, read only with a profile

    name = robots["profile"]
    if not isinstance(name, str) or name not in PROFILES:
        raise ScenarioError(source, "robots.profile",
                            f"unknown profile {name!r}; known profiles: "
                            f"{', '.join(sorted(PROFILES))}")
    profile = PROFILES[name]
    actuated = robots.get("dynamics") == "actuated"
    out = dict(data)
    out["robots"] = {**{k: v for k, v in profile["robots"].items()
                        if actuated or k not in ACTUATED_KEYS}, **robots}
    sensors = data.get("sensors", {})
    lidar = sensors.get("lidar", {}) if isinstance(sensors, dict) else None
    if profile.get("lidar") and isinstance(lidar, dict):
        out["sensors"] = {**sensors, "lidar": {**profile["lidar"], **lidar}}
    return out


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


def _plan_leader(world: World, spec: ScenarioSpec, source: str) -> np.ndarray | None:
    """The leader's path on ``world`` by its planner; None when the goal is unreachable.

    Raises:
        ScenarioError: The start or the goal is not free, or the planner fails.
    """
    from dfcoa_opt.planning.registry import get_planner, planner_options

    check_free(world.grid, spec.leader.start, source, "leader.start")
    check_free(world.grid, spec.leader.goal, source, "leader.goal")
    check_via_points(world.grid, spec, source)
    options = planner_options(spec.leader.planner, spec.leader.planner_options, source)
    try:
        path = get_planner(spec.leader.planner)(world.grid, np.asarray(spec.leader.start, float),
                                                np.asarray(spec.leader.goal, float),
                                                np.asarray(spec.leader.waypoints, float), options)
    except DfcoaError as exc:
        raise ScenarioError(source, "leader.goal", str(exc)) from None
    return None if path is None or len(path) == 0 else np.asarray(path, dtype=float)


def _build_world(spec: ScenarioSpec, source: str, base_dir: Path, offsets: np.ndarray
                 ) -> tuple[World, np.ndarray]:
    """The world of the file (map, shapes, clutter, a generated world) and the leader's path."""
    ws = spec.world
    raster = map_file(ws, source, base_dir)
    if raster is None:
        check_cells(ws.size, ws.resolution, source)  # type: ignore[arg-type]
        grid = OccupancyGrid.empty(ws.size, ws.resolution, ws.origin)  # type: ignore[arg-type]
    else:
        grid = raster
    x0, x1, y0, y1 = grid.extent
    if not max(abs(x0), abs(x1), abs(y0), abs(y1)) <= MAX_EXTENT:
        key = "world.origin" if max(map(abs, ws.origin)) > MAX_EXTENT else "world.resolution"
        key = "world.map_yaml" if ws.map_yaml is not None else key  # its origin and resolution
        raise ScenarioError(source, key, f"the map spans [{x0:g}, {x1:g}] x [{y0:g}, {y1:g}] m, "
                            f"beyond the {MAX_EXTENT:g} m this toolkit accepts")
    if ws.size is not None and raster is not None:
        w, h = grid.size
        if abs(w - ws.size[0]) > grid.cell_size / 2 or abs(h - ws.size[1]) > grid.cell_size / 2:
            raise ScenarioError(source, "world.size", f"{list(ws.size)} m does not match the map, "
                                f"which is {w:g} x {h:g} m at {grid.resolution:g} cells/m")
    check_polygons(ws.obstacles, source)
    shapes = tuple(_shape(o, source, f"world.obstacles[{i}]") for i, o in enumerate(ws.obstacles))
    check_obstacles_in_map(shapes, grid.extent, source)
    shapes += _clutter(spec, offsets, grid.extent, source)
    discs = tuple(MovingDisc(d.radius, d.speed, d.waypoints, d.start_time, d.end)
                  for d in ws.dynamic_obstacles)
    if ws.generate.family:
        return _generated(spec, source, offsets, grid, raster, shapes, discs)
    world = World(grid=grid.with_shapes(shapes), shapes=shapes, dynamic=DynamicObstacles(discs),
                  raster=raster)
    path = _plan_leader(world, spec, source)
    if path is None:
        raise ScenarioError(source, "leader.goal", f"unreachable from leader.start with planner "
                                                   f"'{spec.leader.planner}'")
    return world, path


def _generated(spec: ScenarioSpec, source: str, offsets: np.ndarray, grid: OccupancyGrid,
               raster: OccupancyGrid | None, shapes: tuple[Shape, ...],
               discs: tuple[MovingDisc, ...]) -> tuple[World, np.ndarray]:
    """Draw ``[world.generate]`` until a passage one robot wide joins start and goal.

    The family draws inside the walls that enclose the map (``walls`` thick).
    Each draw continues the world's generator (:func:`~dfcoa_opt.world.generate.world_rng`
    of the seed), so the accepted draw is a pure function of the seed. A draw is
    kept when :func:`~dfcoa_opt.world.generate.passage_exists` finds a passage
    keeping ``robots.radius + margin`` from every obstacle and the leader's planner
    finds a path.

    Raises:
        ScenarioError: No draw of ``tries`` is kept (one line: the seed and what to loosen).
    """
    from dfcoa_opt.world import generate as gen

    g = spec.world.generate
    params = gen.family_options(g.family, g.options, source)
    reach = float(np.max(np.hypot(*offsets.T))) + spec.robots.radius
    x0, x1, y0, y1 = grid.extent
    if g.walls:
        t = g.walls
        if not (x1 - x0 > 2 * t and y1 - y0 > 2 * t):
            raise ScenarioError(source, "world.generate.walls", f"{t:g} m walls leave no room "
                                f"inside the {x1 - x0:g} x {y1 - y0:g} m map")
        shapes += (Rectangle((x0, y0), (x1, y0 + t)), Rectangle((x0, y1 - t), (x1, y1)),
                   Rectangle((x0, y0 + t), (x0 + t, y1 - t)),
                   Rectangle((x1 - t, y0 + t), (x1, y1 - t)))
        x0, x1, y0, y1 = x0 + t, x1 - t, y0 + t, y1 - t
    layout = gen.Layout(extent=(x0, x1, y0, y1), start=tuple(spec.leader.start),
                        goal=tuple(spec.leader.goal), start_clear=reach + g.keep_clear,
                        goal_clear=reach + g.keep_clear)
    seed = spec.seed if g.seed is None else g.seed
    rng = gen.world_rng(seed)
    clearance = spec.robots.radius + g.margin
    for _ in range(g.tries):
        try:
            drawn = gen.generate(g.family, params, rng, layout)
        except ValueError as exc:
            raise ScenarioError(source, "world.generate.options", str(exc)) from None
        all_shapes = shapes + drawn.shapes
        world = World(grid=grid.with_shapes(all_shapes), shapes=all_shapes,
                      dynamic=DynamicObstacles(discs + drawn.discs), raster=raster,
                      facts=dict(drawn.facts))
        if not gen.passage_exists(world.grid, spec.leader.start, spec.leader.goal, clearance):
            continue
        path = _plan_leader(world, spec, source)
        if path is not None:
            return world, path
    raise ScenarioError(source, "world.generate", f"family '{g.family}' drew no world with a "
                        f"passage {2 * clearance:g} m wide from leader.start to leader.goal in "
                        f"{g.tries} draws (world seed {seed}); raise tries or loosen the options")
