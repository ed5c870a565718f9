"""Batched simulation: E runs of one scenario stepped as one array of E x N robots.

A batch is one scenario (the same file and overrides) with E seeds. Each run
keeps its own random generator, world (:meth:`Scenario.for_seed`: a clutter
field follows the seed), leader track, pose estimator, stall monitor, contacts
and log; neighbours, contacts and the LiDAR see only robots of the same run.
The simulator's own work -- neighbour tables, gathering the neighbours' states,
moving obstacles, converting and integrating the commands, clearances, contact
counts, the log -- is done once per step for every row of the batch, so its
interpreter overhead is paid once per step, not once per run. A run that ends
leaves the batch; its log is complete then (:meth:`BatchSimulator.run_iter`
yields it) and identical, bit for bit, to the run simulated alone.

Rows are run after run: the rows of the ``j``-th active run are
``j*N .. j*N+N-1``. Every per-run value keeps the single run's order of
operations (elementwise arithmetic on all rows, reductions per run along the
robot axis), which is what keeps the bits.

A controller with ``batched = True`` gets one :class:`Observation` of every
active run per step (``obs.env``: the run of each row; ``obs.leader``: one
state per run; neighbour indices are rows of that observation) and is reset
once with :meth:`reset_batch(scenarios, rngs)`. Any other controller is one
object per run, called with the single run's :class:`Observation`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt import __version__, dispatch
from dfcoa_opt.control.adapters import convert
from dfcoa_opt.control.base import Controller, MovingObstacles, Neighbours, Observation
from dfcoa_opt.errors import DfcoaError
from dfcoa_opt.localization import TruthEstimator, make_estimators
from dfcoa_opt.outcome import StallMonitor
from dfcoa_opt.robots.models import RobotState, make_model
from dfcoa_opt.sim.leader import LeaderTrack, leader_track
from dfcoa_opt.sim.log import BatchLog, RunLog
from dfcoa_opt.sim.neighbours import batch_proximity, gather, new_contacts
from dfcoa_opt.sim.scenario import Scenario
from dfcoa_opt.world.lidar import LaserScan, Lidar

FloatArray = NDArray[np.float64]


class ControllerError(DfcoaError):
    """A controller returned a malformed or non-finite command (the run fails)."""


def is_batched(controller: Any) -> bool:
    """Whether ``controller`` steps every run of a batch in one ``act`` (``batched = True``)."""
    return bool(getattr(controller, "batched", False))


class BatchSimulator:
    """Runs one scenario with one controller for several seeds at once.

    Args:
        scenario: The loaded scenario.
        controller: A batched controller (``batched = True``), or one
            controller object per seed (a single object when there is one seed).
        seeds: The runs' seeds (None: the scenario's). Each run is the run of
            :class:`~dfcoa_opt.sim.simulator.Simulator` with that seed.

    Raises:
        DfcoaError: No seeds, or not one unbatched controller per seed.
    """

    def __init__(self, scenario: Scenario, controller: Controller | Sequence[Controller],
                 seeds: Sequence[int | None]) -> None:
        self.seeds = [scenario.spec.seed if s is None else int(s) for s in seeds]
        if not self.seeds:
            raise DfcoaError("a batch needs at least one seed")
        self.scenarios = [scenario.for_seed(s) for s in self.seeds]
        if isinstance(controller, Sequence):
            self.controllers = list(controller)
        elif is_batched(controller) or len(self.seeds) == 1:
            self.controllers = [controller]
        else:
            raise DfcoaError(f"controller '{getattr(controller, 'name', controller)}' is not "
                             f"batched: give one object per seed ({len(self.seeds)})")
        self.batched = len(self.controllers) == 1 and is_batched(self.controllers[0])
        if not self.batched and len(self.controllers) != len(self.seeds):
            raise DfcoaError(f"{len(self.controllers)} controllers for {len(self.seeds)} seeds")
        spec = self.scenarios[0].spec
        self.spec = spec
        self.model = make_model(spec.robots)
        self.n = spec.team.n
        self.radius = spec.robots.radius
        r_obs = spec.sensors.obstacle_range
        self.obstacle_range = spec.sensors.lidar.range_max if r_obs is None else r_obs
        # runs that share a scenario object share its world, leader track and LiDAR
        groups: dict[int, int] = {}
        #: One scenario per group of runs that share it (one group unless the world follows
        #: the seed).
        self.group_scenarios: list[Scenario] = []
        for sc in self.scenarios:
            if id(sc) not in groups:
                groups[id(sc)] = len(self.group_scenarios)
                self.group_scenarios.append(sc)
        #: ``(E,)`` each run's group.
        self.group = np.array([groups[id(sc)] for sc in self.scenarios])
        self.lidars = [Lidar(spec.sensors.lidar, sc.world.grid) if spec.sensors.lidar.enabled
                       else None for sc in self.group_scenarios]
        self._disturbances = {kind: [(spec.robot_index(d.robot), d.t_start, d.t_end, d.value)
                                     for d in spec.disturbances if d.kind == kind]
                              for kind in ("velocity", "force")}

    # ------------------------------------------------------------------ set-up helpers
    def _disturbance(self, kind: str, t: float, runs: int) -> FloatArray | None:
        """``(runs*N, 2)`` disturbances of ``kind`` active at ``t`` (None when there are none)."""
        table = self._disturbances[kind]
        if not table:
            return None
        out = np.zeros((self.n, 2))
        for robot, t0, t1, value in table:
            if t0 <= t < t1:
                out[robot] += value
        return out if runs == 1 else np.tile(out, (runs, 1))

    def _moving_obstacles(self, dist: FloatArray, dyn_pos: FloatArray, dyn_vel: FloatArray,
                          radii: FloatArray) -> MovingObstacles:
        """Moving obstacles within sensing range; ``dist`` = (rows, M) centre distances."""
        mask = dist - radii[None, :] <= self.obstacle_range
        w = mask[..., None]
        return MovingObstacles(np.where(w, dyn_pos[None], 0.0), np.where(w, dyn_vel[None], 0.0),
                               np.where(mask, radii[None, :], 0.0), mask)

    def _checked(self, controller: Any, cmd: object, t: float, rows: int) -> FloatArray:
        name = getattr(controller, "name", type(controller).__name__)
        try:
            arr = np.asarray(cmd, dtype=float)
        except (TypeError, ValueError):
            raise ControllerError(f"controller '{name}' returned a non-numeric command at "
                                  f"t={t:.3f} s") from None
        if arr.ndim != 2 or arr.shape[0] != rows or arr.shape[1] not in (2, 3):
            raise ControllerError(f"controller '{name}' returned shape {arr.shape} at t={t:.3f} s,"
                                  f" expected ({rows}, 2)")
        if not np.all(np.isfinite(arr)):
            bad = sorted(set(np.nonzero(~np.isfinite(arr))[0].tolist()))
            raise ControllerError(f"controller '{name}' returned NaN/inf for robot(s) {bad} at "
                                  f"t={t:.3f} s")
        return arr

    # --------------------------------------------------------------------------- run
    def run_all(self) -> list[RunLog]:
        """Simulate every run; their logs in the order of ``seeds``."""
        logs: list[RunLog | None] = [None] * len(self.seeds)
        for e, log in self.run_iter():
            logs[e] = log
        return logs  # type: ignore[return-value]

    def run_iter(self) -> Iterator[tuple[int, RunLog]]:
        """Simulate; yields ``(run index, log)`` as each run ends.

        Raises:
            ControllerError: The controller returned a wrong shape, NaN or inf.
        """
        dispatch.check()  # numpy imported before dfcoa_opt runs uncapped: say so, once
        spec, n, n_runs = self.spec, self.n, len(self.seeds)
        dt = spec.dt
        steps = int(math.floor(spec.t_max / dt + 1e-9)) + 1
        rngs = [np.random.default_rng(s) for s in self.seeds]
        tracks = [leader_track(sc, dt, steps) for sc in self.group_scenarios]
        start = [sc.start_pose(rng) for sc, rng in zip(self.scenarios, rngs, strict=True)]
        estimators = make_estimators(spec.localization.mode, self.scenarios)
        if is_batched(estimators[0]):
            estimators[0].reset_batch(rngs)
        else:
            for est_e, rng in zip(estimators, rngs, strict=True):
                est_e.reset(rng)
        ctrls = self.controllers
        if self.batched:
            ctrls[0].reset_batch(self.scenarios, rngs)
        else:
            for c, sc, rng in zip(ctrls, self.scenarios, rngs, strict=True):
                c.reset(sc, rng)
        truth = all(type(x) is TruthEstimator for x in estimators)
        # the LiDAR runs only when the controller or the estimator reads the scan
        scanning = self.lidars[0] is not None and (getattr(ctrls[0], "uses_scan", True)
                                                   or getattr(estimators[0], "uses_scan", True))
        state = RobotState.at_rest(np.concatenate(start))
        sc0 = self.scenarios[0]
        dyn = sc0.world.dynamic
        m = len(dyn)
        cap, sensors, leader_spec = spec.metrics.clearance_cap, spec.sensors, spec.leader
        owners = np.concatenate((np.arange(n), np.full(m, -1)))
        disc_r = np.concatenate((np.full(n, self.radius), dyn.radii))
        goal = np.asarray(leader_spec.goal, dtype=float)
        dyn_pos_all, dyn_vel_all = dyn.state(np.arange(steps) * dt)
        dyn_pos_all.flags.writeable = dyn_vel_all.flags.writeable = False  # rows shared below
        robot_ids = np.arange(n)
        robot_ids.flags.writeable = False  # the same rows every step
        monitors = [StallMonitor(sc.leader_path, steps, dt, leader_spec.settle_tolerance,
                                 spec.metrics) if spec.stop_on_deadlock else None
                    for sc in self.scenarios]
        one_group = len(tracks) == 1
        kind = ctrls[0].command

        active = np.arange(n_runs)  # the runs still stepping, in row order
        prev_static = np.zeros(n_runs * n, dtype=bool)
        prev_dyn = np.zeros((n_runs * n, m), dtype=bool)
        prev_keys, prev_ptr = np.zeros(0, dtype=np.int64), np.zeros(n_runs + 1, dtype=np.int64)
        leaders = np.zeros((n_runs, 5))  # each run's broadcast leader state (batched obs)
        log: BatchLog | None = None
        wall = np.zeros(n_runs)
        tick = time.perf_counter()
        for k in range(steps):
            t = k * dt
            a = len(active)
            pos = state.pose[:, :2]
            dyn_pos, dyn_vel = dyn_pos_all[k], dyn_vel_all[k]
            # centre distances robot -> moving obstacle, (rows, M); sensing and contacts
            dyn_dist = np.linalg.norm(pos[:, None, :] - dyn_pos[None, :, :], axis=2) if m \
                else np.zeros((a * n, 0))
            lead_a, slots_a, at_goal_a = self._leader(tracks, active, k, one_group)
            # -- sensing, all from the same snapshot
            scans: list[LaserScan | None] = [None] * a
            scan_all: LaserScan | None = None  # every row's scan, when made in one call
            if scanning and one_group and a > 1:
                scan_all = self.lidars[0].scan_teams(state.pose, n, dyn_pos, dyn.radii,
                                                     self.radius, [rngs[e] for e in active])
                scans = [scan_all.take(slice(j * n, (j + 1) * n)) for j in range(a)]
            elif scanning:
                for j, e in enumerate(active):
                    rows = slice(j * n, (j + 1) * n)
                    scans[j] = self.lidars[self.group[e]].scan(
                        state.pose[rows], np.vstack((pos[rows], dyn_pos)), disc_r, owners,
                        rngs[e])
            if truth:
                est = state.pose
            elif is_batched(estimators[0]):
                every = scan_all if scan_all is not None or not scanning else LaserScan(
                    scans[0].angle_min, scans[0].angle_increment, scans[0].range_min,
                    scans[0].range_max, np.concatenate([s.ranges for s in scans]))
                est = estimators[0].estimate_batch(state.pose, state.twist, every, dt,
                                                   np.repeat(active, n))
            else:
                est = np.concatenate([estimators[e].estimate(
                    state.pose[j * n:(j + 1) * n], state.twist[j * n:(j + 1) * n], scans[j], dt)
                    for j, e in enumerate(active)])
            prox = batch_proximity(pos, n, sensors.comm_radius, sensors.max_neighbors,
                                   2.0 * self.radius)
            base = (np.arange(a * n) // n * n)[:, None]
            row_index = np.where(prox.index >= 0, prox.index + base, -1)
            nb_pos, nb_vel, nb_heading = gather(row_index, est, state.velocity)
            moving = self._moving_obstacles(dyn_dist, dyn_pos, dyn_vel, dyn.radii)
            # -- act
            if self.batched:
                leaders[active] = lead_a
                env = np.repeat(active, n)
                scan = scan_all if scan_all is not None or not scanning else LaserScan(
                    scans[0].angle_min, scans[0].angle_increment, scans[0].range_min,
                    scans[0].range_max, np.concatenate([s.ranges for s in scans]))
                obs = Observation(t, dt, np.tile(robot_ids, a), est, state.velocity, state.twist,
                                  scan, Neighbours(row_index, nb_pos, nb_vel, prox.distance,
                                                   nb_heading), moving, leaders, goal,
                                  np.tile(sc0.offsets, (a, 1)),
                                  np.ascontiguousarray(slots_a).reshape(a * n, 2), env=env)
                cmd = self._checked(ctrls[0], ctrls[0].act(obs), t, a * n)
            else:
                cmds = []
                for j, e in enumerate(active):
                    rows = slice(j * n, (j + 1) * n)
                    nb = Neighbours(prox.index[rows], nb_pos[rows], nb_vel[rows],
                                    prox.distance[rows], nb_heading[rows])
                    obs = Observation(t, dt, robot_ids, est[rows], state.velocity[rows],
                                      state.twist[rows], scans[j], nb, moving.take(rows),
                                      lead_a[j], goal, self.scenarios[e].offsets, slots_a[j])
                    cmds.append(self._checked(ctrls[e], ctrls[e].act(obs), t, n))
                cmd = cmds[0] if a == 1 else np.concatenate(cmds)
            if log is None:
                log = BatchLog.allocate(n_runs, steps, n, m, cmd.shape[1])
            native = convert(cmd, kind, self.model.native, est, state.velocity, dt,
                             spec.robots.nid_distance)
            new_state = self.model.step(state, native, dt, self._disturbance("velocity", t, a),
                                        self._disturbance("force", t, a))
            # -- contacts at t_k
            clearance = self._clearance(pos, active, cap, one_group)
            static_hit = clearance < self.radius
            dyn_hit = dyn_dist < self.radius + dyn.radii[None, :]
            pairs = np.diff(prox.key_ptr)
            events = (new_contacts(prev_keys, prev_ptr, prox.contact_keys, prox.key_ptr)
                      + (static_hit & ~prev_static).reshape(a, n).sum(axis=1)
                      + (dyn_hit & ~prev_dyn).reshape(a, n * m).sum(axis=1))
            # -- log
            log.t[k] = t
            log.pose[active, k] = state.pose.reshape(a, n, 3)
            log.pose_est[active, k] = est.reshape(a, n, 3)
            log.velocity[active, k] = state.velocity.reshape(a, n, 2)
            log.twist[active, k] = new_state.twist.reshape(a, n, 2)
            log.leader[active, k] = lead_a
            log.slots[active, k] = slots_a
            log.clearance[active, k] = clearance.reshape(a, n)
            log.min_inter_robot[active, k] = prox.min_distance
            log.robot_contacts[active, k] = pairs
            log.obstacle_contacts[active, k] = static_hit.reshape(a, n).sum(axis=1)
            log.dynamic_contacts[active, k] = (dyn_hit.any(axis=1).reshape(a, n).sum(axis=1)
                                               if m else 0)
            log.collision_events[active, k] = events
            log.dyn_pos[active, k] = dyn_pos
            log.command[active, k] = cmd.reshape(a, n, -1)
            self._log_extras(log, active, k)
            # -- stop conditions
            ended = np.zeros(a, dtype=bool)
            reached = at_goal_a.copy()
            if leader_spec.wait_for_formation and reached.any():
                gap = np.hypot(*(pos.reshape(a, n, 2) - slots_a).transpose(2, 0, 1))
                reached &= np.all(gap <= leader_spec.settle_tolerance, axis=1)
            ended |= reached
            if spec.stop_on_collision:
                ended |= events > 0
            for j, e in enumerate(active):
                if not ended[j] and monitors[e] is not None and monitors[e].update(
                        k, log.pose[e, ..., :2], log.slots[e]):
                    ended[j] = True
            now = time.perf_counter()
            wall[active] += (now - tick) / a
            tick = now
            last = k == steps - 1
            for j in np.flatnonzero(ended | last):
                e = int(active[j])
                yield e, self._finish(log, e, k + 1, bool(reached[j]), t if reached[j] else
                                      math.nan, wall[e], ctrls[0 if self.batched else e])
            if ended.all() or last:
                break
            if ended.any():
                keep = ~ended
                rows = np.repeat(keep, n)
                new_state = RobotState(new_state.pose[rows], new_state.velocity[rows],
                                       new_state.twist[rows])
                static_hit, dyn_hit = static_hit[rows], dyn_hit[rows]
                key_keep = np.repeat(keep, pairs)
                prox_keys = prox.contact_keys[key_keep]
                key_ptr = np.zeros(int(keep.sum()) + 1, dtype=np.int64)
                np.cumsum(pairs[keep], out=key_ptr[1:])
                active = active[keep]
            else:
                prox_keys, key_ptr = prox.contact_keys, prox.key_ptr
            prev_keys, prev_ptr, prev_static, prev_dyn = prox_keys, key_ptr, static_hit, dyn_hit
            state = new_state

    def _leader(self, tracks: list[LeaderTrack], active: NDArray[np.intp], k: int,
                one_group: bool) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
        """Each active run's leader state ``(A, 5)``, slots ``(A, N, 2)``, at-goal flag ``(A,)``."""
        a = len(active)
        if one_group:
            tr = tracks[0]
            return (np.broadcast_to(tr.state[k], (a, 5)),
                    np.broadcast_to(tr.slots[k], (a, *tr.slots.shape[1:])),
                    np.full(a, bool(tr.at_goal[k])))
        runs = [tracks[self.group[e]] for e in active]
        return (np.stack([tr.state[k] for tr in runs]), np.stack([tr.slots[k] for tr in runs]),
                np.array([bool(tr.at_goal[k]) for tr in runs]))

    def _clearance(self, pos: FloatArray, active: NDArray[np.intp], cap: float,
                   one_group: bool) -> FloatArray:
        """Every row's clearance to the static obstacles of its own run's world, m."""
        if one_group:
            return self.group_scenarios[0].world.clearance(pos, cap)
        n = self.n
        return np.concatenate([self.group_scenarios[self.group[e]].world.clearance(
            pos[j * n:(j + 1) * n], cap) for j, e in enumerate(active)])

    def _log_extras(self, log: BatchLog, active: NDArray[np.intp], k: int) -> None:
        """The controllers' steering directions and filter results of step ``k``."""
        n, a = self.n, len(active)
        if self.batched:
            c = self.controllers[0]
            steer = getattr(c, "last_steering", None)
            if steer is not None:
                log.steering[active, k] = np.reshape(steer, (a, n))
            res = getattr(c, "last_result", None)
            if res is not None:
                log.filter_status[active, k] = np.reshape(res.status, (a, n))
                log.filter_slack[active, k] = np.reshape(res.slack, (a, n))
                log.filter_time[active, k] = np.reshape(res.solve_time, (a, n))
            return
        for e in active:
            c = self.controllers[e]
            steer = getattr(c, "last_steering", None)
            if steer is not None:
                log.steering[e, k] = steer
            res = getattr(c, "last_result", None)
            if res is not None:
                log.filter_status[e, k], log.filter_slack[e, k] = res.status, res.slack
                log.filter_time[e, k] = res.solve_time

    def _finish(self, log: BatchLog, e: int, end: int, reached: bool, t_goal: float,
                wall: float, controller: Any) -> RunLog:
        """Run ``e``'s :class:`RunLog` of ``end`` instants, with its meta."""
        sc, spec = self.scenarios[e], self.spec
        out = log.run(e, end, sc.offsets, sc.world.dynamic.radii)
        counters = (controller.run_counters(e) if self.batched and
                    hasattr(controller, "run_counters") else getattr(controller, "counters", None))
        out.meta = {
            "scenario": sc.name, "source": sc.source, "controller": controller.name,
            "seed": self.seeds[e], "dt": spec.dt, "n": self.n, "robot_radius": self.radius,
            "robot_model": spec.robots.model, "command_kind": controller.command,
            "reached_goal": reached, "time_to_goal": t_goal, "steps": end,
            "wall_time": wall, "version": __version__,
            "leader_path": sc.leader_path.tolist(), "goal": list(spec.leader.goal),
            "settle_tolerance": spec.leader.settle_tolerance,
            "controller_counters": {str(k): int(v) for k, v in (counters or {}).items()},
        }
        return out
