"""Data of the scaling study (:mod:`benchmarks.scaling`): per-step samples and their summary.

:class:`Sample` holds the pooled step times of one (controller, N) pair as measured by
:mod:`benchmarks.scaling.measure`; :class:`Summary` the rows and slopes made from them
by :func:`benchmarks.scaling.report.summarise`. Plain data, no imports of the study.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass
class Sample:
    """Per-step times (s) of one or more runs of one controller at one N.

    Attributes:
        act: Controller ``act`` durations.
        step: Whole-step durations (successive ``act`` starts).
        lidar: LiDAR scan durations (sensing of the step that follows).
        query: Neighbour-query (``proximity``) durations.
        rounds: Median ``act`` time of each round, s (noise indicator).
        log_step: ``wall_time / steps`` of each run's log (warm-up included), s.
        notes: Caps and skips.
    """

    act: list[float] = field(default_factory=list)
    step: list[float] = field(default_factory=list)
    lidar: list[float] = field(default_factory=list)
    query: list[float] = field(default_factory=list)
    rounds: list[float] = field(default_factory=list)
    log_step: list[float] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


@dataclass
class Summary:
    """Per-controller results, ready to print.

    Attributes:
        rows: CSV rows, one per (controller, N).
        slopes: Per controller: act/step slopes over all sizes and over N >= UPPER_FROM.
    """

    rows: list[dict[str, Any]]
    slopes: dict[str, dict[str, float]]


def median_ms(a: Sequence[float] | np.ndarray) -> float:
    """Median of per-step times in s, as ms (nan when empty)."""
    return float(np.median(a)) * 1e3 if len(a) else math.nan
