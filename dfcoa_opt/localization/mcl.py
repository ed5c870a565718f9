"""``mcl``: Monte Carlo localization of every robot (paper 000, Algorithm 3).

Each robot runs its own particle filter over its own odometry and LiDAR scan on
the known map (``GlobalLocalization = false``), as MATLAB's
``monteCarloLocalization`` with an ``odometryMotionModel`` and a
``likelihoodFieldSensorModel``. All robots' particles are kept in one array
(robot ``r`` owns rows ``ptr[r]:ptr[r+1]``), so a step is a few array
operations plus two numba kernels whatever the team size.

Per call of :meth:`MonteCarloLocalization.estimate`:

1. **Odometry** (simulated): the true motion since the last call, split into
   ``(rot1, trans, rot2)`` and perturbed by the ``alpha1..alpha4`` model, is
   added to each robot's odometry pose. This is the only use of the true pose
   (besides centring the initial cloud).
2. **Update test** (MATLAB ``UpdateThresholds``): a robot's filter runs only when
   its odometry moved more than the x, y or theta threshold since its last update.
3. **Motion update**: its particles move by the odometry change since the last
   update, with noise from the same model.
4. **Sensor update**: likelihood field (:mod:`dfcoa_opt.localization.mcl_models`).
5. **Estimate**: the weighted mean position and circular mean heading of the
   robot's particles after the sensor update.
6. **Resampling** every ``resampling_interval`` updates: low-variance, to the
   KLD-adaptive size within ``particle_limits``.

Between updates the estimate follows the odometry (last estimate composed with
the odometry change since that update), so it moves smoothly every step.
The first call initialises the clouds (``particle_limits[1]`` particles from
``N(true pose, diag(initial_covariance))``) and runs a sensor update, as AMCL
does on its first scan. See docs/methods/mcl.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.errors import DfcoaError, ScenarioError
from dfcoa_opt.geometry import wrap_angle
from dfcoa_opt.localization import estimator_options, register_estimator
from dfcoa_opt.localization import mcl_models as mm
from dfcoa_opt.params import param
from dfcoa_opt.world.lidar import LaserScan

FloatArray = NDArray[np.float64]


@register_estimator("mcl")
class MonteCarloLocalization:
    """Batched Monte Carlo localization (one particle filter per robot).

    Args:
        scenario: The loaded scenario (map, team size, LiDAR settings and
            ``[localization.options]``).
        params: Options; default: the scenario's ``[localization.options]``
            validated against :class:`Params` (when its mode is ``mcl``).

    Raises:
        ScenarioError: The scenario's LiDAR is disabled.
    """

    @dataclass(frozen=True)
    class Params:
        """Options of ``mcl`` (``[localization.options]``); defaults = paper 000 Algorithm 3."""

        particle_limits: tuple[int, int] = param(
            (50, 5000), doc="Smallest and largest particle count per robot (paper; MATLAB "
                            "ParticleLimits default [500, 5000]).", ge=1)
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
                                        "(paper; MATLAB default 60).", ge=1)
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

    def __init__(self, scenario: Any, params: Params | None = None) -> None:
        spec = scenario.spec
        if not spec.sensors.lidar.enabled:
            raise ScenarioError(scenario.source, "sensors.lidar.enabled",
                                "localization 'mcl' needs the LiDAR: set it to true or use "
                                "localization = \"truth\"")
        if params is None:
            opts = spec.localization.options if spec.localization.mode == "mcl" else {}
            params = estimator_options("mcl", opts, scenario.source)
        self.params: MonteCarloLocalization.Params = params
        self.n: int = spec.team.n
        p = params
        grid = scenario.world.grid
        self._table, self._outside = mm.likelihood_table(
            grid, p.measurement_noise, p.expected_measurement_weight,
            p.random_measurement_weight, p.sensor_limits[1], p.max_likelihood_distance,
            p.beam_combination, p.likelihood_field)
        self._ox, self._oy = grid.origin
        self._inv_h = grid.resolution
        self._half_cell = 0.5 * grid.cell_size
        self._alphas = np.asarray(p.odometry_noise, dtype=float)
        self._thresholds = np.asarray(p.update_thresholds, dtype=float)
        self._bins = np.asarray(p.kld_bin_size, dtype=float)
        self._beam_idx: NDArray[np.intp] | None = None
        self._rng: np.random.Generator | None = None
        self._parts = np.zeros((0, 3))
        self._clear()

    # ------------------------------------------------------------------ state
    def _clear(self) -> None:
        n = self.n
        self._parts = np.zeros((0, 3))
        self._w = np.zeros(0)
        self._ptr = np.zeros(n + 1, dtype=np.int64)
        self._odom = np.zeros((n, 3))  # simulated odometry pose (dead reckoning)
        self._odom_u = np.zeros((n, 3))  # odometry pose at each robot's last update
        self._est_u = np.zeros((n, 3))  # estimate at each robot's last update
        self._prev_true = np.zeros((n, 3))
        self._updates = np.zeros(n, dtype=np.int64)
        self._updated = np.zeros(n, dtype=bool)
        self._started = False

    def reset(self, rng: np.random.Generator) -> None:
        """Forget everything; ``rng`` becomes the only source of randomness.

        The particle clouds are drawn at the next :meth:`estimate` call, around
        the pose it is given.
        """
        self._rng = rng
        self._clear()

    @property
    def particle_counts(self) -> NDArray[np.int64]:
        """``(N,)`` current number of particles of each robot."""
        return np.diff(self._ptr)

    @property
    def odometry(self) -> FloatArray:
        """``(N, 3)`` simulated odometry poses (dead reckoning from the start pose), m, m, rad."""
        return self._odom.copy()

    @property
    def updated(self) -> NDArray[np.bool_]:
        """``(N,)`` whether each robot's filter ran at the last call (MATLAB ``isUpdated``)."""
        return self._updated.copy()

    @property
    def update_counts(self) -> NDArray[np.int64]:
        """``(N,)`` number of filter updates of each robot since :meth:`reset`."""
        return self._updates.copy()

    def particles(self, robot: int) -> tuple[FloatArray, FloatArray]:
        """Robot ``robot``'s particles ``(M, 3)`` (m, m, rad) and weights ``(M,)`` (sum 1)."""
        a, b = self._ptr[robot], self._ptr[robot + 1]
        return self._parts[a:b].copy(), self._w[a:b].copy()

    # ---------------------------------------------------------------- helpers
    def _draw(self) -> np.random.Generator:
        if self._rng is None:
            raise RuntimeError("call reset(rng) before estimate()")
        return self._rng

    def _beams(self, scan: LaserScan) -> tuple[FloatArray, FloatArray, NDArray[np.int64]]:
        """Robot-frame end points ``(N, B)`` x, y of the usable beams (packed first), counts."""
        ranges = np.asarray(scan.ranges, dtype=float).reshape(self.n, -1)
        if self._beam_idx is None:
            total = ranges.shape[1]
            used = min(self.params.num_beams, total)
            self._beam_idx = np.unique((np.arange(used) * total) // used)
            ang = scan.angles[self._beam_idx]
            self._cos, self._sin = np.cos(ang), np.sin(ang)
        r = ranges[:, self._beam_idx]
        lo, hi = self.params.sensor_limits
        with np.errstate(invalid="ignore"):
            valid = np.isfinite(r) & (r >= lo) & (r <= hi)
        order = np.argsort(~valid, axis=1, kind="stable")
        # end points pushed half a cell further: a return on an occupied cell's face
        # then lands inside that cell, where the centre distance field is 0
        rr = np.take_along_axis(np.where(valid, r, 0.0), order, axis=1) + self._half_cell
        ex = np.ascontiguousarray(rr * self._cos[order])
        ey = np.ascontiguousarray(rr * self._sin[order])
        return ex, ey, valid.sum(axis=1).astype(np.int64)

    def _sensor_and_resample(self, upd: NDArray[np.bool_], scan: LaserScan) -> None:
        """Sensor update, estimate and (every ``resampling_interval``) resampling of ``upd``."""
        p = self.params
        ex, ey, nvalid = self._beams(scan)
        est = self._est_u.copy()
        mm.sensor_update(self._parts, self._w, self._ptr, upd, ex, ey, nvalid, self._table,
                         self._outside, self._ox, self._oy, self._inv_h,
                         p.beam_combination == "amcl", est)
        self._est_u[upd] = est[upd]
        self._updates[upd] += 1
        do = upd & (self._updates % p.resampling_interval == 0)
        if do.any():
            u = np.zeros((self.n, 2))
            u[do] = self._draw().random((int(do.sum()), 2))
            self._parts, self._w, self._ptr = mm.resample(
                self._parts, self._w, self._ptr, do, u, p.particle_limits[0],
                p.particle_limits[1], self._bins, p.kld_error, p.kld_z)

    def _start(self, true: FloatArray, scan: LaserScan) -> None:
        """Initial clouds ``N(true pose, diag(initial_covariance))`` and a first sensor update."""
        rng, n, m = self._draw(), self.n, self.params.particle_limits[1]
        std = np.sqrt(np.asarray(self.params.initial_covariance, dtype=float))
        parts = np.repeat(true, m, axis=0) + rng.standard_normal((n * m, 3)) * std
        parts[:, 2] = mm.wrap(parts[:, 2])
        self._parts = parts
        self._w = np.full(n * m, 1.0 / m)
        self._ptr = np.arange(n + 1, dtype=np.int64) * m
        self._odom = true.copy()
        self._odom_u = true.copy()
        self._prev_true = true.copy()
        self._est_u = np.zeros((n, 3))  # every robot is written by the sensor update
        self._updated = np.ones(n, dtype=bool)
        self._started = True
        self._sensor_and_resample(self._updated, scan)

    # ---------------------------------------------------------------- estimate
    def estimate(self, true_pose: FloatArray, twist: FloatArray, scan: LaserScan | None,
                 dt: float) -> FloatArray:
        """Pose estimates of all robots after this step's odometry and scan.

        Args:
            true_pose: ``(N, 3)`` true poses (m, m, rad); used only to simulate the
                odometry (and, at the first call, to centre the initial clouds).
            twist: ``(N, 2)`` body twist of the last step; unused (the odometry is
                simulated from the true motion, which includes disturbances).
            scan: This step's LiDAR scans, ranges ``(N, B)`` in m.
            dt: Step, s; unused.

        Returns:
            ``(N, 3)`` estimated poses (m, m, rad in ``(-pi, pi]``).

        Raises:
            DfcoaError: ``scan`` is None (the LiDAR is off).
            RuntimeError: :meth:`reset` was not called.
        """
        if scan is None:
            raise DfcoaError("localization 'mcl' needs a LiDAR scan every step")
        rng = self._draw()
        true = np.array(true_pose, dtype=float).reshape(self.n, 3)
        if not self._started:
            self._start(true, scan)
            upd = np.zeros(self.n, dtype=bool)
        else:
            # 1. simulated odometry: the true motion with alpha1..alpha4 noise
            motion = mm.decompose_motion(self._prev_true, true, self.params.rotation_noise)
            self._odom = mm.sample_motion(self._odom, motion, self._alphas,
                                          rng.standard_normal((self.n, 3)))
            self._prev_true = true
            # 2. update test against MATLAB's UpdateThresholds [x y theta]
            delta = np.abs(self._odom - self._odom_u)
            delta[:, 2] = np.abs(mm.wrap(delta[:, 2]))
            upd = (delta > self._thresholds).any(axis=1)
            self._updated = upd
        if upd.any():
            # 3. motion update of the updating robots' particles
            counts = np.diff(self._ptr)
            sel = np.repeat(upd, counts)
            step = mm.decompose_motion(self._odom_u[upd], self._odom[upd],
                                       self.params.rotation_noise)
            rows = np.repeat(np.arange(int(upd.sum())), counts[upd])
            moved = mm.sample_motion(self._parts[sel], tuple(s[rows] for s in step),
                                     self._alphas, rng.standard_normal((rows.size, 3)))
            self._parts[sel] = moved
            # 4-6. sensor update, estimate, resampling
            self._sensor_and_resample(upd, scan)
            self._odom_u[upd] = self._odom[upd]
        return _wrap_rows(mm.compose_relative(self._est_u, self._odom_u, self._odom))


def _wrap_rows(pose: FloatArray) -> FloatArray:
    """A copy of ``pose (N, 3)`` with the heading wrapped to ``(-pi, pi]``."""
    out = np.array(pose, dtype=float)
    out[:, 2] = wrap_angle(out[:, 2])
    return out
