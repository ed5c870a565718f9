"""Sensor model of Monte Carlo localization (:mod:`dfcoa_opt.sim.localization.mcl`).

**Likelihood field** (Thrun §6.4; MATLAB ``likelihoodFieldSensorModel``;
AMCL): per beam ``p = z_hit exp(-d^2 / (2 sigma^2)) + z_rand / z_max`` where
``d`` is the distance from the beam end point to the nearest occupied cell,
capped at the maximum likelihood distance (also outside the map). The per
cell values are tabulated once; a particle's log-likelihood is the sum of the
table values of its beam end points (``"product"``) or AMCL's heuristic
``log(1 + sum p^3)`` (``"amcl"``).

:class:`Maps` holds the likelihood field of every map of a batch of runs: one
when the runs share their world, one per run when each has its own (a seeded
clutter field), and runs the sensor update of every robot on its own run's map.

Every per-particle / per-beam loop runs in numba (``cache=True``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.core.errors import DfcoaError
from dfcoa_opt.sim.localization.mcl.params import MclParams
from dfcoa_opt.world.grid import OccupancyGrid

FloatArray = NDArray[np.float64]


def boundary_cells(grid: OccupancyGrid) -> NDArray[np.bool_]:
    """Occupied cells with a free face-neighbour inside the grid: what a LiDAR can hit.

    A beam enters an occupied cell through a face from a free cell, so these are
    the only cells a return can come from (a map built by SLAM holds only these).
    """
    occ = grid.occupied
    free = np.pad(~occ, 1, constant_values=False)
    near_free = free[:-2, 1:-1] | free[2:, 1:-1] | free[1:-1, :-2] | free[1:-1, 2:]
    return occ & near_free


def likelihood_table(grid: OccupancyGrid, sigma: float, z_hit: float, z_rand: float,
                     z_max: float, max_distance: float, combine: str, field: str = "boundary"
                     ) -> tuple[FloatArray, float]:
    """Per-cell beam score of the likelihood field, and the score outside the map.

    Args:
        grid: The map; ``d`` is its centre-to-centre distance field, to the
            boundary cells only when ``field == "boundary"``.
        sigma: Measurement noise ``sigma_hit``, m.
        z_hit: Weight of the Gaussian (expected measurement) term.
        z_rand: Weight of the uniform (random measurement) term.
        z_max: Largest sensor range (divides ``z_rand``), m.
        max_distance: ``d`` is capped here (and is this outside the map), m.
        combine: ``"product"``: the score is ``log p``; ``"amcl"``: ``p^3``.
        field: ``"boundary"``: distances to :func:`boundary_cells`, so an end
            point deep inside a filled obstacle scores low; ``"occupied"``: to
            any occupied cell (``grid.distance_field``, MATLAB/AMCL on this map).

    Returns:
        ``(table (H, W), outside)``.
    """
    def score(d: FloatArray) -> FloatArray:
        p = z_hit * np.exp(-0.5 * (d / sigma) ** 2) + z_rand / z_max
        p = np.maximum(p, 1e-300)
        return np.log(p) if combine == "product" else p ** 3

    if field == "boundary":
        grid = OccupancyGrid(boundary_cells(grid), grid.resolution, grid.origin)
    d = np.minimum(grid.distance_field, max_distance)
    table = np.ascontiguousarray(score(d))
    return table, float(score(np.array(max_distance)))


# ------------------------------------------------------------------ numba kernels
@numba.njit(cache=True)
def _weigh(parts, w, a, b, ex, ey, r, nb, table, n_rows, n_cols, outside, ox, oy, inv_h, amcl,
           est):  # pragma: no cover - numba
    """Sensor update of one robot: particles ``a:b``, beams ``ex[r, :nb]``; writes ``est[r]``."""
    lw = np.empty(b - a)
    best = -np.inf
    for j in range(a, b):
        x, y = parts[j, 0], parts[j, 1]
        c, s = math.cos(parts[j, 2]), math.sin(parts[j, 2])
        acc = 0.0
        for k in range(nb):
            fx = (x + c * ex[r, k] - s * ey[r, k] - ox) * inv_h
            fy = (y + s * ex[r, k] + c * ey[r, k] - oy) * inv_h
            if fx >= 0.0 and fx < n_cols and fy >= 0.0 and fy < n_rows:
                acc += table[int(fy), int(fx)]
            else:
                acc += outside
        if amcl:
            acc = math.log1p(acc)
        v = (math.log(w[j]) if w[j] > 0.0 else -np.inf) + acc
        lw[j - a] = v
        if v > best:
            best = v
    total = 0.0
    for j in range(a, b):
        e = math.exp(lw[j - a] - best)
        w[j] = e
        total += e
    sx = sy = sc = ss = 0.0
    for j in range(a, b):
        wj = w[j] / total
        w[j] = wj
        sx += wj * parts[j, 0]
        sy += wj * parts[j, 1]
        sc += wj * math.cos(parts[j, 2])
        ss += wj * math.sin(parts[j, 2])
    est[r, 0] = sx
    est[r, 1] = sy
    est[r, 2] = math.atan2(ss, sc)


@numba.njit(cache=True)
def sensor_update(parts, w, ptr, upd, ex, ey, nvalid, table, outside, ox, oy, inv_h, amcl,
                  est):  # pragma: no cover - numba
    """Weight the particles of robots ``upd`` by their scans; write their weighted means.

    Args:
        parts: ``(P, 3)`` particles, robot ``r`` owns rows ``ptr[r]:ptr[r+1]``.
        w: ``(P,)`` weights, normalised per robot; updated in place.
        ptr: ``(N + 1,)`` row offsets.
        upd: ``(N,)`` robots to update.
        ex: ``(N, B)`` beam end points in the robot frame, x (m); valid ones first.
        ey: ``(N, B)`` same, y.
        nvalid: ``(N,)`` number of valid beams per robot.
        table: ``(H, W)`` per-cell beam score (:func:`likelihood_table`).
        outside: Score of an end point outside the map.
        ox: Map origin x, m.
        oy: Map origin y, m.
        inv_h: Cells per metre.
        amcl: ``True``: log-likelihood ``log(1 + sum score)``; else ``sum score``.
        est: ``(N, 3)`` output: weighted mean x, y and circular mean heading.
    """
    n_rows, n_cols = table.shape
    for r in range(ptr.shape[0] - 1):
        if upd[r]:
            _weigh(parts, w, ptr[r], ptr[r + 1], ex, ey, r, nvalid[r], table, n_rows, n_cols,
                   outside, ox, oy, inv_h, amcl, est)


@numba.njit(cache=True)
def sensor_update_worlds(parts, w, ptr, upd, ex, ey, nvalid, world, tables, shapes, outside,
                         ox, oy, inv_h, amcl, est):  # pragma: no cover - numba
    """:func:`sensor_update` with each robot on its own map (a batch of runs whose maps differ).

    Robot ``r`` uses map ``world[r]``; map ``k`` is ``tables[k, :shapes[k, 0], :shapes[k, 1]]``
    (``tables`` ``(K, H, W)``, padded), scores ``outside[k]`` outside itself, has its origin at
    ``(ox[k], oy[k])`` m and ``inv_h[k]`` cells per metre. Each robot's numbers are those of
    :func:`sensor_update` on its own map.
    """
    for r in range(ptr.shape[0] - 1):
        if upd[r]:
            k = world[r]
            _weigh(parts, w, ptr[r], ptr[r + 1], ex, ey, r, nvalid[r], tables[k], shapes[k, 0],
                   shapes[k, 1], outside[k], ox[k], oy[k], inv_h[k], amcl, est)


class Maps:
    """The likelihood fields of a batch's maps, and which map each robot is on.

    Args:
        scenarios: One scenario per run, in run order; runs whose scenarios share
            a grid object share its field.
        n: Robots per run.
        params: The estimator's options (sensor model).
        previous: Maps built before; their fields are reused for the same grids.

    Raises:
        DfcoaError: The maps differ in resolution (the beam end points are pushed
            half a cell, one length for the batch).
    """

    def __init__(self, scenarios: Sequence[Any], n: int, params: MclParams,
                 previous: Maps | None = None) -> None:
        known = {} if previous is None else dict(zip(map(id, previous.grids), previous.fields,
                                                     strict=True))
        index: dict[int, int] = {}
        #: The distinct grids, in order of first use.
        self.grids: list[Any] = []
        for sc in scenarios:
            if id(sc.world.grid) not in index:
                index[id(sc.world.grid)] = len(self.grids)
                self.grids.append(sc.world.grid)
        if len({g.cell_size for g in self.grids}) > 1:
            raise DfcoaError("localization 'mcl': the runs of a batch need one map resolution")
        p = params
        #: ``(table (H, W), outside score)`` of each grid (:func:`likelihood_table`).
        self.fields: list[tuple[FloatArray, float]] = [known.get(id(g)) or likelihood_table(
            g, p.measurement_noise, p.expected_measurement_weight, p.random_measurement_weight,
            p.sensor_limits[1], p.max_likelihood_distance, p.beam_combination,
            p.likelihood_field) for g in self.grids]
        #: ``(E*N,)`` the grid of each robot (robot ``r`` of run ``e`` is ``e*N + r``).
        self.world = np.repeat([index[id(sc.world.grid)] for sc in scenarios], n)
        self._stacked: tuple[Any, ...] = ()
        if len(self.grids) > 1:  # every field in one padded array for the kernel
            shapes = np.array([t.shape for t, _ in self.fields], dtype=np.int64)
            tables = np.zeros((len(self.grids), *shapes.max(axis=0)))
            for k, (t, _) in enumerate(self.fields):
                tables[k, :t.shape[0], :t.shape[1]] = t
            self._stacked = (tables, shapes, np.array([o for _, o in self.fields]),
                             np.array([g.origin[0] for g in self.grids], dtype=float),
                             np.array([g.origin[1] for g in self.grids], dtype=float),
                             np.array([g.resolution for g in self.grids], dtype=float))

    def sensor_update(self, parts: FloatArray, w: FloatArray, ptr: NDArray[np.int64],
                      upd: NDArray[np.bool_], ex: FloatArray, ey: FloatArray,
                      nvalid: NDArray[np.int64], amcl: bool, est: FloatArray) -> None:
        """The kernel :func:`~dfcoa_opt.sim.localization.mcl.sensor.sensor_update` of ``upd``.

        Each robot of ``upd`` is weighed on its own run's map.

        Args:
            parts: ``(P, 3)`` particles (m, m, rad), robot ``r``'s rows ``ptr[r]:ptr[r+1]``.
            w: ``(P,)`` weights, normalised per robot; updated in place.
            ptr: ``(E*N + 1,)`` row offsets.
            upd: ``(E*N,)`` robots to update.
            ex: ``(E*N, B)`` beam end points in the robot frame, x (m); valid ones first.
            ey: ``(E*N, B)`` same, y (m).
            nvalid: ``(E*N,)`` number of valid beams per robot.
            amcl: AMCL's beam combination (else the product).
            est: ``(E*N, 3)`` output: the updated robots' weighted means (m, m, rad).
        """
        if not self._stacked:
            (table, outside), grid = self.fields[0], self.grids[0]
            sensor_update(parts, w, ptr, upd, ex, ey, nvalid, table, outside, grid.origin[0],
                          grid.origin[1], grid.resolution, amcl, est)
        else:
            tables, shapes, outs, oxs, oys, inv_h = self._stacked
            sensor_update_worlds(parts, w, ptr, upd, ex, ey, nvalid, self.world, tables,
                                 shapes, outs, oxs, oys, inv_h, amcl, est)
