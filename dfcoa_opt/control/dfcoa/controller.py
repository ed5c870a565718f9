"""``dfcoa``: the DFCOA controller of paper 000 (the parts composed).

Per robot, from its own observation only (distributed, §4.5.4):

1. the formation tracking law (eq 15-28, :mod:`dfcoa_opt.control.dfcoa.formation_law`)
   drives the robot's tracking point to its slot behind the broadcast virtual
   leader;
2. the improved VFH* with inter-robot repulsion (Algorithm 1,
   :mod:`dfcoa_opt.control.dfcoa.histogram`) turns the robot's LiDAR scan and the
   neighbours it perceives into a safe steering direction;
3. the safety layer of §4.5.3 blends the two: the formation command passes
   unchanged far from obstacles and the VFH* steering overrides it when they
   are close (:func:`dfcoa_opt.control.dfcoa.vfh_star.blend`).

The pose comes from the scenario's estimator (``truth`` or ``mcl``, Algorithm
3). The virtual leader follows the improved A* path by pure pursuit in the
simulator (``leader.planner = "improved_astar"``).

Each step runs the numba versions of 1-3 (``*_fast``, :class:`VFHStar` kernels);
``DFCOA(params, kernel=False)`` runs the NumPy reference functions instead, with
bit-identical commands (``tests/test_dfcoa.py``).

Batched (:class:`~dfcoa_opt.control.base.BatchedController`): one object steps
every run of a batch in one ``act``, each part fed every row at once (each row
with its own run's leader state). The VFH* state (hysteresis, previous
direction) has one row per robot of every run, row ``env * N + robot``; every
row is computed from its own inputs only, so a run's commands are, bit for bit,
those of the run alone (``tests/test_batch.py``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from dfcoa_opt.control.base import BatchedController, Observation, as_batch
from dfcoa_opt.control.dfcoa.formation_law import (
    formation_tracking_law,
    formation_tracking_law_fast,
)
from dfcoa_opt.control.dfcoa.histogram import VFHParams, wrap_angles
from dfcoa_opt.control.dfcoa.vfh_star import VFHStar, blend, blend_fast
from dfcoa_opt.control.registry import register
from dfcoa_opt.core.geometry import wrap_angle
from dfcoa_opt.core.params import param

if TYPE_CHECKING:
    from dfcoa_opt.scenario.scenario import Scenario


@register("dfcoa")
class DFCOA(BatchedController):
    """Formation tracking law (eq 26-28, re-derived) + improved VFH* safety layer.

    Attributes:
        p: Parameters.
        kernel: Step with the numba kernels (False: the NumPy reference, same bits).
        vfh: VFH* state of every robot of every run (None before a reset).
        last_steering: ``(R,)`` VFH* steering direction of each row of the latest
            observation, rad in the robot frame (NaN = none, or no avoidance).
    """

    command = "unicycle"

    @dataclass(frozen=True)
    class Params:
        """Parameters of ``dfcoa`` (Tables 3 and 4 for k1, k2, d)."""

        k1: float = param(2.8, doc="Longitudinal gain k1 of eq 24.", unit="1/s", gt=0.0,
                          tune=(0.5, 8.0), scale="log")
        k2: float = param(0.7, doc="Lateral gain k2 of eq 24.", unit="1/s", gt=0.0,
                          tune=(0.1, 3.0), scale="log")
        d: float = param(0.98, doc="Distance from the robot centre to its tracking point "
                                   "(eq 15).", unit="m", gt=0.0, tune=(0.2, 1.5))
        compensate_tracking_offset: bool = param(
            False, doc="Aim the tracking point d ahead of the slot so that the robot centre, "
                       "not the tracking point, sits on the slot (the paper does not).")
        avoidance: bool = param(True, doc="Use the improved VFH* safety layer (needs a LiDAR).")
        vfh: VFHParams = field(default_factory=VFHParams,
                               metadata={"doc": "Improved VFH* and blending (Algorithm 1)."})

    def __init__(self, params: Params, kernel: bool = True) -> None:
        """``kernel=False`` runs the NumPy reference functions (same bits, slower)."""
        self.p = params
        self.kernel = kernel
        self.vfh: VFHStar | None = None
        self.last_steering: np.ndarray | None = None
        self._n = 0

    def reset_batch(self, scenarios: list[Scenario], rngs: list[np.random.Generator]) -> None:
        """New VFH* state (hysteresis) for the N robots of each of the E runs.

        Args:
            scenarios: One scenario per run (one file: the same team and robots).
            rngs: One generator per run (unused: DFCOA draws nothing).
        """
        sc = scenarios[0]
        vfh = dataclasses.replace(self.p.vfh, robot_radius=sc.spec.robots.radius)
        self._n = sc.n
        self.vfh = VFHStar(vfh, len(scenarios) * sc.n, kernel=self.kernel)
        self.last_steering = np.full(sc.n, np.nan)

    def act(self, obs: Observation) -> np.ndarray:
        """Row i uses robot i's pose, scan, neighbours and the leader state it received.

        Args:
            obs: The observation of one run, or of every active run of a batch.

        Returns:
            ``(R, 2)`` unicycle commands (v m/s, omega rad/s), one per row.
        """
        obs = as_batch(obs)
        fast = self.kernel
        offsets = obs.slot_offset
        if self.p.compensate_tracking_offset:
            offsets = offsets + np.array([self.p.d, 0.0])
        law = formation_tracking_law_fast if fast else formation_tracking_law
        cmd = law(offsets, obs.pose, obs.row_leader(), self.p.k1, self.p.k2, self.p.d)
        if not self.p.avoidance or obs.scan is None or self.vfh is None:
            self.last_steering = np.full(obs.n, np.nan)
            return cmd
        # target direction: towards the slot's tracking target, in the robot frame
        target = obs.slot - obs.pose[:, :2]
        heading = np.arctan2(target[:, 1], target[:, 0])
        target_dir = (wrap_angles if fast else wrap_angle)(heading - obs.pose[:, 2])
        rows = obs.env * self._n + obs.robot_ids  # each robot's own VFH* state row
        res = self.vfh.step(obs.scan, obs.neighbours, obs.pose, target_dir, rows)
        self.last_steering = res.direction
        return (blend_fast if fast else blend)(cmd, res.direction, res.danger, self.p.vfh)
