"""The ``nmpc`` controller's ``goto`` fallback command (:mod:`comparisons.nmpc.controller`).

The solve-time and failure statistics of a run are in :mod:`dfcoa_opt.metrics.solver`.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.core.geometry import wrap_angle

if TYPE_CHECKING:
    from comparisons.nmpc.spec import ProblemSpec

FloatArray = NDArray[np.float64]


def goto_command(pose: FloatArray, slot: FloatArray, gain: float, spec: ProblemSpec
                 ) -> FloatArray:
    """Proportional unicycle command towards the slot (the ``goto`` fallback).

    ``v = k (e . heading)``, ``omega = 2 k wrap(atan2(e) - theta)``, clipped to the
    limits, with ``e = slot - p`` (m) and ``k = gain`` (1/s).

    Returns:
        ``(2,)`` (v m/s, omega rad/s).
    """
    e = np.asarray(slot, float) - pose[:2]
    th = float(pose[2])
    v = gain * (e[0] * math.cos(th) + e[1] * math.sin(th))
    err = float(wrap_angle(math.atan2(e[1], e[0]) - th)) if np.hypot(*e) > 1e-9 else 0.0
    return np.array([min(max(v, spec.v_min), spec.v_max),
                     min(max(2.0 * gain * err, -spec.w_max), spec.w_max)])

