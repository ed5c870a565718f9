"""Pose estimation: where the pose in each observation comes from.

An estimator has ``reset(scenario, rng)`` and
``estimate(true_pose, twist, scan, dt) -> (N, 3)``: it receives the true pose
only to simulate its own sensors (odometry noise); it must not pass it through
unless it is the ``truth`` estimator. Estimators are registered by name; the
scenario picks one with ``[localization] mode``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

_ESTIMATORS: dict[str, Callable[..., Any]] = {}


def register_estimator(name: str) -> Callable[[type], type]:
    """Class decorator registering an estimator under ``name``."""

    def deco(cls: type) -> type:
        _ESTIMATORS[name] = cls
        return cls

    return deco


def estimator_names() -> list[str]:
    """Sorted names of the registered estimators."""
    return sorted(_ESTIMATORS)


def make_estimator(name: str, scenario: Any) -> Any:
    """Instantiate the estimator ``name`` for ``scenario``."""
    return _ESTIMATORS[name](scenario)


@register_estimator("truth")
class TruthEstimator:
    """Ground truth: the observation pose is the true pose."""

    def __init__(self, scenario: Any) -> None:
        self.scenario = scenario

    def reset(self, rng: np.random.Generator) -> None:
        """Nothing to reset."""

    def estimate(self, true_pose: np.ndarray, twist: np.ndarray, scan: Any,
                 dt: float) -> np.ndarray:
        """Return the true pose."""
        return true_pose
