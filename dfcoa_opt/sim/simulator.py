"""Synchronous multi-robot simulator.

One step at ``t_k = k dt``:

1. every robot senses the same snapshot: LiDAR (grid + other robots + moving
   obstacles), neighbours within communication range, moving obstacles within
   sensing range, the leader's broadcast state; its pose comes from the
   estimator (``truth`` or e.g. ``mcl``);
2. the controller returns one command row per robot;
3. the command is adapted to the robot model and all robots integrate at once;
4. contacts are counted (a run goes on after a collision unless
   ``stop_on_collision``), everything is logged, the leader advances.

The run ends when the leader is within ``goal_radius`` of the goal and (unless
``leader.wait_for_formation`` is false) every robot is within
``settle_tolerance`` of its slot, or at ``t_max`` -- or earlier at the first
collision with ``stop_on_collision``, or once the run is stalled
(:class:`dfcoa_opt.outcome.StallMonitor`) with ``stop_on_deadlock``.

The leader follows its path whatever the robots do, so its states and the slots
of every step come from :func:`~dfcoa_opt.sim.leader.leader_track`, computed
once per process for a scenario and shared by its runs (the same numbers as
stepping it inside the loop).
"""

from __future__ import annotations

import math
import time

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt import __version__, dispatch
from dfcoa_opt.control.adapters import convert
from dfcoa_opt.control.base import Controller, MovingObstacles, Neighbours, Observation
from dfcoa_opt.errors import DfcoaError
from dfcoa_opt.geometry import wrap_angle
from dfcoa_opt.localization import make_estimator
from dfcoa_opt.outcome import StallMonitor
from dfcoa_opt.robots.models import RobotState, make_model
from dfcoa_opt.sim.leader import leader_track
from dfcoa_opt.sim.log import RunLog
from dfcoa_opt.sim.neighbours import gather, proximity
from dfcoa_opt.sim.scenario import Scenario
from dfcoa_opt.world.lidar import Lidar

FloatArray = NDArray[np.float64]


class ControllerError(DfcoaError):
    """A controller returned a malformed or non-finite command (the run fails)."""


class Simulator:
    """Runs one scenario with one controller.

    Args:
        scenario: The loaded scenario.
        controller: Any object implementing :class:`~dfcoa_opt.control.base.Controller`.
        seed: Seed of the run's only random generator (default ``scenario.spec.seed``).
            A world drawn from the seed (a clutter field) is drawn again for it
            (:meth:`~dfcoa_opt.sim.scenario.Scenario.for_seed`), so the run is
            that of the file loaded with ``seed``; :attr:`scenario` is the
            scenario that runs.
    """

    def __init__(self, scenario: Scenario, controller: Controller, seed: int | None = None) -> None:
        self.seed = scenario.spec.seed if seed is None else int(seed)
        self.scenario = scenario.for_seed(self.seed)
        scenario = self.scenario
        self.controller = controller
        spec = scenario.spec
        self.model = make_model(spec.robots)
        self.lidar = Lidar(spec.sensors.lidar, scenario.world.grid) if spec.sensors.lidar.enabled \
            else None
        self.n = spec.team.n
        self.radius = spec.robots.radius
        r_obs = spec.sensors.obstacle_range
        self.obstacle_range = spec.sensors.lidar.range_max if r_obs is None else r_obs
        self._dist_v, self._dist_f = self._disturbance_table()

    def _disturbance_table(self) -> tuple[list, list]:
        vel, force = [], []
        spec = self.scenario.spec
        for d in spec.disturbances:
            entry = (spec.robot_index(d.robot), d.t_start, d.t_end, d.value)
            (vel if d.kind == "velocity" else force).append(entry)
        return vel, force

    def _disturbance(self, table: list, t: float) -> FloatArray | None:
        if not table:
            return None
        out = np.zeros((self.n, 2))
        for robot, t0, t1, value in table:
            if t0 <= t < t1:
                out[robot] += value
        return out

    def run(self) -> RunLog:
        """Simulate until the goal is reached (with the formation settled) or ``t_max``.

        Returns:
            The run log; ``log.meta`` holds ``reached_goal``, ``time_to_goal``,
            ``wall_time`` and the run's identity.

        Raises:
            ControllerError: The controller returned a wrong shape, NaN or inf.
        """
        dispatch.check()  # numpy imported before dfcoa_opt runs uncapped: say so, once
        sc, spec = self.scenario, self.scenario.spec
        dt, n = spec.dt, self.n
        rng = np.random.default_rng(self.seed)
        steps = int(math.floor(spec.t_max / dt + 1e-9)) + 1
        dyn = sc.world.dynamic
        m = len(dyn)
        buf: RunLog | None = None  # allocated once the command width is known
        track = leader_track(sc, dt, steps)  # the leader does not depend on the robots
        state = RobotState.at_rest(self._start_pose(rng))
        estimator = make_estimator(spec.localization.mode, sc)
        estimator.reset(rng)
        self.controller.reset(sc, rng)
        # the LiDAR runs only when the controller or the estimator reads the scan
        scanning = self.lidar is not None and (getattr(self.controller, "uses_scan", True)
                                               or getattr(estimator, "uses_scan", True))
        world, cap = sc.world, spec.metrics.clearance_cap
        sensors = spec.sensors
        owners = np.concatenate((np.arange(n), np.full(m, -1)))
        disc_r = np.concatenate((np.full(n, self.radius), dyn.radii))
        prev_pairs: set[int] = set()
        prev_static = np.zeros(n, dtype=bool)
        prev_dyn = np.zeros((n, m), dtype=bool)
        no_dyn = np.zeros((n, 0))  # without moving obstacles: the same empty arrays every step
        no_moving = self._moving_obstacles(no_dyn, np.zeros((0, 2)), np.zeros((0, 2)),
                                           np.zeros(0))
        goal = np.asarray(spec.leader.goal, dtype=float)
        # moving obstacles are a pure function of t: their states at every t_k in one call
        dyn_pos_all, dyn_vel_all = dyn.state(np.arange(steps) * dt)
        dyn_pos_all.flags.writeable = dyn_vel_all.flags.writeable = False  # rows shared below
        reached, t_goal = False, math.nan
        robot_ids = np.arange(n)
        robot_ids.flags.writeable = False  # the same rows every step
        monitor = (StallMonitor(sc.leader_path, steps, dt, spec.leader.settle_tolerance,
                                spec.metrics) if spec.stop_on_deadlock else None)
        wall0 = time.perf_counter()
        k = 0
        for k in range(steps):
            t = k * dt
            pos = state.pose[:, :2]
            dyn_pos, dyn_vel = dyn_pos_all[k], dyn_vel_all[k]
            # centre distances robot -> moving obstacle, (N, M); used by sensing and contacts
            dyn_dist = np.linalg.norm(pos[:, None, :] - dyn_pos[None, :, :], axis=2) if m \
                else no_dyn
            lead, slots = track.state[k], track.slots[k]
            # -- sensing, all from the same snapshot
            scan = None
            if scanning:
                scan = self.lidar.scan(state.pose, np.vstack((pos, dyn_pos)), disc_r, owners, rng)
            est = estimator.estimate(state.pose, state.twist, scan, dt)
            prox = proximity(pos, sensors.comm_radius, sensors.max_neighbors, 2.0 * self.radius)
            nb_pos, nb_vel, nb_heading = gather(prox.index, est, state.velocity)
            nb = Neighbours(prox.index, nb_pos, nb_vel, prox.distance, nb_heading)
            moving = self._moving_obstacles(dyn_dist, dyn_pos, dyn_vel, dyn.radii) if m \
                else no_moving
            obs = Observation(t, dt, robot_ids, est, state.velocity, state.twist, scan, nb,
                              moving, lead, goal, sc.offsets, slots)
            # -- act
            cmd = self._checked(self.controller.act(obs), t)
            if buf is None:
                buf = RunLog.allocate(steps, n, m, cmd.shape[1])
            native = convert(cmd, self.controller.command, self.model.native, est,
                             state.velocity, dt, spec.robots.nid_distance)
            new_state = self.model.step(state, native, dt, self._disturbance(self._dist_v, t),
                                        self._disturbance(self._dist_f, t))
            # -- contacts at t_k
            clearance = world.clearance(pos, cap)
            static_hit = clearance < self.radius
            dyn_hit = dyn_dist < self.radius + dyn.radii[None, :]
            pairs = set(prox.contact_keys.tolist())
            events = (len(pairs - prev_pairs) + int((static_hit & ~prev_static).sum())
                      + int((dyn_hit & ~prev_dyn).sum()))
            prev_pairs, prev_static, prev_dyn = pairs, static_hit, dyn_hit
            # -- log
            buf.t[k] = t
            buf.pose[k], buf.pose_est[k], buf.velocity[k] = state.pose, est, state.velocity
            buf.twist[k], buf.leader[k], buf.slots[k] = new_state.twist, lead, slots
            buf.clearance[k], buf.min_inter_robot[k] = clearance, prox.min_distance
            buf.robot_contacts[k] = len(pairs)
            buf.obstacle_contacts[k] = int(static_hit.sum())
            buf.dynamic_contacts[k] = int(dyn_hit.any(axis=1).sum()) if m else 0
            buf.collision_events[k] = events
            buf.dyn_pos[k], buf.command[k] = dyn_pos, cmd
            steer = getattr(self.controller, "last_steering", None)
            if steer is not None:
                buf.steering[k] = steer
            res = getattr(self.controller, "last_result", None)
            if res is not None:
                buf.filter_status[k], buf.filter_slack[k] = res.status, res.slack
                buf.filter_time[k] = res.solve_time
            # -- stop conditions
            if track.at_goal[k] and (not spec.leader.wait_for_formation or np.all(
                    np.hypot(*(pos - slots).T) <= spec.leader.settle_tolerance)):
                reached, t_goal = True, t
                break
            if spec.stop_on_collision and events:
                break
            if monitor is not None and monitor.update(k, buf.pose[..., :2], buf.slots):
                break
            state = new_state
        wall = time.perf_counter() - wall0
        end = k + 1
        assert buf is not None  # at least one step always runs
        buf.offsets[:], buf.dyn_radius[:] = sc.offsets, dyn.radii
        buf.meta = {
            "scenario": sc.name, "source": sc.source, "controller": self.controller.name,
            "seed": self.seed, "dt": dt, "n": n, "robot_radius": self.radius,
            "robot_model": spec.robots.model, "command_kind": self.controller.command,
            "reached_goal": reached, "time_to_goal": t_goal, "steps": end,
            "wall_time": wall, "version": __version__,
            "leader_path": sc.leader_path.tolist(), "goal": list(spec.leader.goal),
            "settle_tolerance": spec.leader.settle_tolerance,
            "controller_counters": {str(k): int(v) for k, v in
                                    (getattr(self.controller, "counters", None) or {}).items()},
        }
        return buf.truncated(end)

    def _start_pose(self, rng: np.random.Generator) -> FloatArray:
        """Initial poses plus ``team.start_noise`` / ``heading_noise`` (no draw when both are 0).

        A perturbed position that lands on an occupied cell falls back to the
        nominal one, so the run starts as collision-free as the file.
        """
        team = self.scenario.spec.team
        pose = self.scenario.initial_pose.copy()
        if team.start_noise == 0.0 and team.heading_noise == 0.0:
            return pose
        noise = rng.normal(size=(self.n, 3)) * (team.start_noise, team.start_noise,
                                                team.heading_noise)
        grid = self.scenario.world.grid
        moved = pose[:, :2] + noise[:, :2]
        free = grid.in_bounds(*grid.world_to_cell(moved)) & ~grid.is_occupied_at(moved)
        noise[~free, :2] = 0.0
        pose += noise
        pose[:, 2] = wrap_angle(pose[:, 2])
        return pose

    def _moving_obstacles(self, dist: FloatArray, dyn_pos: FloatArray, dyn_vel: FloatArray,
                          radii: FloatArray) -> MovingObstacles:
        """Moving obstacles within sensing range; ``dist`` = (N, M) centre distances."""
        mask = dist - radii[None, :] <= self.obstacle_range
        w = mask[..., None]
        return MovingObstacles(np.where(w, dyn_pos[None], 0.0), np.where(w, dyn_vel[None], 0.0),
                               np.where(mask, radii[None, :], 0.0), mask)

    def _checked(self, cmd: object, t: float) -> FloatArray:
        name = getattr(self.controller, "name", type(self.controller).__name__)
        try:
            arr = np.asarray(cmd, dtype=float)
        except (TypeError, ValueError):
            raise ControllerError(f"controller '{name}' returned a non-numeric command at "
                                  f"t={t:.3f} s") from None
        if arr.ndim != 2 or arr.shape[0] != self.n or arr.shape[1] not in (2, 3):
            raise ControllerError(f"controller '{name}' returned shape {arr.shape} at t={t:.3f} s,"
                                  f" expected ({self.n}, 2)")
        if not np.all(np.isfinite(arr)):
            bad = sorted(set(np.nonzero(~np.isfinite(arr))[0].tolist()))
            raise ControllerError(f"controller '{name}' returned NaN/inf for robot(s) {bad} at "
                                  f"t={t:.3f} s")
        return arr


def run_scenario(scenario: Scenario, controller_id: str, seed: int | None = None) -> RunLog:
    """Build the controller (with the scenario's overrides) and run it.

    Args:
        scenario: The loaded scenario.
        controller_id: Registry id, or ``"<controller>+<filter>"``.
        seed: Run seed; default: the scenario's.
    """
    from dfcoa_opt.control.registry import build_controller

    ctrl = build_controller(controller_id, scenario.spec.controllers, scenario.source)
    return Simulator(scenario, ctrl, seed).run()
