"""Scenario schema: frozen dataclasses, one per TOML section.

Every key is documented here once (doc, unit, bounds); ``scenarios/README.md``
is generated from these definitions (``dfcoa schema``) and a test keeps the two
in sync. Cross-key rules live in each class's ``check`` method and in
:mod:`dfcoa_opt.scenario.loader`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Literal

from dfcoa_opt.core.errors import ScenarioError
from dfcoa_opt.core.params import param
from dfcoa_opt.world.lidar import LidarSpec  # noqa: F401 - re-exported
from dfcoa_opt.world.robots.spec import RobotSpec  # noqa: F401 - re-exported
from dfcoa_opt.world.spec import (  # noqa: F401 - re-exported: the schema is one module
    ClutterSpec,
    DynamicObstacleSpec,
    GenerateSpec,
    ObstacleSpec,
    Vec2,
    WorldSpec,
    _need,
)

Pose = tuple[float, float, float]

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
    allow_start_contact: bool = param(False, doc="Let robots start overlapping each other "
                                                 "(centres closer than 2 x robots.radius, "
                                                 "counted as contacts at t = 0), for runs "
                                                 "that begin in contact on purpose; false: "
                                                 "such a start is an error. Starts outside "
                                                 "the map are refused either way.")

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
    columns: int = param(0, doc="Grid columns; 0 = ceil(sqrt(n)).", ge=0, le=100_000)

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
    goal_radius: float = param(0.5, doc="Leader is at the goal within this distance (a "
                                        "step that would pass the goal is shortened to end "
                                        "on it).",
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
class SensorSpec:
    """What each robot senses besides its own state."""

    lidar: LidarSpec = field(default_factory=LidarSpec, metadata={"doc": "LiDAR."})
    comm_radius: float = param(10.0, doc="Neighbours within this distance are observed.",
                               unit="m", gt=0.0, finite=False)
    max_neighbors: int = param(10, doc="At most this many nearest neighbours are observed.",
                               ge=0, le=100_000)
    obstacle_range: float | None = param(None, doc="Moving obstacles within this distance are "
                                                   "observed; default lidar.range_max.",
                                         unit="m", gt=0.0, finite=False)
    pose_noise_std: float = param(0.0, doc="With localization 'truth': standard deviation of "
                                           "Gaussian noise on the position each robot "
                                           "believes (and broadcasts), drawn every step.",
                                  unit="m", ge=0.0)
    heading_noise_std: float = param(0.0, doc="With localization 'truth': the same on the "
                                              "heading.", unit="rad", ge=0.0)


@dataclass(frozen=True)
class CommsSpec:
    """How the robots' messages travel (docs/comms.md); every key off by default."""

    latency: float = param(0.0, doc="Age of every message a robot receives about another "
                                    "robot (its pose, velocity and what its controller "
                                    "broadcasts); a whole number of steps.", unit="s", ge=0.0)
    dropout: float = param(0.0, doc="Probability that a message from one robot to another is "
                                    "lost at a step; the receiver keeps the last one it got.",
                           ge=0.0, lt=1.0)
    leader_latency: float = param(0.0, doc="Age of the virtual leader's broadcast (its state, "
                                           "hence the slots); a whole number of steps.",
                                  unit="s", ge=0.0)
    leader_dropout: float = param(0.0, doc="Probability that the leader's broadcast is lost at "
                                           "a step, for the whole team.", ge=0.0, lt=1.0)

    @property
    def on(self) -> bool:
        """Whether any message is late or lost."""
        return bool(self.latency or self.dropout or self.leader_latency or self.leader_dropout)


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
    value: Vec2 = param(doc="Disturbance vector, world frame (each component within "
                            "+-1e4).", unit="m/s or N", ge=-1e4, le=1e4)
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


#: The seed ranges a scenario may declare (``[splits]``), in the order tuning uses them.
SPLITS = ("train", "validation", "test")


@dataclass(frozen=True)
class SplitSpec:
    """Disjoint seed ranges: what tuning may see, and what only the final evaluation sees."""

    train: tuple[int, int] | None = param(None, doc="Inclusive [first, last] seeds that tuning "
                                                    "(dfcoa tune) draws its worlds from.", ge=0)
    validation: tuple[int, int] | None = param(None, doc="Inclusive [first, last] seeds kept "
                                                         "for choosing between tuned "
                                                         "configurations.", ge=0)
    test: tuple[int, int] | None = param(None, doc="Inclusive [first, last] seeds of the "
                                                   "held-out evaluation: never tuned on.", ge=0)

    def range_of(self, split: str) -> tuple[int, int] | None:
        """The ``[first, last]`` seeds of ``split`` (None when not declared)."""
        return getattr(self, split)

    def split_of(self, seed: int) -> str | None:
        """The split whose range holds ``seed`` (None: no split does)."""
        return next((name for name in SPLITS if (r := self.range_of(name)) is not None
                     and r[0] <= seed <= r[1]), None)

    def check(self, src: str, key: str) -> None:
        """Each range in order; no two ranges share a seed."""
        for name in SPLITS:
            r = self.range_of(name)
            if r is not None and r[0] > r[1]:
                raise ScenarioError(src, f"{key}.{name}", f"[{r[0]}, {r[1]}]: the first seed "
                                                          "must not exceed the last")
        for i, a in enumerate(SPLITS):
            for b in SPLITS[i + 1:]:
                ra, rb = self.range_of(a), self.range_of(b)
                if ra is not None and rb is not None and ra[0] <= rb[1] and rb[0] <= ra[1]:
                    raise ScenarioError(src, f"{key}.{b}", f"[{rb[0]}, {rb[1]}] overlaps "
                                                           f"{key}.{a} [{ra[0]}, {ra[1]}]: a seed "
                                                           "may belong to one split only")


@dataclass(frozen=True)
class ScenarioSpec:
    """A whole scenario file."""

    world: WorldSpec = param(doc="Map and obstacles.")
    team: TeamSpec = param(doc="Robots and their start.")
    leader: LeaderSpec = param(doc="Virtual leader mission.")
    name: str = param("", doc="Scenario name; default: the file name without .toml.")
    description: str = param("", doc="Free text.")
    dt: float = param(0.1, doc="Control and integration step (at least 1 us).", unit="s",
                      ge=1e-6)
    t_max: float = param(60.0, doc="Time limit; t_max / dt + 1 is at most 1e7 instants.",
                         unit="s", gt=0.0)
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
    comms: CommsSpec = field(default_factory=CommsSpec,
                             metadata={"doc": "Communication: latency and dropout."})
    disturbances: tuple[DisturbanceSpec, ...] = param((), doc="Disturbances.")
    metrics: MetricSpec = field(default_factory=MetricSpec, metadata={"doc": "Metric settings."})
    controllers: dict[str, dict[str, Any]] = param(
        default_factory=dict, doc="Per-controller parameter overrides: [controllers.<id>] key = "
                                  "value.")
    splits: SplitSpec = field(default_factory=SplitSpec,
                              metadata={"doc": "Disjoint train / validation / test seed ranges "
                                               "(docs/heldout.md)."})

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
        for name in ("latency", "leader_latency"):
            if getattr(self.comms, name) > self.t_max:
                raise ScenarioError(src, f"comms.{name}", f"({getattr(self.comms, name):g} s) "
                                    f"exceeds t_max ({self.t_max:g} s): no message would "
                                    "arrive within the run")
            steps = getattr(self.comms, name) / self.dt
            if abs(steps - round(steps)) > 1e-9 * max(1.0, steps):
                raise ScenarioError(src, f"comms.{name}", f"({getattr(self.comms, name)} s) is "
                                    f"not a whole number of steps of dt = {self.dt} s")
        noisy = self.sensors.pose_noise_std or self.sensors.heading_noise_std
        if noisy and self.localization.mode != "truth":
            raise ScenarioError(src, "sensors.pose_noise_std", "applies to localization 'truth' "
                                f"only, not '{self.localization.mode}' (an estimator has its "
                                "own noise)")
        if self.formation.shape == "rectangle" and self.team.n != 4:
            raise ScenarioError(src, "formation.shape", f"'rectangle' (paper 000 eq 3-5) places "
                                f"4 robots, team.n = {self.team.n}")
        n_off = len(self.formation.offsets)
        if self.formation.shape in ("offsets", "polar") and n_off != self.team.n:
            raise ScenarioError(src, "formation.offsets", f"has {len(self.formation.offsets)} "
                                f"entries, team.n = {self.team.n}")
