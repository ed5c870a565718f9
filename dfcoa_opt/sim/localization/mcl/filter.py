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
4. **Sensor update**: likelihood field (:mod:`dfcoa_opt.sim.localization.mcl.sensor`).
5. **Estimate**: the weighted mean position and circular mean heading of the
   robot's particles after the sensor update.
6. **Resampling** every ``resampling_interval`` updates: low-variance, to the
   KLD-adaptive size within ``particle_limits``.

Between updates the estimate follows the odometry (last estimate composed with
the odometry change since that update), so it moves smoothly every step.
The first call initialises the clouds (``particle_limits[1]`` particles from
``N(true pose, diag(initial_covariance))``) and runs a sensor update, as AMCL
does on its first scan.

One object also steps a batch of runs (``for_batch``, ``reset_batch``,
``estimate_batch``): robot ``r`` of run ``e`` is robot ``e*N + r`` of the same arrays
and kernels, and each run draws from its own generator in the order and sizes of the
run alone, so its numbers are the single run's, bit for bit. See docs/methods/mcl.md.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.core.errors import DfcoaError, ScenarioError
from dfcoa_opt.core.geometry import wrap_angle, wrap_angle_fast
from dfcoa_opt.sim.localization import estimator_options, register_estimator
from dfcoa_opt.sim.localization.mcl.motion import compose_relative, decompose_motion, sample_motion
from dfcoa_opt.sim.localization.mcl.params import MclParams
from dfcoa_opt.sim.localization.mcl.resampling import resample
from dfcoa_opt.sim.localization.mcl.sensor import Maps
from dfcoa_opt.world.lidar import LaserScan

FloatArray = NDArray[np.float64]


@register_estimator("mcl")
class MonteCarloLocalization:
    """Monte Carlo localization, one particle filter per robot, of one run or a batch.

    Args:
        scenario: The loaded scenario (map, team size, LiDAR settings and
            ``[localization.options]``).
        params: Options; default: the scenario's ``[localization.options]``
            validated against :class:`Params` (when its mode is ``mcl``).

    Raises:
        ScenarioError: The scenario's LiDAR is disabled.
    """

    Params = MclParams  # the options (dfcoa_opt.sim.localization.mcl.params.MclParams)
    batched = True  # one object may hold every run of a batch (make_estimators)

    def __init__(self, scenario: Any, params: MclParams | None = None) -> None:
        spec = scenario.spec
        if not spec.sensors.lidar.enabled:
            raise ScenarioError(scenario.source, "sensors.lidar.enabled",
                                "localization 'mcl' needs the LiDAR: set it to true or use "
                                "localization = \"truth\"")
        if params is None:
            opts = spec.localization.options if spec.localization.mode == "mcl" else {}
            params = estimator_options("mcl", opts, scenario.source)
        self.params: MclParams = params
        self.n: int = spec.team.n
        self._alphas = np.asarray(params.odometry_noise, dtype=float)
        self._thresholds = np.asarray(params.update_thresholds, dtype=float)
        self._bins = np.asarray(params.kld_bin_size, dtype=float)
        self._beam_idx: NDArray[np.intp] | None = None
        self._rngs: list[np.random.Generator] | None = None
        self._one_run = np.zeros(self.n, dtype=np.int64)  # env of a batch of one
        self._set_worlds([scenario])

    @classmethod
    def for_batch(cls, scenarios: Sequence[Any], params: MclParams | None = None
                  ) -> MonteCarloLocalization:
        """One estimator for a batch of runs; reset it with :meth:`reset_batch`.

        Args:
            scenarios: One scenario per run, in run order (one file and overrides:
                the options are the first one's). Runs that share a grid share its
                likelihood field; a run with its own map (a seeded clutter field)
                gets its own.
            params: Options; default: as :class:`MonteCarloLocalization`.
        """
        est = cls(scenarios[0], params)
        if len(scenarios) > 1:
            est._set_worlds(list(scenarios))
        return est

    def _set_worlds(self, scenarios: list[Any]) -> None:
        """Each run's map and likelihood field (:class:`Maps`); clears the state."""
        self._maps = Maps(scenarios, self.n, self.params, getattr(self, "_maps", None))
        self._table, self._outside = self._maps.fields[0]
        grid = self._maps.grids[0]
        self._ox, self._oy = grid.origin
        self._inv_h = grid.resolution
        self._half_cell = 0.5 * grid.cell_size
        self.n_runs = len(scenarios)
        self._clear()

    # ------------------------------------------------------------------ state
    def _clear(self) -> None:
        n = self.n_runs * self.n  # robot r of run e is robot e*N + r here
        self._parts = np.zeros((0, 3))
        self._w = np.zeros(0)
        self._ptr = np.zeros(n + 1, dtype=np.int64)
        self._odom = np.zeros((n, 3))  # simulated odometry pose (dead reckoning)
        self._odom_u = np.zeros((n, 3))  # odometry pose at each robot's last update
        self._est_u = np.zeros((n, 3))  # estimate at each robot's last update
        self._prev_true = np.zeros((n, 3))
        self._updates = np.zeros(n, dtype=np.int64)
        self._updated = np.zeros(n, dtype=bool)
        self._started = np.zeros(self.n_runs, dtype=bool)

    def reset(self, rng: np.random.Generator) -> None:
        """Forget everything; ``rng`` becomes the only source of randomness (a batch of one).

        The particle clouds are drawn at the next :meth:`estimate` call, around
        the pose it is given.
        """
        self.reset_batch([rng])

    def reset_batch(self, rngs: Sequence[np.random.Generator]) -> None:
        """Forget everything; run ``e`` draws only from ``rngs[e]``.

        Raises:
            ValueError: Not one generator per run.
        """
        if len(rngs) != self.n_runs:
            raise ValueError(f"{len(rngs)} generators for a batch of {self.n_runs} runs")
        self._rngs = list(rngs)
        self._clear()

    @property
    def particle_counts(self) -> NDArray[np.int64]:
        """``(N,)`` current number of particles of each robot (``(E*N,)`` in a batch)."""
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
        """Robot ``robot``'s (run ``e``'s ``r``: ``e*N + r``) particles ``(M, 3)`` and weights.

        The particles are in m, m, rad; the ``(M,)`` weights sum to 1.
        """
        a, b = self._ptr[robot], self._ptr[robot + 1]
        return self._parts[a:b].copy(), self._w[a:b].copy()

    # ---------------------------------------------------------------- helpers
    def _beams(self, scan: LaserScan, rows: int | None = None
               ) -> tuple[FloatArray, FloatArray, NDArray[np.int64]]:
        """End points ``(rows, B)`` x, y (m, robot frame; usable beams first), beam counts.

        ``scan`` holds ``rows`` scans (default ``N``), ranges in m.
        """
        ranges = np.asarray(scan.ranges, dtype=float).reshape(rows or self.n, -1)
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

    def _start(self, true: FloatArray, robots: NDArray[np.integer], normals: FloatArray) -> None:
        """Initial clouds ``N(true pose, diag(initial_covariance))`` of ``robots`` (not started).

        Args:
            true: ``(K, 3)`` their true poses (m, m, rad).
            robots: ``(K,)`` their indices, ascending.
            normals: ``(K*M, 3)`` standard normal draws, ``M = particle_limits[1]``.
        """
        m = self.params.particle_limits[1]
        std = np.sqrt(np.asarray(self.params.initial_covariance, dtype=float))
        parts = np.repeat(true, m, axis=0) + normals * std
        parts[:, 2] = wrap_angle_fast(parts[:, 2])
        counts = np.diff(self._ptr)
        counts[robots] = m
        ptr = np.zeros_like(self._ptr)
        np.cumsum(counts, out=ptr[1:])
        mine = np.repeat(np.isin(np.arange(counts.size), robots), counts)  # others keep theirs
        all_parts, w = np.empty((ptr[-1], 3)), np.empty(ptr[-1])
        all_parts[mine], w[mine] = parts, 1.0 / m
        all_parts[~mine], w[~mine] = self._parts, self._w
        self._parts, self._w, self._ptr = all_parts, w, ptr
        self._odom[robots] = self._odom_u[robots] = self._prev_true[robots] = true
        self._est_u[robots] = 0.0  # every such robot is written by the sensor update
        self._started[robots[::self.n] // self.n] = True

    def _odometry(self, true: FloatArray, robots: slice | NDArray[np.integer],
                  normals: FloatArray) -> NDArray[np.bool_]:
        """Steps 1-2 for ``robots``: their simulated odometry; which of them update.

        Args:
            true: ``(K, 3)`` their true poses (m, m, rad).
            robots: ``(K,)`` their indices (or a slice).
            normals: ``(K, 3)`` standard normal draws.

        Returns:
            ``(K,)`` whether each moved past an update threshold since its last update.
        """
        motion = decompose_motion(self._prev_true[robots], true, self.params.rotation_noise)
        odom = sample_motion(self._odom[robots], motion, self._alphas, normals)
        self._odom[robots] = odom
        self._prev_true[robots] = true
        delta = np.abs(odom - self._odom_u[robots])
        delta[:, 2] = np.abs(wrap_angle_fast(delta[:, 2]))
        return np.asarray((delta > self._thresholds).any(axis=1))

    def _filter(self, sense: NDArray[np.bool_], move: NDArray[np.bool_],
                runs: NDArray[np.integer], rows: slice | NDArray[np.integer], n_rows: int,
                scan: LaserScan) -> None:
        """Steps 3-6: motion update of ``move``, sensor update and resampling of ``sense``.

        Args:
            sense: ``(E*N,)`` robots whose filter runs.
            move: ``(E*N,)`` those of them whose particles move first (not starting).
            runs: ``(A,)`` this call's runs, ascending.
            rows: This call's robots (``(A*N,)``, or every robot), row after row of the scan.
            n_rows: ``A*N``.
            scan: The scans of ``rows`` (ranges in m).
        """
        p, n, rngs = self.params, self.n, self._generators()
        counts = np.diff(self._ptr)
        self._updates[sense] += 1
        do = sense & (self._updates % p.resampling_interval == 0)
        # each run's own draws, in its own order: motion noise, then resampling offsets
        n_move = np.where(move, counts, 0).reshape(-1, n).sum(axis=1).tolist()
        n_do = do.reshape(-1, n).sum(axis=1).tolist()
        normals, offsets = [], []
        for e in runs.tolist():
            if n_move[e]:
                normals.append(rngs[e].standard_normal((n_move[e], 3)))
            if n_do[e]:
                offsets.append(rngs[e].random((n_do[e], 2)))
        if normals:
            sel = np.repeat(move, counts)
            step = decompose_motion(self._odom_u[move], self._odom[move], p.rotation_noise)
            which = np.repeat(np.arange(int(move.sum())), counts[move])
            self._parts[sel] = sample_motion(self._parts[sel], tuple(s[which] for s in step),
                                             self._alphas, _joined(normals))
        ex, ey, nvalid = self._beams(scan, n_rows)
        if n_rows != sense.size:  # some runs have ended: their rows are absent
            ex, ey, nvalid = (_scatter(a, rows, sense.size) for a in (ex, ey, nvalid))
        est = self._est_u.copy()
        self._maps.sensor_update(self._parts, self._w, self._ptr, sense, ex, ey, nvalid,
                                 p.beam_combination == "amcl", est)
        self._est_u[sense] = est[sense]
        if offsets:
            u = np.zeros((sense.size, 2))
            u[do] = _joined(offsets)  # the runs' robots in order, as drawn
            self._parts, self._w, self._ptr = resample(
                self._parts, self._w, self._ptr, do, u, p.particle_limits[0],
                p.particle_limits[1], self._bins, p.kld_error, p.kld_z)
        self._odom_u[sense] = self._odom[sense]

    def _generators(self) -> list[np.random.Generator]:
        if self._rngs is None:
            raise RuntimeError("call reset(rng) before estimate()")
        return self._rngs

    # ---------------------------------------------------------------- estimate
    def estimate(self, true_pose: FloatArray, twist: FloatArray, scan: LaserScan | None,
                 dt: float) -> FloatArray:
        """Pose estimates of all robots after this step's odometry and scan (a batch of one).

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
        return self.estimate_batch(true_pose, twist, scan, dt, self._one_run)

    def estimate_batch(self, true_pose: FloatArray, twist: FloatArray, scan: LaserScan | None,
                       dt: float, env: NDArray[np.integer]) -> FloatArray:
        """:meth:`estimate` of every active run of the batch at once, each as if alone.

        Args:
            true_pose: ``(A*N, 3)`` true poses (m, m, rad), run after run.
            twist: ``(A*N, 2)`` body twists; unused.
            scan: The scans of those rows, ranges ``(A*N, B)`` in m.
            dt: Step, s; unused.
            env: ``(A*N,)`` the run of each row; runs ascending, N rows each.

        Returns:
            ``(A*N, 3)`` estimated poses (m, m, rad in ``(-pi, pi]``).

        Raises:
            DfcoaError: ``scan`` is None (the LiDAR is off).
            RuntimeError: :meth:`reset_batch` was not called.
            ValueError: The rows are not whole runs in ascending run order.
        """
        if scan is None:
            raise DfcoaError("localization 'mcl' needs a LiDAR scan every step")
        rngs, n = self._generators(), self.n
        true = np.array(true_pose, dtype=float).reshape(-1, 3)
        env = np.asarray(env, dtype=np.int64)
        runs = env[::n]
        if env.size != runs.size * n or (runs.size > 1 and np.any(np.diff(runs) <= 0)):
            raise ValueError("estimate_batch: rows must be whole runs in ascending run order")
        # this call's robots: every robot (a slice) unless some runs have ended
        rows: slice | NDArray[np.integer] = slice(None) if runs.size == self.n_runs else \
            env * n + np.tile(np.arange(n), runs.size)
        fresh = ~self._started[runs]
        init, odo = [], []  # each run's first draws: its initial cloud, or its odometry noise
        for e, new in zip(runs.tolist(), fresh.tolist(), strict=True):
            if new:
                init.append(rngs[e].standard_normal((n * self.params.particle_limits[1], 3)))
            else:
                odo.append(rngs[e].standard_normal((n, 3)))
        move = np.zeros(self._updated.size, dtype=bool)
        if not init:  # every run steps (the usual call): the moved robots are those that sense
            move[rows] = self._odometry(true, rows, _joined(odo))
            sense = move
        else:
            first = np.repeat(fresh, n)
            robots = np.arange(move.size)[rows]
            self._start(true[first], robots[first], _joined(init))
            if odo:
                going = robots[~first]
                move[going[self._odometry(true[~first], going, _joined(odo))]] = True
            sense = move.copy()
            sense[robots[first]] = True
        self._updated[rows] = sense[rows]
        if sense.any():
            self._filter(sense, move, runs, rows, len(true), scan)
        return _wrap_rows(compose_relative(self._est_u[rows], self._odom_u[rows],
                                           self._odom[rows]))


def _joined(draws: list[FloatArray]) -> FloatArray:
    """The runs' draws one after the other (the array itself when there is one)."""
    return draws[0] if len(draws) == 1 else np.concatenate(draws)


def _scatter(a: NDArray[Any], rows: slice | NDArray[np.integer], size: int) -> NDArray[Any]:
    """``a`` (one entry per row) placed at ``rows`` of a zeroed array of ``size`` entries."""
    out = np.zeros((size, *a.shape[1:]), dtype=a.dtype)
    out[rows] = a
    return out


def _wrap_rows(pose: FloatArray) -> FloatArray:
    """A copy of ``pose (N, 3)`` with the heading wrapped to ``(-pi, pi]``."""
    out = np.array(pose, dtype=float)
    out[:, 2] = wrap_angle(out[:, 2])
    return out
