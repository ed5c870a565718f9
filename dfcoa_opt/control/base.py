"""Controller and safety-filter interfaces, and the per-step observation.

Distributed by construction: :class:`Observation` is batched for speed, but row
``i`` of every array is what robot ``i`` knows -- its own (estimated) state and
scan, the neighbours within communication range, the moving obstacles within
sensing range, its own slot, and the virtual leader's broadcast state. A
controller must compute row ``i`` of its command from row ``i`` of the
observation only; :meth:`Observation.take` and the test helper
``tests/helpers.py::assert_distributed`` check that.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.world.lidar import LaserScan
from dfcoa_opt.world.robots.models import CommandKind
from dfcoa_opt.world.robots.spec import RobotSpec

if TYPE_CHECKING:
    from dfcoa_opt.scenario.scenario import Scenario

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Neighbours:
    """Up to K nearest other robots of each robot, padded with index -1.

    Attributes:
        index: ``(N, K)`` robot indices, -1 where there is no neighbour.
        position: ``(N, K, 2)`` their positions (as they broadcast them), m; 0 when padded.
        velocity: ``(N, K, 2)`` their world velocities, m/s; 0 when padded.
        distance: ``(N, K)`` centre distances, m, ascending; ``inf`` when padded.
        heading: ``(N, K)`` their headings (as they broadcast them), rad; 0 when padded.
            Optional: None where a hand-made table gives no headings.
        age: ``(N, K)`` age of each entry's message, s (``comms.latency`` and the
            steps since the last one that got through; 0 when padded). None when
            every message arrives at once (``[comms]`` off); ``distance`` is then
            the true centre distance, and with ``[comms]`` on the distance from
            the receiver's own pose to the received position.
    """

    index: NDArray[np.intp]
    position: FloatArray
    velocity: FloatArray
    distance: FloatArray
    heading: FloatArray | None = None
    age: FloatArray | None = None

    @property
    def mask(self) -> NDArray[np.bool_]:
        """``(N, K)`` True where a neighbour exists."""
        return self.index >= 0

    def take(self, rows: NDArray[np.intp]) -> Neighbours:
        """The rows of the given robots."""
        return Neighbours(self.index[rows], self.position[rows], self.velocity[rows],
                          self.distance[rows],
                          None if self.heading is None else self.heading[rows],
                          None if self.age is None else self.age[rows])


@dataclass(frozen=True)
class MovingObstacles:
    """Moving obstacles each robot senses (within ``sensors.obstacle_range``), padded.

    Attributes:
        position: ``(N, M, 2)`` m; 0 when padded.
        velocity: ``(N, M, 2)`` m/s; 0 when padded.
        radius: ``(N, M)`` m; 0 when padded.
        mask: ``(N, M)`` True where an obstacle is sensed.
    """

    position: FloatArray
    velocity: FloatArray
    radius: FloatArray
    mask: NDArray[np.bool_]

    def take(self, rows: NDArray[np.intp]) -> MovingObstacles:
        """The rows of the given robots."""
        return MovingObstacles(self.position[rows], self.velocity[rows], self.radius[rows],
                               self.mask[rows])


@dataclass(frozen=True)
class Limits:
    """The robot's limits a controller may plan with (``[robots]``, docs/robots.md).

    Every robot of a team has the same. The simulator enforces them whether a
    controller reads them or not; each method note says whether it does.

    Attributes:
        v_min: Smallest forward speed, m/s.
        v_max: Largest forward speed (speed norm of the integrators), m/s.
        w_max: Largest turn rate, rad/s.
        wheel_radius: Wheel radius, m.
        track_width: Track width, m.
        wheel_speed_max: Largest wheel speed, rad/s (inf: none).
        wheel_accel_max: Largest acceleration of a wheel's rim, m/s^2 (inf: none).
        motor_time_constant: First-order lag of each wheel's speed, s (0: none).
        dynamics: ``"kinematic"`` or ``"actuated"``.
    """

    v_min: float
    v_max: float
    w_max: float
    wheel_radius: float
    track_width: float
    wheel_speed_max: float
    wheel_accel_max: float
    motor_time_constant: float
    dynamics: str

    @classmethod
    def of(cls, spec: RobotSpec) -> Limits:
        """The limits of a ``[robots]`` table (a kinematic robot's acceleration is unbounded)."""
        actuated = spec.dynamics == "actuated"
        return cls(spec.v_lower, spec.v_max, spec.w_max, spec.wheel_radius, spec.track_width,
                   spec.wheel_speed_max, spec.wheel_accel_max if actuated else float("inf"),
                   spec.motor_time_constant if actuated else 0.0, spec.dynamics)


@dataclass(frozen=True)
class Observation:
    """What every robot knows at one step (row i = robot i).

    Attributes:
        t: Time, s.
        dt: Control step, s.
        robot_ids: ``(N,)`` global indices of the rows (``arange(N)`` in a full observation).
        pose: ``(N, 3)`` own pose (x, y, theta) -- the estimate, or truth in 'truth' mode.
        velocity: ``(N, 2)`` own world velocity, m/s.
        twist: ``(N, 2)`` own (v, omega) of the last step.
        scan: Own LiDAR scan (``ranges`` is ``(N, B)``), or None when disabled.
        neighbours: Robots within communication range.
        obstacles: Moving obstacles within sensing range.
        leader: ``(5,)`` broadcast virtual-leader state (x, y, theta, v, omega).
        goal: ``(2,)`` mission goal, m.
        slot_offset: ``(N, 2)`` own slot offset in the leader frame, m.
        slot: ``(N, 2)`` own slot in the world (from ``leader`` and ``slot_offset``), m.
        env: None in the observation of one run. In the observation of a batch
            (given to a controller with ``batched = True``): ``(R,)`` the run of
            each row; rows are run after run, ``robot_ids`` are indices within
            the run, ``leader`` is ``(E, 5)``, one state per run of the batch
            (``leader[env]`` is row i's), and neighbour indices are rows of
            this observation.
        leader_age: Age of the leader state received, s (``comms.leader_latency``
            and the steps since the last broadcast that got through): a number,
            or ``(E,)`` in a batch; 0 with ``[comms]`` off.
        team: ``(N, 5)`` each row's robot as the team's planner at the virtual
            leader last received it (x, y m, theta rad, vx, vy m/s), for a
            central planner; None when messages are neither late nor lost
            (``comms.latency`` and ``comms.dropout`` 0): it then reads ``pose``.
        team_age: ``(N,)`` the age of each of those messages, s; None with ``team``.
        leader_now: The virtual leader's state at this step as its own node (a
            central planner there) knows it: like ``leader``; None when the
            broadcast is neither late nor lost (``leader`` is then the same).
        slot_now: ``(N, 2)`` the slots of ``leader_now``, m; None with it.
        limits: The robots' :class:`Limits` (None where no simulator made the
            observation, e.g. in a hand-built test observation).

    The simulator shares some of these arrays between steps and runs
    (``robot_ids``, ``leader``, ``slot``, and in a batch ``env`` and
    ``slot_offset``): they are read-only, and a controller that wants to change
    one works on a copy.
    """

    t: float
    dt: float
    robot_ids: NDArray[np.intp]
    pose: FloatArray
    velocity: FloatArray
    twist: FloatArray
    scan: LaserScan | None
    neighbours: Neighbours
    obstacles: MovingObstacles
    leader: FloatArray
    goal: FloatArray
    slot_offset: FloatArray
    slot: FloatArray
    env: NDArray[np.intp] | None = None
    leader_age: float | FloatArray = 0.0
    team: FloatArray | None = None
    team_age: FloatArray | None = None
    leader_now: FloatArray | None = None
    slot_now: FloatArray | None = None
    limits: Limits | None = None

    @property
    def n(self) -> int:
        """Number of rows (robots)."""
        return len(self.pose)

    def row_leader(self) -> FloatArray:
        """``(N, 5)`` the leader state each row received (``leader[env]`` in a batch)."""
        if self.env is None:
            return np.broadcast_to(self.leader, (self.n, 5))
        return self.leader[self.env]

    def take(self, rows: NDArray[np.intp] | list[int]) -> Observation:
        """Sub-observation with only the given rows (for checking distributedness)."""
        rows = np.asarray(rows, dtype=np.intp)
        scan = None if self.scan is None else self.scan.take(rows)
        return Observation(self.t, self.dt, self.robot_ids[rows], self.pose[rows],
                           self.velocity[rows], self.twist[rows], scan,
                           self.neighbours.take(rows), self.obstacles.take(rows), self.leader,
                           self.goal, self.slot_offset[rows], self.slot[rows],
                           None if self.env is None else self.env[rows], self.leader_age,
                           None if self.team is None else self.team[rows],
                           None if self.team_age is None else self.team_age[rows],
                           self.leader_now,
                           None if self.slot_now is None else self.slot_now[rows], self.limits)



def slot_velocity(leader: FloatArray, slot: FloatArray) -> FloatArray:
    """World velocity of points fixed in the virtual leader's frame (the slots' feed-forward).

    ``d/dt slot = v_l (cos th_l, sin th_l) + w_l J (slot - p_l)`` with ``J`` the
    rotation by +90 deg: the velocity a slot has while the leader moves with its
    broadcast (v, omega). With ``omega = 0`` it is the leader's velocity.

    Args:
        leader: ``(5,)`` broadcast leader state (x m, y m, theta rad, v m/s, omega rad/s),
            or ``(..., 5)`` one per point (e.g. :meth:`Observation.row_leader`),
            broadcast against ``slot``'s leading axes.
        slot: ``(..., 2)`` world positions of the slots (or any leader-fixed points), m.

    Returns:
        ``(..., 2)`` their world velocities, m/s.
    """
    lead = np.asarray(leader, dtype=float)
    rel = np.asarray(slot, dtype=float) - lead[..., :2]
    th, v, w = lead[..., 2], lead[..., 3], lead[..., 4]
    out = np.empty(rel.shape)
    out[..., 0] = v * np.cos(th) - w * rel[..., 1]
    out[..., 1] = v * np.sin(th) + w * rel[..., 0]
    return out


@runtime_checkable
class Controller(Protocol):
    """A multi-robot controller: one command row per robot.

    Attributes:
        name: Registry id.
        command: Kind of the rows ``act`` returns: ``"unicycle"`` (v, omega),
            ``"velocity"`` (vx, vy) or ``"acceleration"`` (ax, ay).
        uses_scan: Whether ``act`` reads ``obs.scan``. Optional: a controller
            without the attribute gets the scan. When neither the controller
            nor the pose estimator reads it, the simulator does not run the
            LiDAR and ``obs.scan`` is None (a LiDAR scan of 4 robots costs
            about as much as the rest of a simulation step).
        batched: Optional, see :class:`BatchedController`. Without it, the
            simulator makes one object per run and calls it with that run's
            observation.
    """

    name: str
    command: CommandKind

    def reset(self, scenario: Scenario, rng: np.random.Generator) -> None:
        """Prepare for a run; ``rng`` is the run's only source of randomness."""

    def act(self, obs: Observation) -> FloatArray:
        """Return ``(N, k)`` commands, row i computed from row i of ``obs`` only."""


class BatchedController:
    """Base of controllers (and filters) that step every run of a batch in one call.

    With ``batched = True`` the simulator builds one object for a batch of E
    runs (:class:`~dfcoa_opt.sim.batch.BatchSimulator`), calls
    :meth:`reset_batch` once, and :meth:`act` (a filter: ``filter``) once per
    step with the observation of every active run: rows run after run
    (``obs.env`` the run of each row, in increasing order), ``obs.robot_ids``
    the robot within its run, ``obs.leader`` ``(E, 5)`` one state per run
    (:meth:`Observation.row_leader` gives each row's), neighbour indices rows
    of this observation. A run that ends leaves the observation; ``env`` stays
    the run's index, so per-run state is kept by ``env`` (e.g. in rows
    ``env * N + robot_ids``).

    The rows of a batch must be the rows of its runs simulated alone, bit for
    bit: elementwise arithmetic over all rows, any reduction per run along
    the robot axis, and random draws from each run's own generator in the
    run's own order. ``tests/test_batch.py`` checks every registered
    controller so. ``last_steering`` and ``last_result`` hold one entry per
    row; per-run counters come from ``run_counters(env)``.

    :meth:`reset` (one run) and an observation without ``env`` (one run, e.g.
    built by hand) work too: :func:`as_batch` turns it into a batch of one.
    """

    batched = True

    def reset_batch(self, scenarios: list[Scenario], rngs: list[np.random.Generator]) -> None:
        """Prepare for E runs: ``scenarios[e]`` and ``rngs[e]`` are run ``e``'s."""

    def reset(self, scenario: Scenario, rng: np.random.Generator) -> None:
        """Prepare for one run: :meth:`reset_batch` of a batch of one."""
        self.reset_batch([scenario], [rng])


def as_batch(obs: Observation) -> Observation:
    """``obs`` as the observation of a batch: one without ``env`` becomes a batch of one run."""
    if obs.env is not None:
        return obs
    return replace(obs, leader=np.asarray(obs.leader, dtype=float)[None, :],
                   env=np.zeros(obs.n, dtype=np.intp))


#: Filter status codes of :class:`FilterResult` (``RunLog.filter_status`` logs them).
STATUS_OK = 0          # nominal command passed unchanged
STATUS_MODIFIED = 1    # filter changed the command, constraints met
STATUS_FALLBACK = 2    # infeasible: the configured fallback policy was applied
STATUS_SOLVER_FAIL = 3  # solver error: the configured fallback policy was applied
#: A filtered command closer than this to the nominal one is unchanged (STATUS_OK), m/s.
UNCHANGED_TOL = 1e-9


@dataclass
class FilterResult:
    """Output of a safety filter for one step.

    Attributes:
        command: ``(N, k)`` safe commands (the filter's command kind).
        status: ``(N,)`` int8, ``STATUS_*``.
        slack: ``(N,)`` constraint violation left (0 when feasible), in the
            command's units.
        solve_time: ``(N,)`` wall time per robot, s.
    """

    command: FloatArray
    status: NDArray[np.int8]
    slack: FloatArray
    solve_time: FloatArray


@runtime_checkable
class SafetyFilter(Protocol):
    """Maps nominal commands to safe ones.

    Attributes:
        name: Registry id.
        command: Command kind it consumes and returns.
    """

    name: str
    command: CommandKind

    def reset(self, scenario: Scenario, rng: np.random.Generator) -> None:
        """Prepare for a run."""

    def filter(self, obs: Observation, nominal: FloatArray) -> FilterResult:
        """Return safe commands for ``nominal`` (same kind as ``self.command``)."""


@dataclass
class Filtered:
    """A controller whose output passes through a safety filter; itself a Controller.

    The nominal command is converted to the filter's kind with
    :func:`dfcoa_opt.control.adapters.convert` before filtering.

    Attributes:
        controller: The nominal controller.
        safety: The filter.
        last_result: The filter's result at the latest step (the simulator logs it).
    """

    controller: Controller
    safety: SafetyFilter
    last_result: FilterResult | None = field(default=None, init=False)
    _nid: float = field(default=0.1, init=False, repr=False)

    @property
    def name(self) -> str:
        """``controller+filter``."""
        return f"{self.controller.name}+{self.safety.name}"

    @property
    def command(self) -> CommandKind:
        """The filter's command kind."""
        return self.safety.command

    @property
    def uses_scan(self) -> bool:
        """Whether the controller or the filter reads ``obs.scan`` (True without the flag)."""
        return (getattr(self.controller, "uses_scan", True)
                or getattr(self.safety, "uses_scan", True))

    @property
    def batched(self) -> bool:
        """Batched (:class:`BatchedController`) when both parts are."""
        return bool(getattr(self.controller, "batched", False)
                    and getattr(self.safety, "batched", False))

    def reset(self, scenario: Scenario, rng: np.random.Generator) -> None:
        """Reset both parts."""
        self._nid = scenario.spec.robots.nid_distance
        self.controller.reset(scenario, rng)
        self.safety.reset(scenario, rng)
        self.last_result = None

    def reset_batch(self, scenarios: list[Scenario], rngs: list[np.random.Generator]) -> None:
        """Reset both (batched) parts for E runs."""
        self._nid = scenarios[0].spec.robots.nid_distance
        self.controller.reset_batch(scenarios, rngs)  # type: ignore[attr-defined]
        self.safety.reset_batch(scenarios, rngs)  # type: ignore[attr-defined]
        self.last_result = None

    def act(self, obs: Observation) -> FloatArray:
        """Nominal command, converted, then filtered."""
        from dfcoa_opt.control.adapters import convert

        nominal = convert(self.controller.act(obs), self.controller.command, self.safety.command,
                          obs.pose, obs.velocity, obs.dt, self._nid)
        self.last_result = self.safety.filter(obs, nominal)
        return self.last_result.command
