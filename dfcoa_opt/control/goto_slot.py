"""``goto_slot``: the smallest useful controller (and the README's example).

Each robot drives towards its own formation slot with proportional control
plus the leader's velocity as feed-forward. It ignores obstacles.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dfcoa_opt.control.base import BatchedController, Observation, slot_velocity
from dfcoa_opt.control.registry import register
from dfcoa_opt.core.params import param


@register("goto_slot")
class GotoSlot(BatchedController):
    """Velocity command ``u_i = kp (slot_i - p_i) + d/dt slot_i``.

    The feed-forward ``d/dt slot_i = v_l (cos th_l, sin th_l) + w_l J (slot_i - p_l)``
    (``J`` = rotation by +90 deg) is the slot's velocity under the leader's motion
    (:func:`~dfcoa_opt.control.base.slot_velocity`).
    """

    command = "velocity"
    uses_scan = False

    @dataclass(frozen=True)
    class Params:
        """Parameters of ``goto_slot``."""

        kp: float = param(1.0, doc="Proportional gain.", unit="1/s", gt=0.0, tune=(0.2, 5.0),
                          scale="log")
        feedforward: bool = param(True, doc="Add the leader's velocity.", tune=(False, True))

    def __init__(self, params: Params) -> None:
        self.p = params

    def act(self, obs: Observation) -> np.ndarray:
        """Row i uses only robot i's pose and slot and the leader state it received."""
        u = self.p.kp * (obs.slot - obs.pose[:, :2])
        if self.p.feedforward:
            u = u + slot_velocity(obs.row_leader(), obs.slot)
        return u
