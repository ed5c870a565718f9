"""Pose estimation: where the pose in each observation comes from.

An estimator is built as ``cls(scenario)``, has ``reset(rng)`` and
``estimate(true_pose, twist, scan, dt) -> (N, 3)``: it receives the true pose
only to simulate its own sensors (odometry noise); it must not pass it through
unless it is the ``truth`` estimator. Estimators are registered by name; the
scenario picks one with ``[localization] mode``. An estimator with options
has a ``Params`` dataclass; the scenario's ``[localization.options]`` table is
validated against it at load time (:func:`estimator_options`) and the
estimator reads it the same way. An estimator that never reads the scan says
so with ``uses_scan = False`` (the simulator then may skip the LiDAR). A batch of
runs makes one estimator per run, or one for the batch (:func:`make_estimators`).
The table is :data:`dfcoa_opt.core.registry.ESTIMATORS` (below the scenario
layer, which checks ``[localization]``); an estimator is registered with
``@register_estimator("name")`` and named in the entry-point group
``dfcoa_opt.estimators``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from dfcoa_opt.core.registry import ESTIMATORS


def register_estimator(name: str) -> Callable[[type], type]:
    """Class decorator registering an estimator under ``name``."""
    return ESTIMATORS.register(name)


def estimator_names() -> list[str]:
    """Sorted names of the registered estimators."""
    return ESTIMATORS.names()


def estimator_options(name: str, options: Mapping[str, Any], source: str) -> Any:
    """``[localization.options]`` validated against estimator ``name``'s ``Params``.

    Raises:
        ScenarioError: Unknown or bad key (names ``localization.options.<key>``).
    """
    return ESTIMATORS.options(name, options, source, "localization.options")


def make_estimator(name: str, scenario: Any) -> Any:
    """Instantiate the estimator ``name`` for ``scenario``."""
    return ESTIMATORS.get(name)(scenario)


def make_estimators(name: str, scenarios: list[Any]) -> list[Any]:
    """The estimators of a batch of runs (one scenario per run, in run order).

    A batched estimator (``batched = True``) is one object for the whole batch,
    made by its ``for_batch(scenarios)``, reset by ``reset_batch(rngs)`` and
    asked ``estimate_batch(true_pose, twist, scan, dt, env)`` with every row of
    every active run (``env``: the run of each row), each run's numbers and
    draws those of the run alone. Any other estimator is one object per run.

    Returns:
        ``[the batched estimator]``, or one estimator per scenario.
    """
    cls = ESTIMATORS.get(name)
    if getattr(cls, "batched", False):
        return [cls.for_batch(scenarios)]
    return [cls(sc) for sc in scenarios]


@register_estimator("truth")
class TruthEstimator:
    """Ground truth: the observation pose is the true pose."""

    uses_scan = False

    def __init__(self, scenario: Any) -> None:
        self.scenario = scenario

    def reset(self, rng: np.random.Generator) -> None:
        """Nothing to reset."""

    def estimate(self, true_pose: np.ndarray, twist: np.ndarray, scan: Any,
                 dt: float) -> np.ndarray:
        """Return the true pose."""
        return true_pose
