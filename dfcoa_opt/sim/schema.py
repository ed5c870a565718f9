"""Scenario schema: frozen dataclasses, one per TOML section.

Every key is documented here once (doc, unit, bounds); ``scenarios/README.md``
is generated from these definitions (``dfcoa schema``) and a test keeps the two
in sync. Cross-key rules live in each class's ``check`` method and in
:mod:`dfcoa_opt.sim.loader`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Literal

from dfcoa_opt.errors import ScenarioError
from dfcoa_opt.params import param

Vec2 = tuple[float, float]
Pose = tuple[float, float, float]


def _need(src: str, key: str, value: Any, what: str) -> None:
    if value is None or value == ():
        raise ScenarioError(src, key, f"is required {what}")


@dataclass(frozen=True)
class ObstacleSpec:
    """A static geometric obstacle (rasterised into the grid, kept as exact geometry)."""

    type: Literal["polygon", "circle", "rectangle"] = param(doc="Shape kind.")
    vertices: tuple[Vec2, ...] = param((), doc="Polygon vertices, counter-clockwise.", unit="m")
    center: Vec2 | None = param(None, doc="Circle centre.", unit="m")
    radius: float | None = param(None, doc="Circle radius.", unit="m", gt=0.0)
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
    radius_min: float = param(0.2, doc="Smallest disc radius.", unit="m", gt=0.0)
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
    obstacles: tuple[ObstacleSpec, ...] = param((), doc="Static geometric obstacles.")
    dynamic_obstacles: tuple[DynamicObstacleSpec, ...] = param((), doc="Moving discs.")
    clutter: ClutterSpec = field(default_factory=ClutterSpec,
                                 metadata={"doc": "Seeded random disc obstacles."})

    def check(self, src: str, key: str) -> None:
        """Exactly one source of the grid extent."""
        if self.map_ascii is not None and self.map_image is not None:
            raise ScenarioError(src, f"{key}.map_image", "give map_ascii or map_image, not both")
        if self.map_ascii is None and self.map_image is None and self.size is None:
            raise ScenarioError(src, f"{key}.size", "is required when there is no map_ascii "
                                                    "or map_image")


@dataclass(frozen=True)
class RobotSpec:
    """Robot model and its limits (all robots of a team are identical)."""

    model: Literal["unicycle", "single_integrator", "double_integrator"] = param(
        "unicycle", doc="Kinematic model.")
    radius: float = param(0.2, doc="Body radius (collision disc).", unit="m", gt=0.0)
    v_max: float = param(0.5, doc="Largest forward speed (speed norm for integrators).",
                         unit="m/s", gt=0.0)
    v_min: float | None = param(None, doc="Smallest forward speed of a unicycle; default -v_max.",
                                unit="m/s")
    w_max: float = param(1.5, doc="Largest turn rate.", unit="rad/s", gt=0.0)
    a_max: float = param(1.0, doc="Largest acceleration norm (double integrator).",
                         unit="m/s^2", gt=0.0)
    wheel_radius: float = param(0.05, doc="Wheel radius r of paper 000 eq 1-2.", unit="m", gt=0.0)
    track_width: float = param(0.3, doc="Track width d of paper 000 eq 1-2.", unit="m", gt=0.0)
    wheel_speed_max: float = param(math.inf, doc="Largest wheel speed (inf = no limit).",
                                   unit="rad/s", gt=0.0, finite=False)
    nid_distance: float = param(0.1, doc="Offset of the near-identity point used to run "
                                         "velocity commands on unicycles.", unit="m", gt=0.0)
    mass: float = param(1.0, doc="Mass, turns force disturbances into acceleration.",
                        unit="kg", gt=0.0)

    @property
    def v_lower(self) -> float:
        """Effective smallest forward speed in m/s."""
        return -self.v_max if self.v_min is None else self.v_min

    def check(self, src: str, key: str) -> None:
        """v_min <= v_max."""
        if self.v_min is not None and self.v_min > self.v_max:
            raise ScenarioError(src, f"{key}.v_min", f"must be <= v_max ({self.v_max})")


@dataclass(frozen=True)
class TeamSpec:
    """How many robots and where they start."""

    n: int = param(doc="Number of robots.", ge=1, le=100_000)
    placement: Literal["formation", "explicit"] = param(
        "formation", doc="'formation': start on the formation slots around the leader's start; "
                         "'explicit': use poses.")
    poses: tuple[Pose, ...] = param((), doc="Initial (x, y, theta) per robot when explicit.",
                                    unit="m, m, rad")
    ids: tuple[int, ...] = param((), doc="Optional robot labels (unique); default 0..n-1.")
    start_noise: float = param(0.0, doc="Standard deviation of a Gaussian offset added to each "
                                        "start position, drawn from the run's generator (kept "
                                        "only when the new position is free).", unit="m",
                               ge=0.0)
    heading_noise: float = param(0.0, doc="Standard deviation of a Gaussian offset added to "
                                          "each start heading.", unit="rad", ge=0.0)
    start_behind: float = param(0.0, doc="With placement = 'formation': each robot starts this "
                                         "far behind its slot, along the leader's start "
                                         "heading (0: centres on the slots; dfcoa's d puts "
                                         "its tracking point on the slot).", unit="m")

    def check(self, src: str, key: str) -> None:
        """Poses match n; ids unique."""
        if self.placement == "explicit" and len(self.poses) != self.n:
            raise ScenarioError(src, f"{key}.poses",
                                f"has {len(self.poses)} poses, team.n = {self.n}")
        if self.placement == "formation" and self.poses:
            raise ScenarioError(src, f"{key}.poses", "only applies when placement = 'explicit'")
        if self.placement == "explicit" and self.start_behind:
            raise ScenarioError(src, f"{key}.start_behind",
                                "only applies when placement = 'formation'")
        if self.ids:
            if len(self.ids) != self.n:
                raise ScenarioError(src, f"{key}.ids",
                                    f"has {len(self.ids)} ids, team.n = {self.n}")
            if len(set(self.ids)) != len(self.ids):
                dup = sorted({i for i in self.ids if self.ids.count(i) > 1})
                raise ScenarioError(src, f"{key}.ids", f"duplicate robot id(s) {dup}")


@dataclass(frozen=True)
class FormationSpec:
    """Desired formation, as offsets from the virtual leader in its body frame."""

    shape: Literal["rectangle", "offsets", "polar", "v", "line", "grid"] = param(
        "rectangle", doc="rectangle (paper 000 eq 3-5, 4 robots), offsets (x, y), polar (d, phi) "
                         "(paper 000 Alg. 2), v (paper 002 eq 5-6), line, grid.")
    width: float = param(2.0, doc="Rectangle width w (across the heading).", unit="m", gt=0.0)
    length: float = param(2.0, doc="Rectangle length l (along the heading).", unit="m", gt=0.0)
    offsets: tuple[Vec2, ...] = param((), doc="Per-robot (x, y) [offsets] or (d, phi) [polar].",
                                      unit="m or (m, rad)")
    spacing: float = param(1.0, doc="Neighbour spacing for v, line and grid.", unit="m", gt=0.0)
    angle: float = param(math.pi / 6, doc="V half-angle phi between a wing and the backward "
                                          "axis (paper 002 eq 5-6).", unit="rad", gt=0.0,
                         lt=math.pi)
    columns: int = param(0, doc="Grid columns; 0 = ceil(sqrt(n)).", ge=0)

    def check(self, src: str, key: str) -> None:
        """No key that the shape ignores: ``offsets`` need offsets/polar, ``columns`` a grid.

        (``width``, ``length``, ``spacing`` and ``angle`` have defaults, so a
        value given for another shape cannot be told from the default.)
        """
        if self.offsets and self.shape not in ("offsets", "polar"):
            raise ScenarioError(src, f"{key}.offsets", f"does not apply to shape = "
                                                       f"'{self.shape}', which places the robots "
                                                       "itself; use shape = 'offsets' or 'polar'")
        if self.columns and self.shape != "grid":
            raise ScenarioError(src, f"{key}.columns", f"does not apply to shape = "
                                                       f"'{self.shape}', only to 'grid'")


@dataclass(frozen=True)
class LeaderSpec:
    """The virtual leader's mission."""

    start: Vec2 = param(doc="Start position.", unit="m")
    goal: Vec2 = param(doc="Goal position.", unit="m")
    heading: float | None = param(None, doc="Initial heading; default: towards the first path "
                                            "point.", unit="rad")
    speed: float = param(0.3, doc="Desired speed.", unit="m/s", gt=0.0)
    w_max: float = param(1.5, doc="Largest leader turn rate.", unit="rad/s", gt=0.0)
    lookahead: float = param(0.5, doc="Pure-pursuit look-ahead distance.", unit="m", gt=0.0)
    goal_radius: float = param(0.5, doc="Leader is at the goal within this distance.",
                               unit="m", gt=0.0)
    settle_tolerance: float = param(0.5, doc="Formation is settled when every robot is this "
                                             "close to its slot.", unit="m", gt=0.0)
    wait_for_formation: bool = param(True, doc="The run ends when the leader is at the goal "
                                               "and, if true, the formation has settled "
                                               "(paper 000 Algorithm 2 stops at the leader's "
                                               "goal: false).")
    planner: str = param("straight", doc="Global planner of the leader path (registered name).")
    planner_options: dict[str, Any] = param(
        default_factory=dict, doc="Options of the planner, checked against its Params "
                                  "(see docs/methods/).")
    waypoints: tuple[Vec2, ...] = param((), doc="Via points for the 'straight' planner.", unit="m")


@dataclass(frozen=True)
class LidarSpec:
    """2-D LiDAR, the same on every robot (angles in the robot frame)."""

    enabled: bool = param(True, doc="Simulate the LiDAR.")
    beams: int = param(120, doc="Number of beams.", ge=1)
    fov: float = param(2 * math.pi, doc="Field of view, centred on the heading.", unit="rad",
                       gt=0.0, le=2 * math.pi)
    range_min: float = param(0.0, doc="Returns closer than this are reported as -inf.",
                             unit="m", ge=0.0)
    range_max: float = param(10.0, doc="Largest range; beyond it: +inf (no return).", unit="m",
                             gt=0.0)
    noise_std: float = param(0.0, doc="Gaussian range noise standard deviation.", unit="m",
                             ge=0.0)

    def check(self, src: str, key: str) -> None:
        """range_min < range_max: otherwise no return could ever be finite."""
        if self.range_min >= self.range_max:
            raise ScenarioError(src, f"{key}.range_min", f"({self.range_min:g} m) must be below "
                                                         f"range_max ({self.range_max:g} m), or "
                                                         "no return could ever be finite")


@dataclass(frozen=True)
class SensorSpec:
    """What each robot senses besides its own state."""

    lidar: LidarSpec = field(default_factory=LidarSpec, metadata={"doc": "LiDAR."})
    comm_radius: float = param(10.0, doc="Neighbours within this distance are observed.",
                               unit="m", gt=0.0, finite=False)
    max_neighbors: int = param(10, doc="At most this many nearest neighbours are observed.",
                               ge=0)
    obstacle_range: float | None = param(None, doc="Moving obstacles within this distance are "
                                                   "observed; default lidar.range_max.",
                                         unit="m", gt=0.0, finite=False)


@dataclass(frozen=True)
class LocalizationSpec:
    """Where the pose in each observation comes from."""

    mode: str = param("truth", doc="'truth' (ground truth) or a registered estimator, e.g. "
                                   "'mcl'. Shorthand: localization = \"mcl\".")
    options: dict[str, Any] = param(default_factory=dict, doc="Options of the estimator, "
                                                              "checked against its Params.")


@dataclass(frozen=True)
class DisturbanceSpec:
    """An additive disturbance on one robot during a time window."""

    robot: int = param(doc="Robot id: an entry of team.ids, or the 0-based index when there "
                           "are no ids.", ge=0)
    t_start: float = param(doc="Window start.", unit="s", ge=0.0)
    t_end: float = param(doc="Window end (exclusive).", unit="s", ge=0.0)
    value: Vec2 = param(doc="Disturbance vector, world frame.", unit="m/s or N")
    kind: Literal["velocity", "force"] = param(
        "velocity", doc="'velocity': world-frame velocity added to the motion (any model); "
                        "'force': force on a double integrator.")

    def check(self, src: str, key: str) -> None:
        """Window ordering."""
        if self.t_end <= self.t_start:
            raise ScenarioError(src, f"{key}.t_end", f"must be > t_start ({self.t_start})")


@dataclass(frozen=True)
class MetricSpec:
    """Settings of the metrics (docs/metrics.md)."""

    fste_window: float = param(5.0, doc="Window T of the formation stability error, eq 8.",
                               unit="s", gt=0.0)
    stability_threshold: float = param(0.5, doc="A step is stable when the formation shape "
                                                "error (eq 7) is below this.", unit="m", gt=0.0)
    risk_lambda1: float = param(1.0, doc="Inter-robot weight lambda_1 of eq 11.", ge=0.0)
    risk_lambda2: float = param(1.0, doc="Obstacle weight lambda_2 of eq 11.", ge=0.0)
    risk_reference_distance: float = param(
        0.5, doc="Eq 11 is normalised so that one pair at this distance gives risk 1 (clipped "
                 "to [0, 1]).", unit="m", gt=0.0)
    risk_detection_range: float = param(3.5, doc="Obstacles farther than this add no risk.",
                                        unit="m", gt=0.0)
    clearance_cap: float = param(5.0, doc="Obstacle clearances above this are reported as this.",
                                 unit="m", gt=0.0)
    deadlock_window: float = param(10.0, doc="A run is stalled at t when nothing progressed over "
                                             "[t - window, t] (docs/metrics.md, outcomes).",
                                   unit="s", gt=0.0)
    deadlock_advance: float = param(0.2, doc="No progress: the formation centroid advanced less "
                                             "than this along the leader's path in the window.",
                                    unit="m", gt=0.0)
    open_clearance: float = param(1.0, doc="A step is open when every robot keeps at least this "
                                           "surface gap to every static obstacle and moving "
                                           "disc (the *_open_rms metrics).", unit="m", gt=0.0)
    deadlock_displacement: float = param(0.2, doc="No progress: every robot away from its slot "
                                                  "moved less than this in the window.",
                                         unit="m", gt=0.0)


@dataclass(frozen=True)
class ScenarioSpec:
    """A whole scenario file."""

    world: WorldSpec = param(doc="Map and obstacles.")
    team: TeamSpec = param(doc="Robots and their start.")
    leader: LeaderSpec = param(doc="Virtual leader mission.")
    name: str = param("", doc="Scenario name; default: the file name without .toml.")
    description: str = param("", doc="Free text.")
    dt: float = param(0.1, doc="Control and integration step.", unit="s", gt=0.0)
    t_max: float = param(60.0, doc="Time limit.", unit="s", gt=0.0)
    seed: int = param(0, doc="Seed of the run's random generator (CLI --seed overrides).", ge=0)
    stop_on_collision: bool = param(False, doc="End the run at the first collision.")
    stop_on_deadlock: bool = param(False, doc="End the run once it is stalled (metrics."
                                              "deadlock_*): its outcome is then deadlock.")
    robots: RobotSpec = field(default_factory=RobotSpec, metadata={"doc": "Robot model."})
    formation: FormationSpec = field(default_factory=FormationSpec,
                                     metadata={"doc": "Formation shape."})
    sensors: SensorSpec = field(default_factory=SensorSpec, metadata={"doc": "Sensors."})
    localization: LocalizationSpec = field(default_factory=LocalizationSpec,
                                           metadata={"doc": "Localization."})
    disturbances: tuple[DisturbanceSpec, ...] = param((), doc="Disturbances.")
    metrics: MetricSpec = field(default_factory=MetricSpec, metadata={"doc": "Metric settings."})
    controllers: dict[str, dict[str, Any]] = param(
        default_factory=dict, doc="Per-controller parameter overrides: [controllers.<id>] key = "
                                  "value.")

    def robot_index(self, robot_id: int) -> int:
        """Row index of the robot with this id (``team.ids``), or the id itself."""
        return self.team.ids.index(robot_id) if self.team.ids else robot_id

    def check(self, src: str, key: str) -> None:
        """Cross-section rules that need no map."""
        if self.dt > self.t_max:
            raise ScenarioError(src, "dt", f"({self.dt} s) must not exceed t_max ({self.t_max} s)")
        for i, d in enumerate(self.disturbances):
            if self.team.ids and d.robot not in self.team.ids:
                raise ScenarioError(src, f"disturbances[{i}].robot",
                                    f"is {d.robot}, not one of team.ids {list(self.team.ids)}")
            if not self.team.ids and d.robot >= self.team.n:
                raise ScenarioError(src, f"disturbances[{i}].robot",
                                    f"is {d.robot}, but team.n = {self.team.n}")
            if d.kind == "force" and self.robots.model != "double_integrator":
                raise ScenarioError(src, f"disturbances[{i}].kind", "'force' needs "
                                    "robots.model = 'double_integrator'")
        if self.formation.shape == "rectangle" and self.team.n != 4:
            raise ScenarioError(src, "formation.shape", f"'rectangle' (paper 000 eq 3-5) places "
                                f"4 robots, team.n = {self.team.n}")
        n_off = len(self.formation.offsets)
        if self.formation.shape in ("offsets", "polar") and n_off != self.team.n:
            raise ScenarioError(src, "formation.offsets", f"has {len(self.formation.offsets)} "
                                f"entries, team.n = {self.team.n}")
