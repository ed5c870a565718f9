"""``learned``: a small MLP policy cloned from ``goto_slot+cbf`` (BC + DAgger).

The network reads each robot's observation vector
(:func:`dfcoa_opt.control.features.flatten`: slot, heading, velocities, 40
LiDAR beams, 4 neighbours, 2 moving obstacles, in the robot's frame) and gives
a body-frame velocity command (m/s), converted for unicycles by the
simulator's near-identity map like every velocity controller. It runs the
shipped policy file ``learned.json`` (+ ``learned.npz``) through the machinery
of ``policy:PATH`` (:mod:`dfcoa_opt.control.policy.controller`): the same checks, the
same compiled kernel, batched runs equal single runs bit for bit.

``python -m comparisons.learned.train --seed 0 --out comparisons/learned/``
reproduces the shipped files; ``docs/methods/learned.md`` has the method and
its results.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.control.policy.controller import PolicyController, file_policy_class
from dfcoa_opt.control.policy.file import PREFIX, LoadedPolicy, policy_digest
from dfcoa_opt.control.registry import register
from dfcoa_opt.core.atomic import file_exists
from dfcoa_opt.core.errors import ScenarioError
from dfcoa_opt.core.params import param

#: The shipped policy file (its weights: ``learned.npz`` beside it).
SHIPPED = Path(__file__).resolve().parent / "learned.json"
#: SHA-256 of the shipped spec and weights (:func:`~dfcoa_opt.control.policy.policy_digest`).
#: The results cache fingerprints code, not data: a retrained file must change this line,
#: which re-simulates the stored runs of ``learned``.
SHIPPED_DIGEST = "2ee25b1eca127db2f12a362583e033f7e9742ca0f2e331664ddc643eb2c9be19"


def shipped_policy(path: Path | None = None, expected: str | None = None,
                   name: str = "learned") -> LoadedPolicy:
    """A shipped policy file, loaded and checked (kept while the files are unchanged).

    Args:
        path: The shipped JSON spec, its ``controller.py`` beside it (None:
            :data:`SHIPPED`).
        expected: The SHA-256 that ``controller.py`` records for it (None:
            :data:`SHIPPED_DIGEST`).
        name: The controller id, for the message.

    Raises:
        ScenarioError: A file that does not fit, or shipped files whose digest
            is not ``expected`` (retrained without updating it).
    """
    path = SHIPPED if path is None else path
    expected = SHIPPED_DIGEST if expected is None else expected
    digest = policy_digest(path)
    if digest != expected:
        owner = f"comparisons/{path.parent.name}/controller.py"
        raise ScenarioError(str(path), "", f"SHA-256 {digest[:16]}... is not the one {owner} "
                            f"expects ({expected[:16]}...): after retraining, set "
                            f"SHIPPED_DIGEST to the new digest, so that stored results of "
                            f"'{name}' are rerun")
    return file_policy_class(PREFIX + str(path)).policy


def body_gain(what: str) -> Any:
    """The ``param`` of a tunable gain on one column of a body-frame velocity network."""
    return param(1.0, doc=f"Factor on the network's {what}; 1: the network's own command.",
                 ge=0.0, tune=(0.5, 2.0), scale="log")


class ShippedPolicyController(PolicyController):
    """A shipped policy file (or another, ``Params.policy``) with two gains on its output.

    The base of ``learned`` and ``learned_ppo``: their networks give a body-frame
    velocity, whose two columns ``Params.gain_forward`` and ``Params.gain_lateral``
    scale (the tunable parameters). Subclasses declare ``Params`` and :meth:`shipped`.
    """

    def __init__(self, params: Any = None) -> None:
        super().__init__(params)
        pol = (self.shipped() if not self.p.policy
               else file_policy_class(PREFIX + self.p.policy).policy)
        self.policy = pol
        self.command = pol.spec.command
        self.frame = pol.spec.frame or "body"
        self.spec = pol.spec.observation
        self.uses_scan = self.spec.beams > 0

    def shipped(self) -> LoadedPolicy:
        """The controller's own shipped policy, checked against its recorded digest."""
        raise NotImplementedError

    def forward(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Actions ``(R, 2)`` (m/s, :attr:`frame`) for observation vectors ``(R, D)``.

        The network's rows, times ``(gain_forward, gain_lateral)`` when those are not 1.
        """
        y = self.policy.forward(x)
        if self.p.gain_forward != 1.0 or self.p.gain_lateral != 1.0:
            y = y * np.array([self.p.gain_forward, self.p.gain_lateral])
        return y


@register("learned")
class Learned(ShippedPolicyController):
    """The shipped (or another) policy file's network as a registered controller."""

    @dataclass(frozen=True)
    class Params:
        """Parameters of ``learned``."""

        policy: str = param("", doc="Another policy file (JSON spec) to run instead of the "
                                    "shipped comparisons/learned/learned.json; relative to "
                                    "the working folder. Empty: the shipped one.")
        gain_forward: float = body_gain("forward velocity (body x)")
        gain_lateral: float = body_gain("lateral velocity (body y)")

        def check(self, src: str, key: str) -> None:
            """A ``policy`` file must exist (named with the scenario file and the key)."""
            if self.policy and not file_exists(Path(self.policy)):
                raise ScenarioError(src, f"{key}.policy", f"policy file '{self.policy}' not "
                                    "found (a path relative to the working folder)")

    def shipped(self) -> LoadedPolicy:
        """``learned.json``, checked against :data:`SHIPPED_DIGEST`."""
        return shipped_policy()
