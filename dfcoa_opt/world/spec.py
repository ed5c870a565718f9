"""Scenario schema, the map's sections: ``[world]``, obstacles, moving discs, clutter, generators.

Part of :mod:`dfcoa_opt.scenario.schema` (which re-exports every class here).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Literal

from dfcoa_opt.core.errors import ScenarioError
from dfcoa_opt.core.params import param

Vec2 = tuple[float, float]


def _need(src: str, key: str, value: Any, what: str) -> None:
    if value is None or value == ():
        raise ScenarioError(src, key, f"is required {what}")


@dataclass(frozen=True)
class ObstacleSpec:
    """A static geometric obstacle (rasterised into the grid, kept as exact geometry)."""

    type: Literal["polygon", "circle", "rectangle"] = param(doc="Shape kind.")
    vertices: tuple[Vec2, ...] = param((), doc="Polygon vertices, counter-clockwise.", unit="m")
    center: Vec2 | None = param(None, doc="Circle centre.", unit="m")
    radius: float | None = param(None, doc="Circle radius (from 1 mm: ORCA turns a circle "
                                           "into a polygon whose vertices must stay "
                                           "distinct).", unit="m", ge=1e-3)
    min: Vec2 | None = param(None, doc="Rectangle lower-left corner.", unit="m")
    max: Vec2 | None = param(None, doc="Rectangle upper-right corner.", unit="m")

    def check(self, src: str, key: str) -> None:
        """Per-type required keys."""
        need = {"polygon": ("vertices",), "circle": ("center", "radius"),
                "rectangle": ("min", "max")}[self.type]
        for name in need:
            _need(src, f"{key}.{name}", getattr(self, name), f"for type = '{self.type}'")
        for name in ("vertices", "center", "radius", "min", "max"):
            if name not in need and getattr(self, name) not in (None, ()):
                raise ScenarioError(src, f"{key}.{name}", f"does not apply to type = '{self.type}'")


@dataclass(frozen=True)
class DynamicObstacleSpec:
    """A disc moving along waypoints at constant speed (paper 002 humans, paper 004 robots)."""

    radius: float = param(doc="Disc radius.", unit="m", gt=0.0)
    speed: float = param(doc="Speed along the waypoints.", unit="m/s", ge=0.0)
    waypoints: tuple[Vec2, ...] = param(doc="Polyline to follow, first point = start.", unit="m")
    start_time: float = param(0.0, doc="Time the disc starts moving.", unit="s", ge=0.0)
    end: Literal["stop", "loop", "bounce"] = param("stop", doc="Behaviour at the last waypoint.")

    def check(self, src: str, key: str) -> None:
        """At least one waypoint, and a motion that means something.

        A disc told to move (``speed > 0``) needs a path of positive length; a
        disc that never moves (``speed = 0``) makes further waypoints, a
        ``loop``/``bounce`` end and a ``start_time`` meaningless. A parked disc
        (one waypoint, speed 0, ``end = "stop"``, no ``start_time``) is fine.
        A ``start_time`` after ``t_max`` is allowed: a run shortened by an
        override just ends before the disc starts.
        """
        _need(src, f"{key}.waypoints", self.waypoints, "(at least one point)")
        moves = any(p != self.waypoints[0] for p in self.waypoints[1:])
        if self.speed > 0 and not moves:
            raise ScenarioError(src, f"{key}.speed", f"the disc is told to move ({self.speed:g} "
                                                     "m/s) but its waypoints are a single "
                                                     "point: add a waypoint or set speed = 0")
        if self.speed == 0 and moves:
            raise ScenarioError(src, f"{key}.waypoints", "the disc never moves (speed = 0), so "
                                                         "the waypoints after the first are never"
                                                         " reached: set a speed or keep one")
        if self.speed == 0 and self.end != "stop":
            raise ScenarioError(src, f"{key}.end", f"'{self.end}' needs a moving disc "
                                                   "(speed > 0); a parked disc ends with 'stop'")
        if self.speed == 0 and self.start_time > 0:
            raise ScenarioError(src, f"{key}.start_time", f"{self.start_time:g} s is when the "
                                                          "disc starts moving, but it never moves "
                                                          "(speed = 0): set a speed or drop "
                                                          "start_time")


@dataclass(frozen=True)
class ClutterSpec:
    """Seeded random circular obstacles, added to the map (a cluttered field)."""

    density: float = param(0.0, doc="Fraction of the region's area covered by discs; 0 = no "
                                    "clutter.", ge=0.0, lt=0.9)
    radius_min: float = param(0.2, doc="Smallest disc radius (from 1 mm, as a circle's).",
                              unit="m", ge=1e-3)
    radius_max: float = param(0.5, doc="Largest disc radius.", unit="m", gt=0.0)
    region: tuple[float, float, float, float] | None = param(
        None, doc="(x0, y0, x1, y1) box of the disc centres; default: the whole map.", unit="m")
    keep_clear: float = param(1.0, doc="Free margin around the leader's start (plus the "
                                       "formation's extent), its goal and explicit robot poses.",
                              unit="m", ge=0.0)
    gap: float = param(0.0, doc="Smallest free distance between two discs.", unit="m", ge=0.0)
    seed: int | None = param(None, doc="Seed of the field; default: the scenario seed, so every "
                                       "run seed gives a new field.", ge=0)

    def check(self, src: str, key: str) -> None:
        """Radius order and a non-empty region."""
        if self.radius_max < self.radius_min:
            raise ScenarioError(src, f"{key}.radius_max", f"must be >= radius_min "
                                                          f"({self.radius_min})")
        if self.region is not None:
            x0, y0, x1, y1 = self.region
            if not (x1 > x0 and y1 > y0):
                raise ScenarioError(src, f"{key}.region", "needs x1 > x0 and y1 > y0")


@dataclass(frozen=True)
class GenerateSpec:
    """A world drawn from the seed by a registered family (docs/heldout.md)."""

    family: str = param("", doc="World family: 'cellular', 'rooms', 'corridors' or 'crowd' "
                                "(dfcoa_opt.world.generate); empty: none.")
    options: dict[str, Any] = param(default_factory=dict, doc="The family's parameters, checked "
                                                              "against its Params.")
    seed: int | None = param(None, doc="Seed of the world; default: the scenario seed, so every "
                                       "run seed draws a new world.", ge=0)
    tries: int = param(20, doc="Draws before giving up when no passage one robot wide joins "
                               "the leader's start and goal, or the leader's planner finds no "
                               "path.", ge=1, le=1000)
    keep_clear: float = param(0.5, doc="Free margin around the leader's start and goal, beyond "
                                       "the formation's reach.", unit="m", ge=0.0)
    margin: float = param(0.05, doc="The passage keeps robots.radius plus this from every "
                                    "obstacle.", unit="m", ge=0.0)
    walls: float = param(0.2, doc="Thickness of the walls that enclose the map along its edges "
                                  "(0: none); the family draws inside them.", unit="m", ge=0.0)

    def check(self, src: str, key: str) -> None:
        """Options and a seed only with a family."""
        if not self.family and (self.options or self.seed is not None):
            what = "options" if self.options else "seed"
            raise ScenarioError(src, f"{key}.{what}", "applies only with a family (world."
                                                      "generate.family = 'rooms', ...)")


@dataclass(frozen=True)
class WorldSpec:
    """The map: occupancy grid plus exact and moving obstacles."""

    resolution: float = param(10.0, doc="Grid resolution.", unit="cells/m", gt=0.0)
    size: Vec2 | None = param(None, doc="(width, height); required unless a map gives it.",
                              unit="m", gt=0.0)
    origin: Vec2 = param((0.0, 0.0), doc="World position of the map's bottom-left corner.",
                         unit="m")
    map_ascii: str | None = param(None, doc="ASCII map, top row first: '#' occupied, '.' free.")
    map_image: str | None = param(None, doc="PNG map (relative to the scenario file); dark = "
                                            "occupied, one pixel per cell.")
    image_threshold: float = param(0.5, doc="Grey level below which an image pixel is occupied.",
                                   ge=0.0, le=1.0)
    map_yaml: str | None = param(None, doc="ROS map_server map: its YAML file (relative to the "
                                           "scenario file), which sets the image, resolution "
                                           "(m/cell) and origin; a cell is free only where "
                                           "map_server would publish 0, so unknown is occupied "
                                           "(docs/ros.md).")
    obstacles: tuple[ObstacleSpec, ...] = param((), doc="Static geometric obstacles.")
    dynamic_obstacles: tuple[DynamicObstacleSpec, ...] = param((), doc="Moving discs.")
    clutter: ClutterSpec = field(default_factory=ClutterSpec,
                                 metadata={"doc": "Seeded random disc obstacles."})
    generate: GenerateSpec = field(default_factory=GenerateSpec,
                                   metadata={"doc": "A world drawn from the seed."})

    def check(self, src: str, key: str) -> None:
        """Exactly one source of the grid extent."""
        if self.map_ascii is not None and self.map_image is not None:
            raise ScenarioError(src, f"{key}.map_image", "give map_ascii or map_image, not both")
        if self.map_yaml is not None and (self.map_ascii is not None or self.map_image is not None):
            other = "map_ascii" if self.map_ascii is not None else "map_image"
            raise ScenarioError(src, f"{key}.map_yaml", f"give map_yaml or {other}, not both")
        if (self.map_ascii is None and self.map_image is None and self.map_yaml is None
                and self.size is None):
            raise ScenarioError(src, f"{key}.size", "is required when there is no map_ascii, "
                                                    "map_image or map_yaml")


#: ``[world]`` keys that a map_server YAML replaces, and why giving them is an error.
MAP_YAML_SETS = {"resolution": "is set by the map YAML (its resolution, in m/cell)",
                 "origin": "is set by the map YAML (its origin)",
                 "image_threshold": "does not apply to a map YAML (its occupied_thresh and "
                                    "free_thresh do)"}


def check_map_yaml_keys(world: Any, src: str) -> None:
    """With ``world.map_yaml``, the keys its YAML sets must not be given in the scenario.

    Reads the ``[world]`` table as written (not the built spec), so that a value
    equal to its default counts as given too.

    Raises:
        ScenarioError: ``world.resolution``, ``world.origin`` or
            ``world.image_threshold`` next to ``world.map_yaml``.
    """
    if not isinstance(world, Mapping) or world.get("map_yaml") is None:
        return
    for name, why in MAP_YAML_SETS.items():
        if name in world:
            raise ScenarioError(src, f"world.{name}", f"{why}: remove it, or drop world.map_yaml")
