"""What a metric reads besides a log's arrays: its settings, the log's step and robot radius.

Every metric function that has settings accepts a
:class:`~dfcoa_opt.scenario.schema.MetricSpec`, a ``ScenarioSpec`` or a
``Scenario`` (whose ``metrics`` section is used), or None for the defaults
(:data:`Settings`); :func:`metric_settings` turns each into the ``MetricSpec``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Union

from dfcoa_opt.scenario.schema import MetricSpec
from dfcoa_opt.sim.log import RunLog

if TYPE_CHECKING:
    from dfcoa_opt.scenario.scenario import Scenario
    from dfcoa_opt.scenario.schema import ScenarioSpec

#: What a metric accepts as its settings.
Settings = Union[MetricSpec, "ScenarioSpec", "Scenario", None]


def metric_settings(spec: Settings) -> MetricSpec:
    """The metric settings of a MetricSpec, ScenarioSpec or Scenario (None: the defaults)."""
    if spec is None:
        return MetricSpec()
    if isinstance(spec, MetricSpec):
        return spec
    holder: Any = getattr(spec, "spec", spec)  # a Scenario holds its ScenarioSpec as .spec
    return holder.metrics


def log_step(log: RunLog) -> float:
    """A log's step in s: ``meta["dt"]``, else the spacing of ``t``, else 1."""
    if log.meta.get("dt") is not None:
        return float(log.meta["dt"])
    return float(log.t[1] - log.t[0]) if len(log.t) > 1 else 1.0


def log_radius(log: RunLog) -> float:
    """A log's robot radius in m from ``meta["robot_radius"]``."""
    if log.meta.get("robot_radius") is None:
        raise ValueError("RunLog.meta has no 'robot_radius'")
    return float(log.meta["robot_radius"])
