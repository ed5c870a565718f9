"""``mcl``: Monte Carlo localization of every robot (paper 000, Algorithm 3).

One particle filter per robot over its odometry and LiDAR scan on the known map,
as MATLAB's ``monteCarloLocalization`` (see docs/methods/mcl.md). Modules, bottom up:

* :mod:`~dfcoa_opt.sim.localization.mcl.params`: :class:`MclParams`, the
  ``[localization.options]`` of ``mcl``;
* :mod:`~dfcoa_opt.sim.localization.mcl.motion`: the odometry motion model;
* :mod:`~dfcoa_opt.sim.localization.mcl.sensor`: the likelihood-field sensor
  model, its kernels and :class:`Maps` (the per-map likelihood tables);
* :mod:`~dfcoa_opt.sim.localization.mcl.resampling`: low-variance resampling
  with the KLD sample size, and its kernels;
* :mod:`~dfcoa_opt.sim.localization.mcl.filter`: the estimator
  :class:`MonteCarloLocalization`, registered as ``mcl`` when this package is imported.
"""

from __future__ import annotations

from dfcoa_opt.sim.localization.mcl.filter import MonteCarloLocalization
from dfcoa_opt.sim.localization.mcl.motion import (
    MIN_TRANSLATION,
    FloatArray,
    compose_relative,
    decompose_motion,
    sample_motion,
)
from dfcoa_opt.sim.localization.mcl.params import MclParams, Params
from dfcoa_opt.sim.localization.mcl.resampling import (
    kld_sample_size,
    low_variance_resample,
    resample,
)
from dfcoa_opt.sim.localization.mcl.sensor import (
    Maps,
    boundary_cells,
    likelihood_table,
    sensor_update,
    sensor_update_worlds,
)

__all__ = [
    "MIN_TRANSLATION",
    "FloatArray",
    "Maps",
    "MclParams",
    "MonteCarloLocalization",
    "Params",
    "boundary_cells",
    "compose_relative",
    "decompose_motion",
    "kld_sample_size",
    "likelihood_table",
    "low_variance_resample",
    "resample",
    "sample_motion",
    "sensor_update",
    "sensor_update_worlds",
]
