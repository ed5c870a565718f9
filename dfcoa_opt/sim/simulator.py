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
(:class:`dfcoa_opt.sim.stall.StallMonitor`) with ``stop_on_deadlock``.

The leader follows its path whatever the robots do, so its states and the slots
of every step come from :func:`~dfcoa_opt.sim.leader.leader_track`, computed
once per process for a scenario and shared by its runs (the same numbers as
stepping it inside the loop).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from dfcoa_opt.control.base import Controller
from dfcoa_opt.core.errors import ControllerError
from dfcoa_opt.scenario.scenario import Scenario
from dfcoa_opt.sim.batch import BatchSimulator
from dfcoa_opt.sim.log import RunLog
from dfcoa_opt.sim.stepper import is_batched
from dfcoa_opt.world.lidar import Lidar

__all__ = ["ControllerError", "Simulator", "batch_controllers", "run_batch_logs", "run_scenario"]


class Simulator(BatchSimulator):
    """Runs one scenario with one controller: the batch of one run.

    Args:
        scenario: The loaded scenario.
        controller: Any object implementing :class:`~dfcoa_opt.control.base.Controller`.
        seed: Seed of the run's only random generator (default ``scenario.spec.seed``).
            A world drawn from the seed (a clutter field) is drawn again for it
            (:func:`~dfcoa_opt.scenario.loader.reseed`), so the run is
            that of the file loaded with ``seed``; :attr:`scenario` is the
            scenario that runs.
        record_scans: Keep the LiDAR scans in the log (:class:`BatchSimulator`).
    """

    def __init__(self, scenario: Scenario, controller: Controller, seed: int | None = None,
                 record_scans: bool = False) -> None:
        super().__init__(scenario, controller, [seed], record_scans)
        self.seed = self.seeds[0]
        self.scenario = self.scenarios[0]
        self.controller = controller

    @property
    def lidar(self) -> Lidar | None:
        """The run's LiDAR (None when disabled); replaceable, e.g. by a benchmark's reference."""
        return self.lidars[0]

    @lidar.setter
    def lidar(self, value: Lidar | None) -> None:
        self.lidars[0] = value

    def run(self) -> RunLog:
        """Simulate until the goal is reached (with the formation settled) or ``t_max``.

        Returns:
            The run log; ``log.meta`` holds ``reached_goal``, ``time_to_goal``,
            ``wall_time`` and the run's identity.

        Raises:
            ControllerError: The controller returned a wrong shape, NaN or inf.
        """
        return self.run_all()[0]


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


def batch_controllers(controller_id: str, scenario: Scenario, runs: int) -> Any:
    """What :class:`BatchSimulator` takes for ``runs`` runs of a registry id.

    A batched controller is built once for the batch; any other one once per
    run (each with the scenario's ``[controllers.<id>]`` parameters).
    """
    from dfcoa_opt.control.registry import build_controller

    def build() -> Controller:
        return build_controller(controller_id, scenario.spec.controllers, scenario.source)

    first = build()
    return first if is_batched(first) else [first, *(build() for _ in range(runs - 1))]


def run_batch_logs(scenario: Scenario, controller_id: str,
                   seeds: Sequence[int | None]) -> list[RunLog]:
    """:func:`run_scenario` for several seeds in one batch; the logs in the order of ``seeds``."""
    ctrl = batch_controllers(controller_id, scenario, len(seeds))
    return BatchSimulator(scenario, ctrl, seeds).run_all()
