"""Batched simulation: E runs of one scenario stepped as one array of E x N robots.

A batch is one scenario (the same file and overrides) with E seeds. Each run
keeps its own random generator, world (:func:`~dfcoa_opt.scenario.loader.reseed`: a clutter
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

from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.control.base import Controller, Limits
from dfcoa_opt.core.errors import ControllerError, DfcoaError
from dfcoa_opt.core.runtime import dispatch
from dfcoa_opt.core.runtime.version import __version__
from dfcoa_opt.scenario.budget import check_budget
from dfcoa_opt.scenario.loader import reseed
from dfcoa_opt.scenario.scenario import Scenario, World
from dfcoa_opt.sim.log import BatchLog, RunLog
from dfcoa_opt.sim.stepper import Ended, Stepper, is_batched
from dfcoa_opt.world.lidar import Lidar
from dfcoa_opt.world.robots.models import make_model

FloatArray = NDArray[np.float64]


__all__ = ["BatchSimulator", "ControllerError", "is_batched"]


#: The ``[robots]`` keys a log's meta keeps (``meta["robots"]``): what the deployability
#: report (:mod:`dfcoa_opt.metrics.deploy`) reads.
DEPLOY_ROBOT_KEYS = ("model", "profile", "dynamics", "v_max", "v_min", "w_max", "wheel_radius",
                     "track_width", "wheel_speed_max", "wheel_accel_max", "nid_distance")


class BatchSimulator:
    """Runs one scenario with one controller for several seeds at once.

    Args:
        scenario: The loaded scenario.
        controller: A batched controller (``batched = True``), or one
            controller object per seed (a single object when there is one seed).
        seeds: The runs' seeds (None: the scenario's). Each run is the run of
            :class:`~dfcoa_opt.sim.simulator.Simulator` with that seed.
        record_scans: Keep the LiDAR scans the robots had in each log
            (:attr:`RunLog.scan <dfcoa_opt.sim.log.RunLog>`), when the LiDAR runs
            (the controller or the estimator reads it). The run is the same
            either way; the log grows by ``T x N x beams`` floats.

    Raises:
        DfcoaError: No seeds, or not one unbatched controller per seed.
    """

    def __init__(self, scenario: Scenario, controller: Controller | Sequence[Controller],
                 seeds: Sequence[int | None], record_scans: bool = False) -> None:
        self.record_scans = record_scans
        self.seeds = [scenario.spec.seed if s is None else int(s) for s in seeds]
        if not self.seeds:
            raise DfcoaError("a batch needs at least one seed")
        check_budget(scenario.spec, scenario.source, 0.0, len(self.seeds), record_scans)
        #: The scenario as given; each run's is ``reseed(template, seed)``.
        self.template = scenario
        self.scenarios = [reseed(scenario, s) for s in self.seeds]
        for sc in self.scenarios[1:]:
            self._same_movers(sc)
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
        self.limits = Limits.of(spec.robots)  # what every observation carries
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
        self._stacks: dict[str, Any] = {}  # lidar_fields(), world_shapes(): until place()
        #: Disturbance tables by kind: ``(robot, t_start, t_end, value)``.
        self.disturbances = {kind: [(spec.robot_index(d.robot), d.t_start, d.t_end, d.value)
                                     for d in spec.disturbances if d.kind == kind]
                              for kind in ("velocity", "force")}

    def place(self, slot: int, seed: int, scenario: Scenario) -> bool:
        """Make ``scenario`` (drawn for ``seed``) the run of ``slot``, with its world's group.

        A world no other slot uses any more gives its group to the new one, so a
        long series of runs with seeded worlds keeps at most one world per slot.

        Returns:
            Whether the world is new to the batch (the caller builds its leader track).
        """
        self._same_movers(scenario)
        self.seeds[slot], self.scenarios[slot] = seed, scenario
        for g, sc in enumerate(self.group_scenarios):
            if sc is scenario:
                self.group[slot] = g
                return False
        lidar = (Lidar(self.spec.sensors.lidar, scenario.world.grid)
                 if self.spec.sensors.lidar.enabled else None)
        self._stacks.clear()
        old = int(self.group[slot])
        if np.count_nonzero(self.group == old) == 1:  # only this slot used it: reuse it
            self.group_scenarios[old], self.lidars[old] = scenario, lidar
            return True
        self.group[slot] = len(self.group_scenarios)
        self.group_scenarios.append(scenario)
        self.lidars.append(lidar)
        return True

    def _same_movers(self, scenario: Scenario) -> None:
        """A batch's runs move as many discs (their worlds may move them differently).

        Raises:
            DfcoaError: ``scenario`` has another number of moving discs than the first run.
        """
        m, m0 = len(scenario.world.dynamic), len(self.scenarios[0].world.dynamic)
        if m != m0:
            raise DfcoaError(f"{scenario.source}: seed {scenario.spec.seed} has {m} moving "
                             f"discs and seed {self.seeds[0]} has {m0}: a batch steps runs with "
                             "as many moving discs; run them apart")

    def lidar_fields(self) -> NDArray[np.float64] | None:
        """Every group's LiDAR grid in one array (:meth:`Lidar.stack`), kept until a world changes.

        Row ``g`` is the grid of ``lidars[g]``; None without a LiDAR or when the
        grids differ in geometry.
        """
        if "lidar" not in self._stacks:
            self._stacks["lidar"] = (None if self.lidars[0] is None
                                     else Lidar.stack(self.lidars))  # type: ignore[arg-type]
        return self._stacks["lidar"]

    def world_shapes(self) -> tuple[NDArray, ...] | None:
        """Every group's static shapes stacked (:meth:`World.stacked_shapes`), kept likewise."""
        if "shapes" not in self._stacks:
            self._stacks["shapes"] = World.stacked_shapes(
                [sc.world for sc in self.group_scenarios])
        return self._stacks["shapes"]

    # ------------------------------------------------------------------ helpers
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
        ctrls = self.controllers
        stepper = Stepper(self, getattr(ctrls[0], "uses_scan", True))
        if self.batched:
            ctrls[0].reset_batch(self.scenarios, stepper.rngs)
        else:
            for c, sc, rng in zip(ctrls, self.scenarios, stepper.rngs, strict=True):
                c.reset(sc, rng)
        kind, n = ctrls[0].command, self.n
        stepper.start_clock()
        while len(stepper.active):
            stepper.sense()
            t = float(stepper.t[0])
            if self.batched:
                cmd = self._checked(ctrls[0], ctrls[0].act(stepper.batch_observation()), t,
                                    len(stepper.active) * n)
            else:
                cmds = [self._checked(ctrls[e], ctrls[e].act(stepper.run_observation(j)), t, n)
                        for j, e in enumerate(stepper.active)]
                cmd = cmds[0] if len(cmds) == 1 else np.concatenate(cmds)
            for end in stepper.apply(cmd, kind, self._log_extras):
                assert stepper.log is not None
                yield end.slot, self._finish(stepper, end, ctrls[0 if self.batched else end.slot])

    def _log_extras(self, log: BatchLog, active: NDArray[np.intp], k: NDArray[np.int64]) -> None:
        """The controllers' steering directions and filter results of this step."""
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
        for e, ke in zip(active, k, strict=True):
            c = self.controllers[e]
            steer = getattr(c, "last_steering", None)
            if steer is not None:
                log.steering[e, ke] = steer
            res = getattr(c, "last_result", None)
            if res is not None:
                log.filter_status[e, ke], log.filter_slack[e, ke] = res.status, res.slack
                log.filter_time[e, ke] = res.solve_time

    def _finish(self, stepper: Stepper, end: Ended, controller: Any) -> RunLog:
        """An ended run's :class:`RunLog`, with its meta."""
        e = end.slot
        sc, spec = self.scenarios[e], self.spec
        assert stepper.log is not None
        out = stepper.log.run(e, end.steps, sc.offsets, sc.world.dynamic.radii)
        scan = stepper.scans.recorded(e, end.steps)
        counters = (controller.run_counters(e) if self.batched and
                    hasattr(controller, "run_counters") else getattr(controller, "counters", None))
        out.meta = {
            "scenario": sc.name, "source": sc.source, "controller": controller.name,
            "seed": self.seeds[e], "dt": spec.dt, "n": self.n, "robot_radius": self.radius,
            "robot_model": spec.robots.model, "command_kind": controller.command,
            "reached_goal": end.reached, "time_to_goal": end.t_goal, "steps": end.steps,
            "wall_time": float(stepper.wall[e]), "version": __version__,
            "leader_path": sc.leader_path.tolist(), "goal": list(spec.leader.goal),
            "settle_tolerance": spec.leader.settle_tolerance,
            "robots": {k: getattr(spec.robots, k) for k in DEPLOY_ROBOT_KEYS},
            "controller_counters": {str(k): int(v) for k, v in (counters or {}).items()},
        }
        if scan is not None:
            out.scan, out.meta["scan"] = scan
        return out
