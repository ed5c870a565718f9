"""``learned_ppo``: a small MLP policy trained by PPO from the environments' reward.

The network reads each robot's observation vector
(:func:`dfcoa_opt.control.features.flatten`: slot, heading, velocities, 40
LiDAR beams, 4 neighbours, 2 moving obstacles, in the robot's frame) and gives
a body-frame velocity command (m/s, at most 0.5 per axis), converted for
unicycles by the simulator's near-identity map, as in the training. It runs
the shipped policy file ``learned_ppo.json`` (+ ``learned_ppo.npz``) through
the machinery of ``policy:PATH`` (:mod:`dfcoa_opt.control.policy.controller`): no torch
at run time, the same checks, the same compiled kernel, batched runs equal
single runs bit for bit.

``python -m comparisons.learned_ppo.train --seed 0`` retrains it;
``docs/methods/learned.md`` has the training, its curve and its results.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from comparisons.learned.controller import ShippedPolicyController, body_gain, shipped_policy
from dfcoa_opt.control.policy.file import LoadedPolicy
from dfcoa_opt.control.registry import register
from dfcoa_opt.core.params import param

#: The shipped policy file (its weights: ``learned_ppo.npz`` beside it).
SHIPPED = Path(__file__).resolve().parent / "learned_ppo.json"
#: SHA-256 of the shipped spec and weights (:func:`~dfcoa_opt.control.policy.policy_digest`).
#: The results cache fingerprints code, not data: a retrained file must change this line,
#: which re-simulates the stored runs of ``learned_ppo``.
SHIPPED_DIGEST = "6674f0d2df7038d23ecef7ea3c69c761c388aa0b162f8f862b9671613610aaad"


@register("learned_ppo")
class LearnedPPO(ShippedPolicyController):
    """The shipped (or another) PPO policy file's network as a registered controller."""

    @dataclass(frozen=True)
    class Params:
        """Parameters of ``learned_ppo``."""

        policy: str = param("", doc="Another policy file (JSON spec) to run instead of the "
                                    "shipped comparisons/learned_ppo/learned_ppo.json; "
                                    "relative to the working folder. Empty: the shipped one.")
        gain_forward: float = body_gain("forward velocity (body x)")
        gain_lateral: float = body_gain("lateral velocity (body y)")

    def shipped(self) -> LoadedPolicy:
        """``learned_ppo.json``, checked against :data:`SHIPPED_DIGEST`."""
        return shipped_policy(SHIPPED, SHIPPED_DIGEST, "learned_ppo")
