"""DAgger data collection: roll out a teacher/student mixture, record the teacher.

:class:`Mixture` is a batched controller. At every step it computes, from the
same :class:`~dfcoa_opt.control.base.Observation`, the teacher's command
(``goto_slot+cbf``, a world-frame velocity) and the student's (a policy
network, :class:`~dfcoa_opt.control.policy.controller.LoadedPolicy`, in its own frame),
records ``(flatten(obs), teacher command in the policy's frame / action_scale)``
and applies ``beta * teacher + (1 - beta) * student``. With ``beta = 1`` it is
the teacher (plain behaviour cloning), and the student is not evaluated.

Everything is a function of the observation, the runs' seeds and the student's
weights, so a collection is reproducible bit for bit.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.control.base import BatchedController, Observation
from dfcoa_opt.control.features import ObservationSpec, flatten
from dfcoa_opt.control.policy.file import LoadedPolicy
from dfcoa_opt.control.registry import build_controller
from dfcoa_opt.core.geometry import rotate

FloatArray = NDArray[np.float64]
#: The teacher's controller id.
TEACHER = "goto_slot+cbf"


class Mixture(BatchedController):
    """``beta * teacher + (1 - beta) * student`` velocity commands, recording the teacher.

    Args:
        spec: The observation vector of the policy.
        scale: ``(2,)`` the policy's ``action_scale``, m/s: targets are the
            teacher's body-frame command divided by it.
        beta: Weight of the teacher, in [0, 1].
        student: The current policy (body-frame velocity), or None (only with
            ``beta = 1``).
        every: Record every ``every``-th step of each run (1: all).
        teacher_tables: ``[controllers.*]`` tables of the teacher (e.g. the
            ``cbf`` margin); default: the built-in parameters.

    Attributes:
        inputs: Recorded observation vectors, one ``(R, D)`` array per recorded step.
        targets: Recorded targets, one ``(R, 2)`` array per recorded step.
    """

    name = "learned_dagger"
    command = "velocity"
    uses_scan = True

    def __init__(self, spec: ObservationSpec, scale: Sequence[float], beta: float,
                 student: LoadedPolicy | None = None, every: int = 1,
                 teacher_tables: Mapping[str, Mapping[str, Any]] | None = None) -> None:
        if student is None and beta != 1.0:
            raise ValueError("a mixture with beta < 1 needs a student")
        self.spec, self.scale, self.beta, self.student = spec, np.asarray(scale), beta, student
        self.every = every
        self.teacher = build_controller(TEACHER, teacher_tables)
        self.inputs: list[FloatArray] = []
        self.targets: list[FloatArray] = []

    def reset_batch(self, scenarios, rngs) -> None:
        """Reset the teacher for the batch's runs."""
        self.teacher.reset_batch(scenarios, rngs)

    def act(self, obs: Observation) -> FloatArray:
        """The mixed command; records every row's vector and teacher target."""
        teacher = np.asarray(self.teacher.act(obs), dtype=float)[:, :2]
        th = obs.pose[:, 2]
        x = flatten(obs, self.spec)
        if round(obs.t / obs.dt) % self.every == 0:
            self.inputs.append(x)
            self.targets.append(rotate(teacher, -th) / self.scale)  # into the robot's frame
        if self.beta == 1.0 or self.student is None:
            return teacher
        student = rotate(self.student.forward(x), th)
        return self.beta * teacher + (1.0 - self.beta) * student


@dataclass(frozen=True)
class Collected:
    """What one collection gives.

    Attributes:
        x: ``(R, D)`` observation vectors.
        y: ``(R, 2)`` teacher targets (policy frame, / action_scale).
        outcomes: ``metrics["outcome"]`` of each run.
    """

    x: FloatArray
    y: FloatArray
    outcomes: list[str]


def collect(scenario: Any, seeds: Sequence[int], mixture: Mixture) -> Collected:
    """Roll out ``mixture`` on ``scenario`` for ``seeds`` as one batch (``run_batch``).

    Args:
        scenario: A loaded scenario (:func:`dfcoa_opt.load`).
        seeds: The runs' seeds.
        mixture: A fresh :class:`Mixture` (its records are returned).

    Returns:
        The recorded rows and the runs' outcomes.
    """
    from dfcoa_opt.api import run_batch

    runs = run_batch(scenario, mixture, list(seeds))
    outcomes = [str(r.metrics["outcome"]) for r in runs]
    d = mixture.spec.size
    x = np.concatenate(mixture.inputs) if mixture.inputs else np.zeros((0, d))
    y = np.concatenate(mixture.targets) if mixture.targets else np.zeros((0, 2))
    return Collected(x, y, outcomes)
