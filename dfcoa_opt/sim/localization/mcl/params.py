"""Options of ``mcl``: :class:`MclParams`, its ``[localization.options]`` table.

Defaults: paper 000, Algorithm 3 (each field names MATLAB's default beside it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from dfcoa_opt.core.errors import ScenarioError
from dfcoa_opt.core.params import param


@dataclass(frozen=True)
class MclParams:
    """Options of ``mcl`` (``[localization.options]``); defaults = paper 000 Algorithm 3."""

    particle_limits: tuple[int, int] = param(
        (50, 5000), doc="Smallest and largest particle count per robot (paper; MATLAB "
                        "ParticleLimits default [500, 5000]).", ge=1, le=1_000_000)
    initial_covariance: tuple[float, float, float] = param(
        (0.05, 0.05, 0.05), doc="Diagonal of the initial pose covariance (x, y, theta) "
                                "around the start pose (paper; MATLAB default eye(3)).",
        unit="m^2, m^2, rad^2", ge=0.0)
    update_thresholds: tuple[float, float, float] = param(
        (0.01, 0.01, 0.1), doc="The filter updates when the odometry moved more than one of "
                               "these in x, y or theta since the last update (paper; MATLAB "
                               "default [0.2 0.2 0.2]).", unit="m, m, rad", ge=0.0)
    resampling_interval: int = param(1, doc="Resample every this many filter updates "
                                            "(paper and MATLAB default).", ge=1)
    odometry_noise: tuple[float, float, float, float] = param(
        (0.25, 0.25, 0.2, 0.2), doc="Odometry noise alpha1..alpha4 in MATLAB Noise order: "
                                    "rotation from rotation, rotation from translation, "
                                    "translation from translation, translation from "
                                    "rotation (variance coefficients; paper; MATLAB default "
                                    "0.2 each). Used both to simulate the odometry and in "
                                    "the filter's motion model.", ge=0.0)
    rotation_noise: Literal["heading_change", "decomposition"] = param(
        "heading_change", doc="Rotations that scale the odometry noise: half the heading "
                              "change each, or AMCL's folded rot1 and rot2. Equal for any "
                              "differential-drive motion; 'decomposition' takes a sideways "
                              "push for a 90 deg turn and back.")
    sensor_limits: tuple[float, float] = param(
        (0.0, 200.0), doc="Ranges outside [min, max] are ignored; max also divides z_rand "
                          "(paper; MATLAB default [0 12]).", unit="m", ge=0.0)
    num_beams: int = param(120, doc="Beams used per scan, evenly spaced over the scan "
                                    "(paper; MATLAB default 60).", ge=1, le=100_000)
    measurement_noise: float = param(0.25, doc="sigma_hit of the likelihood field (paper; "
                                               "MATLAB default 0.2).", unit="m", gt=0.0)
    expected_measurement_weight: float = param(
        0.97, doc="z_hit, weight of the Gaussian term (paper; MATLAB default 0.95).", ge=0.0)
    random_measurement_weight: float = param(
        0.03, doc="z_rand, weight of the uniform term; absorbs returns from objects not in "
                  "the map such as other robots (paper; MATLAB default 0.05).", ge=0.0)
    max_likelihood_distance: float = param(
        3.5, doc="End-point distances to the map are capped here (paper; MATLAB default 2).",
        unit="m", gt=0.0)
    likelihood_field: Literal["boundary", "occupied"] = param(
        "boundary", doc="Distances are taken to the occupied cells that border free space "
                        "('boundary', what a LiDAR can hit and what a SLAM map holds) or to "
                        "every occupied cell ('occupied', MATLAB/AMCL on a filled map).")
    beam_combination: Literal["product", "amcl"] = param(
        "product", doc="'product': particle likelihood = product of the beam likelihoods "
                       "(Thrun 6.4); 'amcl': AMCL's 1 + sum of cubes.")
    kld_error: float = param(0.05, doc="KLD sampling error bound epsilon (MATLAB/AMCL).",
                             gt=0.0, lt=1.0)
    kld_z: float = param(0.99, doc="KLD normal quantile z, used as given (MATLAB/AMCL pass "
                                   "0.99).", gt=0.0)
    kld_bin_size: tuple[float, float, float] = param(
        (0.5, 0.5, math.pi / 18.0), doc="KLD histogram bin size (x, y, theta) (AMCL "
                                        "defaults; MATLAB does not expose it).",
        unit="m, m, rad", gt=0.0)

    def check(self, src: str, key: str) -> None:
        """Ordered limits, a usable sensor model and KLD bins."""
        if self.particle_limits[0] > self.particle_limits[1]:
            raise ScenarioError(src, f"{key}.particle_limits", "min must be <= max, got "
                                                               f"{list(self.particle_limits)}")
        if self.sensor_limits[0] >= self.sensor_limits[1]:
            raise ScenarioError(src, f"{key}.sensor_limits", "min must be < max, got "
                                                             f"{list(self.sensor_limits)}")
        if self.expected_measurement_weight + self.random_measurement_weight <= 0.0:
            raise ScenarioError(src, f"{key}.expected_measurement_weight",
                                "z_hit + z_rand must be > 0")
        if not 1e-3 <= self.kld_bin_size[2] <= 2.0 * math.pi:
            raise ScenarioError(src, f"{key}.kld_bin_size", "the angular bin must be in "
                                                            "[0.001, 2 pi] rad")
        if min(self.kld_bin_size[:2]) < 1e-3:
            raise ScenarioError(src, f"{key}.kld_bin_size", "the x and y bins must be "
                                                            ">= 0.001 m")


#: The class's former name (``mcl_setup.Params``).
Params = MclParams
