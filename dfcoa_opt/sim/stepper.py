"""One step of a batch, split where the controller acts: :meth:`Stepper.sense`, then :meth:`apply`.

A batch has ``S`` slots; a slot holds one run at a time, with its own seed,
generator, world, estimator, stall monitor, clock (its step index ``k``) and log
rows. :class:`~dfcoa_opt.sim.batch.BatchSimulator` fills the slots with its runs
and calls its controller between the two halves; the environments of
:mod:`dfcoa_opt.envs` put a policy's actions there, and start a new run in a
slot whose run ended (:meth:`Stepper.restart`). Rows are the robots of the
active slots, slot after slot in increasing order.

Every per-run value keeps the single run's order of operations (elementwise
arithmetic on all rows, reductions per run along the robot axis, each run's
draws from its own generator in its own order), so a run's log is the log of
the run simulated alone, bit for bit, wherever its clock stands against the
others'.

The controller's observations are made here from what :meth:`Stepper.sense`
saw (:meth:`Stepper.batch_observation`, :meth:`Stepper.run_observation`); each
run's leader, moving discs, disturbances and clearance come from the stepper's
:class:`~dfcoa_opt.sim.lookups.RunLookups`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.control.adapters import convert
from dfcoa_opt.control.base import MovingObstacles, Neighbours, Observation
from dfcoa_opt.core.errors import DfcoaError, RunFailed
from dfcoa_opt.scenario.loader import reseed
from dfcoa_opt.sim.comms import Comms, wanted
from dfcoa_opt.sim.localization import TruthEstimator, make_estimators
from dfcoa_opt.sim.log import BatchLog
from dfcoa_opt.sim.lookups import Batch, RunLookups
from dfcoa_opt.sim.neighbours import batch_proximity, gather, new_contacts
from dfcoa_opt.sim.scans import ScanBook
from dfcoa_opt.sim.stall import StallMonitor
from dfcoa_opt.world.lidar import LaserScan
from dfcoa_opt.world.robots.models import CommandKind, RobotState

if TYPE_CHECKING:
    from dfcoa_opt.control.base import Limits
    from dfcoa_opt.scenario.scenario import Scenario
    from dfcoa_opt.scenario.schema import ScenarioSpec
    from dfcoa_opt.world.lidar import Lidar
    from dfcoa_opt.world.robots.models import RobotModel

FloatArray = NDArray[np.float64]


def is_batched(obj: Any) -> bool:
    """Whether ``obj`` serves every run of a batch in one call (``batched = True``)."""
    return bool(getattr(obj, "batched", False))


class Runs(Batch, Protocol):
    """What the stepper reads of its batch (a :class:`~dfcoa_opt.sim.batch.BatchSimulator`).

    The batch holds the runs' set-up (scenarios, seeds, robot model, LiDARs);
    the stepper steps them. ``scenarios``, ``seeds``, ``group`` and ``lidars``
    change when :meth:`place` gives a slot another run.
    """

    template: Scenario  # the scenario as given; each run's is reseed(template, seed)
    scenarios: list[Scenario]  # each slot's run
    seeds: list[int]  # each slot's seed
    spec: ScenarioSpec  # the runs' common spec
    n: int  # robots per run
    model: RobotModel  # the robots' motion model
    limits: Limits  # what every observation carries
    radius: float  # robot radius, m
    obstacle_range: float  # moving obstacles within it are observed, m
    lidars: list[Lidar | None]  # each world group's LiDAR
    record_scans: bool  # keep the scans in the log

    def place(self, slot: int, seed: int, scenario: Scenario) -> bool:
        """Make ``scenario`` the run of ``slot``; whether it has a world of its own."""

    def lidar_fields(self) -> NDArray[np.float64] | None:
        """Every group's LiDAR grid in one array, or None."""


@dataclass(frozen=True)
class Ended:
    """A run that ended at the last :meth:`Stepper.apply`.

    Attributes:
        slot: Its slot.
        steps: Instants it logged.
        reached: Whether it reached the goal (with the formation settled).
        t_goal: When, s (NaN when not reached).
    """

    slot: int
    steps: int
    reached: bool
    t_goal: float


class Stepper:
    """The state of a batch's runs, stepped in two halves (module docstring).

    Args:
        sim: The batch: scenario(s), seeds, robot model, LiDARs.
        scan_wanted: Whether the controller reads the scan (the LiDAR then
            runs; so it does when the estimator reads it).
    """

    def __init__(self, sim: Runs, scan_wanted: bool) -> None:
        self.sim = sim
        spec, n = sim.spec, sim.n
        self.spec, self.n, self.dt = spec, n, spec.dt
        self.steps = int(math.floor(spec.t_max / self.dt + 1e-9)) + 1
        slots = len(sim.seeds)
        self.rngs = [np.random.default_rng(s) for s in sim.seeds]
        #: each world group's leader track and moving discs, looked up by run
        self.lookups = RunLookups(sim, spec, n, self.dt, self.steps)
        start = [sc.start_pose(rng) for sc, rng in zip(sim.scenarios, self.rngs, strict=True)]
        self.estimators = make_estimators(spec.localization.mode, sim.scenarios)
        if is_batched(self.estimators[0]):
            self.estimators[0].reset_batch(self.rngs)
        else:
            for est, rng in zip(self.estimators, self.rngs, strict=True):
                est.reset(rng)
        self.truth = all(type(x) is TruthEstimator for x in self.estimators)
        self.scanning = sim.lidars[0] is not None and (
            scan_wanted or getattr(self.estimators[0], "uses_scan", True))
        self.state = RobotState.at_rest(np.concatenate(start))
        self.m = len(sim.scenarios[0].world.dynamic)
        self.goal = np.asarray(spec.leader.goal, dtype=float)
        self.robot_ids = np.arange(n)
        self.robot_ids.flags.writeable = False  # the same rows every step
        self.monitors = [self._monitor(sc) for sc in sim.scenarios]
        #: ``(S,)`` stall flags set for all runs by ``apply``'s ``extras``, instead of ``monitors``
        self.stall_flags: NDArray[np.bool_] | None = None
        self.active = np.arange(slots)  # the slots with a run, in row order
        self.k = np.zeros(slots, dtype=np.int64)  # each slot's step index
        self.prev_static = np.zeros(slots * n, dtype=bool)
        self.prev_dyn = np.zeros((slots * n, self.m), dtype=bool)
        self.prev_keys = np.zeros(0, dtype=np.int64)
        self.prev_ptr = np.zeros(slots + 1, dtype=np.int64)
        self.leaders = np.zeros((slots, 5))  # each slot's broadcast leader state
        #: late and lost messages, pose and command noise (None: every key off)
        self.comms = Comms(spec, n, slots, self.rngs) if wanted(spec) else None
        self.leader_ages = np.zeros(slots)  # each slot's leader state's age, s
        self.leaders_now = np.zeros((slots, 5))  # the true states, when the robots' are late
        self.log: BatchLog | None = None
        self.wall = np.zeros(slots)
        self._tick = time.perf_counter()  # run wall times count from start_clock()
        self._s: dict[str, Any] = {}  # what sense() saw, for apply()
        self._owners = np.concatenate((np.arange(n), np.full(self.m, -1)))  # a run's LiDAR discs
        self._rows: tuple[Any, ...] = (None,)  # per-row constants of the last active set
        #: the scans held between LiDAR frames and those recorded (``sim.record_scans``)
        self.scans = ScanBook(slots, self.steps, n, self.dt, spec.sensors.lidar.rate)

    def start_clock(self) -> None:
        """Start counting the runs' wall times (after the controllers' resets)."""
        self._tick = time.perf_counter()

    def _monitor(self, scenario: Any) -> StallMonitor | None:
        spec = self.spec
        return (StallMonitor(scenario.leader_path, self.steps, self.dt,
                             spec.leader.settle_tolerance, spec.metrics)
                if spec.stop_on_deadlock else None)

    # ------------------------------------------------------------------ restart
    def restart(self, slot: int, seed: int) -> None:
        """Start a new run with ``seed`` in ``slot``, whose run has ended, at its step 0.

        The run is the one a batch (or :class:`~dfcoa_opt.sim.simulator.Simulator`)
        gives for ``seed``: its world drawn for the seed, its own generator,
        start noise, estimator and monitor, its log rows cleared. Its rows join
        the others in slot order; its clock starts while the others' go on.

        Raises:
            DfcoaError: ``slot`` still has a run, or the estimator is batched
                (it cannot start one run alone).
        """
        sim, n = self.sim, self.n
        if slot in self.active:
            raise DfcoaError(f"slot {slot} still has a run")
        if is_batched(self.estimators[0]):
            raise DfcoaError("a batched estimator cannot restart one run of its batch")
        sc = reseed(sim.template, seed)
        fresh = sim.place(slot, seed, sc)
        if fresh:  # a world of its own: its leader track and moving discs too
            self.lookups.place(int(sim.group[slot]), sc)
        rng = self.rngs[slot] = np.random.default_rng(seed)
        start = sc.start_pose(rng)
        self.estimators[slot] = make_estimators(self.spec.localization.mode, [sc])[0]
        self.estimators[slot].reset(rng)
        self.monitors[slot] = None if self.stall_flags is not None else self._monitor(sc)
        self.k[slot], self.wall[slot] = 0, 0.0
        if self.log is not None:
            self.log.clear(slot)
        j = int(np.searchsorted(self.active, slot))
        at = j * n
        self.state = self.state.insert(at, start)
        self.prev_static = np.insert(self.prev_static, at, np.zeros(n, dtype=bool))
        self.prev_dyn = np.insert(self.prev_dyn, at, np.zeros((n, self.m), dtype=bool), axis=0)
        self.prev_ptr = np.insert(self.prev_ptr, j + 1, self.prev_ptr[j])
        self.active = np.insert(self.active, j, slot)

    # ------------------------------------------------------------------ sense
    def sense(self) -> None:
        """Sense every active run from the same snapshot (LiDAR, estimate, neighbours, ...)."""
        sim, n, st = self.sim, self.n, self.state
        active, kk = self.active, self.k[self.active]
        a, m = len(active), self.m
        pos = st.pose[:, :2]
        dyn_pos, dyn_vel, dyn_r = self.lookups.moving(active, kk)  # (A, M, 2) twice, (A, M)
        row_r = self.lookups.moving_rows(dyn_r)  # the radii of each row's discs, (1 or A*N, M)
        # centre distances robot -> moving obstacle, (rows, M); sensing and contacts
        dyn_dist = (np.linalg.norm(pos.reshape(a, n, 1, 2) - dyn_pos[:, None], axis=3)
                    .reshape(a * n, m) if m else np.zeros((a * n, 0)))
        lead, slots, at_goal = self.lookups.leader(active, kk)
        scans: list[LaserScan | None] = [None] * a  # per run; views of scan_all made on demand
        scan_all: LaserScan | None = None  # every row's scan, when made in one call
        fields = sim.lidar_fields() if self.scanning and len(sim.lidars) > 1 else None
        if self.scanning and a > 1 and (len(sim.lidars) == 1 or fields is not None):
            scan_all = sim.lidars[0].scan_teams(
                st.pose, n, dyn_pos, dyn_r[0] if self.lookups.one_mover_table else dyn_r,
                sim.radius,
                self._row_constants()[6], None if fields is None else (fields, sim.group[active]))
        elif self.scanning:
            for j, e in enumerate(active):
                rows = slice(j * n, (j + 1) * n)
                scans[j] = sim.lidars[sim.group[e]].scan(
                    st.pose[rows], np.vstack((pos[rows], dyn_pos[j])),
                    np.concatenate((np.full(n, sim.radius), dyn_r[j])), self._owners,
                    self.rngs[e])
        if self.scanning and scan_all is None:  # (one call per run: one run, or unlike grids)
            scan_all = scans[0] if a == 1 else LaserScan(
                scans[0].angle_min, scans[0].angle_increment, scans[0].range_min,
                scans[0].range_max, np.concatenate([s.ranges for s in scans]))
        if scan_all is not None and math.isfinite(self.spec.sensors.lidar.rate):
            scan_all = self.scans.held(scan_all, active, kk)
            scans = [None] * a
        est = self._estimate(scans, scan_all, active)
        comms = self.comms
        if comms is not None:
            est = comms.believed(est, active)
        sensors = self.spec.sensors
        prox = batch_proximity(pos, n, sensors.comm_radius, sensors.max_neighbors,
                               2.0 * sim.radius)
        rows = self._row_constants()
        row_index = (prox.index if a == 1 else  # (one run: its indices are its rows)
                     np.where(prox.index >= 0, prox.index + rows[1], -1))
        if comms is not None and comms.messages:
            got = comms.neighbours(kk, active, est, st.velocity, prox.index)
            nb_index, nb_dist, nb_age = got.index, got.distance, got.age
            team: tuple[Any, Any] = (got.team, got.team_age)
            nb_pos, nb_vel, nb_heading = got.position, got.velocity, got.heading
            row_index = (nb_index if a == 1 else
                         np.where(nb_index >= 0, nb_index + rows[1], -1))
        else:
            nb_index, nb_dist, nb_age = prox.index, prox.distance, None
            team = (None, None)
            nb_pos, nb_vel, nb_heading = gather(row_index, est, st.velocity)
        moving = rows[5]  # no moving obstacle: the same empty arrays every step
        if m:
            mask = dyn_dist - row_r <= sim.obstacle_range
            w = mask[..., None]
            rows_pos, rows_vel = np.repeat(dyn_pos, n, axis=0), np.repeat(dyn_vel, n, axis=0)
            moving = MovingObstacles(np.where(w, rows_pos, 0.0), np.where(w, rows_vel, 0.0),
                                     np.where(mask, row_r, 0.0), mask)
        heard, heard_slots = lead, slots  # the leader state and slots the robots received
        if comms is not None and comms.leader_on:
            stamp, self.leader_ages[active] = comms.leader(kk, active)
            heard, heard_slots, _ = self.lookups.leader(active, stamp)
            self.leaders_now[active] = lead
        self.leaders[active] = heard
        self._s = dict(pos=pos, dyn_pos=dyn_pos, dyn_dist=dyn_dist, dyn_r=row_r, lead=lead,
                       slots=slots,
                       at_goal=at_goal, scans=scans, scan_all=scan_all, est=est, prox=prox,
                       row_index=row_index, nb=(nb_index, nb_pos, nb_vel, nb_heading, nb_dist,
                                                nb_age), moving=moving, heard=heard,
                       heard_slots=heard_slots, team=team)

    def _diverged(self, pose: FloatArray, active: NDArray[np.intp], kk: NDArray[np.int64]
                  ) -> None:
        """Stop the batch: a robot's new pose is NaN or inf (a state beyond float range).

        Raises:
            RunFailed: Naming the run's seed, the robot and the time.
        """
        row = int(np.flatnonzero(~np.isfinite(pose).all(axis=1))[0])
        j, i = divmod(row, self.n)
        raise RunFailed(f"robot {i}'s pose is not finite after t = {kk[j] * self.dt:.6g} s "
                        f"(seed {self.sim.seeds[active[j]]}): a disturbance or command beyond "
                        "float range")

    def _row_constants(self) -> tuple[Any, ...]:
        """Per-row constants of the active set, made again when it changes.

        ``(active, each row's team's first row, robot ids, env, slot offsets,
        empty moving obstacles, the runs' generators)``; steps and observations
        share them, so the arrays are read-only.
        """
        if self._rows[0] is not self.active:  # a restart or an end made a new array
            a, n = len(self.active), self.n
            rows = [(np.arange(a * n) // n * n)[:, None], np.tile(self.robot_ids, a),
                    np.repeat(self.active, n), np.tile(self.sim.scenarios[0].offsets, (a, 1)),
                    np.zeros((a * n, 0, 2)), np.zeros((a * n, 0)), np.zeros((a * n, 0), bool)]
            for arr in rows:
                arr.flags.writeable = False
            self._rows = (self.active, *rows[:4], MovingObstacles(rows[4], rows[4], rows[5],
                          rows[6]), [self.rngs[e] for e in self.active])
        return self._rows

    def _estimate(self, scans: list[LaserScan | None], scan_all: LaserScan | None,
                  active: NDArray[np.intp]) -> FloatArray:
        st, n, est0 = self.state, self.n, self.estimators[0]
        if self.truth:
            return st.pose
        if is_batched(est0):
            return est0.estimate_batch(st.pose, st.twist, scan_all, self.dt,
                                       np.repeat(active, n))
        return np.concatenate([self.estimators[e].estimate(
            st.pose[j * n:(j + 1) * n], st.twist[j * n:(j + 1) * n],
            self._scan(scans, scan_all, j), self.dt) for j, e in enumerate(active)])

    def _scan(self, scans: list[LaserScan | None], scan_all: LaserScan | None,
              j: int) -> LaserScan | None:
        """The ``j``-th active run's scan (a view of ``scan_all`` when made in one call)."""
        if scans[j] is None and scan_all is not None:
            scans[j] = scan_all.take(slice(j * self.n, (j + 1) * self.n))
        return scans[j]

    @property
    def t(self) -> FloatArray:
        """``(A,)`` each active run's time, s."""
        return self.k[self.active] * self.dt

    # ------------------------------------------------------------------ observe
    def batch_observation(self, one_clock: bool = True) -> Observation:
        """The observation of every active run (``env`` = slot; ``leader`` one state a slot).

        Args:
            one_clock: Require the runs to share one clock (a batched controller sees
                one ``t``). With False, runs restarted at different steps give ``t`` NaN.

        Raises:
            DfcoaError: ``one_clock`` and the runs' clocks differ.
        """
        s, n, a = self._s, self.n, len(self.active)
        kk = self.k[self.active]
        same = a == 1 or bool((kk == kk[0]).all())
        if one_clock and not same:
            raise DfcoaError("a batched controller needs the runs of a batch on one clock")
        _, nb_pos, nb_vel, nb_heading, nb_dist, nb_age = s["nb"]
        rows = self._row_constants()
        return Observation(
            float(kk[0] * self.dt) if same else math.nan, self.dt, rows[2], s["est"],
            self.state.velocity, self.state.twist, s["scan_all"],
            Neighbours(s["row_index"], nb_pos, nb_vel, nb_dist, nb_heading, nb_age),
            s["moving"], self.leaders, self.goal, rows[4],
            np.ascontiguousarray(s["heard_slots"]).reshape(a * n, 2), env=rows[3],
            leader_age=self.leader_ages if self.comms is not None else 0.0,
            team=s["team"][0], team_age=s["team"][1], limits=self.sim.limits,
            **self._now(slice(None)))

    def run_observation(self, j: int) -> Observation:
        """The observation of the ``j``-th active run alone (today's single-run Observation)."""
        s, n, e = self._s, self.n, int(self.active[j])
        rows = slice(j * n, (j + 1) * n)
        nb_index, nb_pos, nb_vel, nb_heading, nb_dist, nb_age = s["nb"]
        st = self.state
        nb = Neighbours(nb_index[rows], nb_pos[rows], nb_vel[rows], nb_dist[rows],
                        nb_heading[rows], None if nb_age is None else nb_age[rows])
        return Observation(float(self.k[e] * self.dt), self.dt, self.robot_ids, s["est"][rows],
                           st.velocity[rows], st.twist[rows],
                           self._scan(s["scans"], s["scan_all"], j), nb,
                           s["moving"].take(rows), s["heard"][j], self.goal,
                           self.sim.scenarios[e].offsets, s["heard_slots"][j],
                           leader_age=float(self.leader_ages[e]),
                           team=None if s["team"][0] is None else s["team"][0][rows],
                           team_age=None if s["team"][1] is None else s["team"][1][rows],
                           limits=self.sim.limits, **self._now(j))

    def _now(self, j: int | slice) -> dict[str, Any]:
        """``leader_now`` and ``slot_now`` of the ``j``-th active run (a slice: all), or none."""
        if self.comms is None or not self.comms.leader_on:
            return {}
        s, n = self._s, self.n
        if isinstance(j, slice):  # the batch's: leaders by slot, slots by row
            return {"leader_now": self.leaders_now,
                    "slot_now": np.ascontiguousarray(s["slots"]).reshape(-1, 2)}
        return {"leader_now": s["lead"][j], "slot_now": s["slots"][j].reshape(n, 2)}

    # ------------------------------------------------------------------ apply
    def apply(self, cmd: FloatArray, kind: CommandKind, extras: Any = None) -> list[Ended]:
        """Apply the active rows' commands: move, count contacts, log, stop, drop ended runs.

        Args:
            cmd: ``(R, k)`` commands of ``kind``, one row per active robot.
            kind: Their kind (converted to the robot model's).
            extras: Called as ``extras(log, active, k)`` to log a controller's own
                arrays (steering, filter results) before a run's log is final.

        Returns:
            The runs that ended (their log rows stay until their slot restarts).
        """
        sim, n, spec, s, st = self.sim, self.n, self.spec, self._s, self.state
        active = self.active
        kk, a, m, dt = self.k[active], len(active), self.m, self.dt
        if self.log is None:
            self.log = BatchLog.allocate(len(self.k), self.steps, n, m, cmd.shape[1])
            self.log.t[:] = np.arange(self.steps) * dt
        log, pos, prox = self.log, s["pos"], s["prox"]
        native = convert(cmd, kind, sim.model.native, s["est"], st.velocity, dt,
                         spec.robots.nid_distance)
        if self.comms is not None:
            native = self.comms.command(native, active)
        args = (st, native, dt, self.lookups.disturbance("velocity", kk),
                self.lookups.disturbance("force", kk))
        std = spec.robots.wheel_noise_std
        new_state = sim.model.step(*args) if not std else sim.model.step(  # type: ignore[call-arg]
            *args, wheel_noise=np.concatenate([self.rngs[e].normal(0.0, std, (n, 2))
                                               for e in active]))
        if not np.isfinite(new_state.pose).all():
            self._diverged(new_state.pose, active, kk)
        # -- contacts at t_k
        clearance = self.lookups.clearance(pos, active)
        static_hit = clearance < sim.radius
        dyn_hit = s["dyn_dist"] < sim.radius + s["dyn_r"]
        pairs = prox.key_ptr[1:] - prox.key_ptr[:-1]
        events = (new_contacts(self.prev_keys, self.prev_ptr, prox.contact_keys, prox.key_ptr)
                  + (static_hit & ~self.prev_static).reshape(a, n).sum(axis=1))
        if m:
            events += (dyn_hit & ~self.prev_dyn).reshape(a, n * m).sum(axis=1)
        at = log.write(  # -- log: one write per field for every run
            active, kk, pose=st.pose.reshape(a, n, 3), pose_est=s["est"].reshape(a, n, 3),
            velocity=st.velocity.reshape(a, n, 2), twist=new_state.twist.reshape(a, n, 2),
            leader=s["lead"], slots=s["slots"], clearance=clearance.reshape(a, n),
            min_inter_robot=prox.min_distance, robot_contacts=pairs,
            obstacle_contacts=static_hit.reshape(a, n).sum(axis=1),
            dynamic_contacts=dyn_hit.any(axis=1).reshape(a, n).sum(axis=1) if m else 0,
            collision_events=events, dyn_pos=s["dyn_pos"], command=cmd.reshape(a, n, -1))
        if extras is not None:
            extras(log, active, kk)
        if sim.record_scans and s["scan_all"] is not None:
            self.scans.record(s["scan_all"], active, kk)
        # -- stop conditions
        reached = np.array(s["at_goal"], dtype=bool)
        leader = spec.leader
        if leader.wait_for_formation and reached.any():
            gap = np.hypot(*(pos.reshape(a, n, 2) - s["slots"]).transpose(2, 0, 1))
            reached &= np.all(gap <= leader.settle_tolerance, axis=1)
        ended = reached.copy()
        if spec.stop_on_collision:
            ended |= events > 0
        if self.stall_flags is not None:
            ended |= self.stall_flags[active]
        elif self.monitors.count(None) < len(self.monitors):
            for j, e in enumerate(active):
                mon = self.monitors[e]
                if not ended[j] and mon is not None and mon.update(
                        int(kk[j]), log.pose[e, ..., :2], log.slots[e]):
                    ended[j] = True
        now = time.perf_counter()
        self.wall[at[0]] += (now - self._tick) / a
        self._tick = now
        ended |= kk == self.steps - 1
        self.k[at[0]] += 1
        out: list[Ended] = []
        if ended.any():
            out = [Ended(int(e), int(k) + 1, bool(r), float(k * dt) if r else math.nan)
                   for e, k, r in zip(active[ended], kk[ended], reached[ended], strict=True)]
            keep = ~ended
            rows = np.repeat(keep, n)
            new_state = new_state.rows(rows)
            static_hit, dyn_hit = static_hit[rows], dyn_hit[rows]
            keys = prox.contact_keys[np.repeat(keep, pairs)]
            ptr = np.zeros(int(keep.sum()) + 1, dtype=np.int64)
            np.cumsum(pairs[keep], out=ptr[1:])
            self.active = active[keep]
        else:
            keys, ptr = prox.contact_keys, prox.key_ptr
        self.prev_keys, self.prev_ptr = keys, ptr
        self.prev_static, self.prev_dyn, self.state = static_hit, dyn_hit, new_state
        return out
