"""Models and kernels of Monte Carlo localization (used by :mod:`dfcoa_opt.sim.localization.mcl`).

* **Odometry motion model** (Thrun, *Probabilistic Robotics* Table 5.6; MATLAB
  ``odometryMotionModel``): a relative motion between two odometry poses is
  split into ``(rot1, trans, rot2)`` and each part is perturbed by a zero-mean
  Gaussian whose *variance* is ``alpha1 rot1^2 + alpha2 trans^2`` (rotations),
  ``alpha3 trans^2 + alpha4 (rot1^2 + rot2^2)`` (translation). As in AMCL,
  the rotations that scale the noise are those of the robot's own turn (see
  :func:`decompose_motion`), so driving backwards or being pushed sideways is
  not mistaken for a half or quarter turn, and a translation below
  :data:`MIN_TRANSLATION` is treated as a rotation in place.
* **Likelihood field** (Thrun §6.4; MATLAB ``likelihoodFieldSensorModel``;
  AMCL): per beam ``p = z_hit exp(-d^2 / (2 sigma^2)) + z_rand / z_max`` where
  ``d`` is the distance from the beam end point to the nearest occupied cell,
  capped at the maximum likelihood distance (also outside the map). The per
  cell values are tabulated once; a particle's log-likelihood is the sum of the
  table values of its beam end points (``"product"``) or AMCL's heuristic
  ``log(1 + sum p^3)`` (``"amcl"``).
* **Low-variance resampling** (Thrun Table 4.4) with the **KLD** sample size of
  Fox (2003): ``n = (k - 1) / (2 eps) [1 - 2/(9(k-1)) + sqrt(2/(9(k-1))) z]^3``
  for ``k`` occupied histogram bins.

Every per-particle / per-beam loop runs in numba (``cache=True``).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from dfcoa_opt.core.geometry import wrap_angle_fast
from dfcoa_opt.world.grid import OccupancyGrid

FloatArray = NDArray[np.float64]

#: Relative motions shorter than this (m) are treated as rotations in place by
#: the noise model (AMCL uses the same 0.01 m), so a rotation of the direction
#: of a tiny displacement does not inflate the heading noise.
MIN_TRANSLATION = 0.01
_KEY_OFFSET = 1 << 19  # bin indices are shifted by this and packed 21 bits each in an int64
_KEY_MAX = (1 << 21) - 1  # (clipped: far-away bins merge, which only lowers k)


def decompose_motion(prev: FloatArray, cur: FloatArray, rotation_noise: str = "heading_change"
                     ) -> tuple[FloatArray, ...]:
    """Split the motions ``prev -> cur`` into the odometry model's three parts.

    Args:
        prev: ``(M, 3)`` start poses (m, m, rad).
        cur: ``(M, 3)`` end poses (m, m, rad).
        rotation_noise: Which rotations scale the noise (below
            :data:`MIN_TRANSLATION` always ``0`` and the whole heading change,
            as AMCL). ``"decomposition"``: ``rot1`` and ``rot2`` folded to
            ``min(|rot|, pi - |rot|)`` (AMCL). ``"heading_change"``: half the
            heading change each. The two agree for every motion a differential
            drive can make (an arc, forwards or backwards, has ``rot1 = rot2``);
            they differ for a sideways displacement (an external push), which
            the first takes for a +-90 deg turn there and back.

    Returns:
        ``(rot1, trans, rot2, rot1_noise, rot2_noise)``, each ``(M,)``: the exact
        decomposition (rad, m, rad; ``rot1 + rot2`` is the heading change) and
        the rotations (rad) that scale the noise.
    """
    dx = cur[:, 0] - prev[:, 0]
    dy = cur[:, 1] - prev[:, 1]
    dth = wrap_angle_fast(cur[:, 2] - prev[:, 2])
    trans = np.hypot(dx, dy)
    rot1 = wrap_angle_fast(np.arctan2(dy, dx) - prev[:, 2])
    rot2 = wrap_angle_fast(dth - rot1)
    moving = trans >= MIN_TRANSLATION
    if rotation_noise == "decomposition":
        n1 = np.minimum(np.abs(rot1), np.pi - np.abs(rot1))
        n2 = np.minimum(np.abs(rot2), np.pi - np.abs(rot2))
    else:
        n1 = n2 = 0.5 * np.abs(dth)
    return rot1, trans, rot2, np.where(moving, n1, 0.0), np.where(moving, n2, np.abs(dth))


def sample_motion(poses: FloatArray, motion: tuple[FloatArray, ...], alphas: ArrayLike,
                  normals: FloatArray) -> FloatArray:
    """Apply noisy odometry motions (Thrun's ``sample_motion_model_odometry``).

    Args:
        poses: ``(M, 3)`` poses to move (m, m, rad).
        motion: ``(rot1, trans, rot2, rot1_noise, rot2_noise)`` from
            :func:`decompose_motion`, each ``(M,)`` (or broadcastable).
        alphas: ``(alpha1, alpha2, alpha3, alpha4)``: rotation from rotation,
            rotation from translation, translation from translation, translation
            from rotation (MATLAB ``Noise`` order); variance coefficients
            (rad^2/rad^2, rad^2/m^2, m^2/m^2, m^2/rad^2).
        normals: ``(M, 3)`` standard normal draws.

    Returns:
        The moved poses ``(M, 3)``, heading wrapped to ``[-pi, pi)``.
    """
    a1, a2, a3, a4 = (float(a) for a in alphas)
    rot1, trans, rot2, n1, n2 = motion
    t2 = trans * trans
    s1 = np.sqrt(a1 * n1 * n1 + a2 * t2)
    st = np.sqrt(a3 * t2 + a4 * (n1 * n1 + n2 * n2))
    s2 = np.sqrt(a1 * n2 * n2 + a2 * t2)
    r1 = rot1 - s1 * normals[:, 0]
    tr = trans - st * normals[:, 1]
    r2 = rot2 - s2 * normals[:, 2]
    head = poses[:, 2] + r1
    out = np.empty_like(poses)
    out[:, 0] = poses[:, 0] + tr * np.cos(head)
    out[:, 1] = poses[:, 1] + tr * np.sin(head)
    out[:, 2] = wrap_angle_fast(head + r2)
    return out


def compose_relative(base: FloatArray, frm: FloatArray, to: FloatArray) -> FloatArray:
    """``base (+) (frm^-1 (+) to)``: move ``base`` by the relative motion ``frm -> to``.

    Args:
        base: ``(M, 3)`` poses to move.
        frm: ``(M, 3)`` start of the relative motion.
        to: ``(M, 3)`` end of the relative motion.
    """
    c, s = np.cos(frm[:, 2]), np.sin(frm[:, 2])
    dx, dy = to[:, 0] - frm[:, 0], to[:, 1] - frm[:, 1]
    lx, ly = c * dx + s * dy, -s * dx + c * dy
    cb, sb = np.cos(base[:, 2]), np.sin(base[:, 2])
    out = np.empty_like(base)
    out[:, 0] = base[:, 0] + cb * lx - sb * ly
    out[:, 1] = base[:, 1] + sb * lx + cb * ly
    out[:, 2] = wrap_angle_fast(base[:, 2] + to[:, 2] - frm[:, 2])
    return out


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


def kld_sample_size(k: int, eps: float, z: float) -> int:
    """Fox's KLD bound for ``k`` occupied bins (0 for ``k <= 1``).

    Args:
        k: Number of occupied histogram bins.
        eps: Bound ``epsilon`` on the Kullback-Leibler error.
        z: Normal quantile ``z_{1-delta}`` (MATLAB/AMCL pass 0.99 here).
    """
    return int(_kld(int(k), float(eps), float(z)))


def low_variance_resample(weights: ArrayLike, n: int, u: float) -> NDArray[np.int64]:
    """Indices drawn by low-variance (systematic) resampling.

    Sample ``m`` is the particle where the cumulative weight first reaches
    ``(u + m) / n`` of the total, so particle ``i`` is drawn ``floor`` or
    ``ceil`` of ``n w_i / sum(w)`` times.

    Args:
        weights: ``(M,)`` non-negative weights, positive sum.
        n: Number of draws.
        u: Offset in ``[0, 1)`` (one uniform draw).
    """
    w = np.ascontiguousarray(weights, dtype=np.float64)
    out = np.empty(int(n), dtype=np.int64)
    _lowvar(w, 0, w.shape[0], float(u), out)
    return out


# ------------------------------------------------------------------ numba kernels
@numba.njit(cache=True)
def _kld(k, eps, z):  # pragma: no cover - numba
    if k <= 1:
        return 0
    b = 2.0 / (9.0 * (k - 1))
    x = 1.0 - b + math.sqrt(b) * z
    return int(math.ceil((k - 1) / (2.0 * eps) * x * x * x))


@numba.njit(cache=True)
def _lowvar(w, a, b, u, out):  # pragma: no cover - numba
    """Fill ``out`` (length n) with low-variance draws from ``w[a:b]`` (absolute indices)."""
    n = out.shape[0]
    total = 0.0
    for j in range(a, b):
        total += w[j]
    step = total / n
    i = a
    c = w[a]
    for m in range(n):
        t = (u + m) * step
        while t > c and i < b - 1:
            i += 1
            c += w[i]
        out[m] = i


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


@numba.njit(cache=True)
def resample(parts, w, ptr, do, u, n_min, n_max, bins, eps, z):  # pragma: no cover - numba
    """KLD-adaptive low-variance resampling of the robots ``do``.

    For each such robot: draw as many particles as it has now, count the
    histogram bins ``bins = (dx, dy, dtheta)`` they occupy (``k``), then draw
    ``clip(kld(k), n_min, n_max)`` particles with equal weights. Other robots
    keep their particles and weights.

    Args:
        parts: ``(P, 3)`` particles.
        w: ``(P,)`` weights, normalised per robot.
        ptr: ``(N + 1,)`` row offsets.
        do: ``(N,)`` robots to resample.
        u: ``(N, 2)`` uniform offsets in ``[0, 1)`` (two draws per robot).
        n_min: Smallest particle count.
        n_max: Largest particle count.
        bins: ``(3,)`` bin sizes (m, m, rad).
        eps: KLD error bound.
        z: KLD normal quantile.

    Returns:
        ``(parts, w, ptr)`` of the new particle set.
    """
    n = ptr.shape[0] - 1
    counts = np.empty(n, dtype=np.int64)
    for r in range(n):
        counts[r] = ptr[r + 1] - ptr[r]
        if not do[r]:
            continue
        a, b = ptr[r], ptr[r + 1]
        idx = np.empty(b - a, dtype=np.int64)
        _lowvar(w, a, b, u[r, 0], idx)
        keys = np.empty(b - a, dtype=np.int64)
        for m in range(b - a):
            j = idx[m]
            kx = min(max(int(math.floor(parts[j, 0] / bins[0])) + _KEY_OFFSET, 0), _KEY_MAX)
            ky = min(max(int(math.floor(parts[j, 1] / bins[1])) + _KEY_OFFSET, 0), _KEY_MAX)
            kt = min(max(int(math.floor((parts[j, 2] + math.pi) / bins[2])), 0), _KEY_MAX)
            keys[m] = (kx << 42) | (ky << 21) | kt
        keys.sort()
        k = 1
        for m in range(1, keys.shape[0]):
            if keys[m] != keys[m - 1]:
                k += 1
        counts[r] = min(max(_kld(k, eps, z), n_min), n_max)
    new_ptr = np.zeros(n + 1, dtype=np.int64)
    for r in range(n):
        new_ptr[r + 1] = new_ptr[r] + counts[r]
    new_parts = np.empty((new_ptr[n], 3))
    new_w = np.empty(new_ptr[n])
    for r in range(n):
        a, b, o = ptr[r], ptr[r + 1], new_ptr[r]
        if do[r]:
            idx = np.empty(counts[r], dtype=np.int64)
            _lowvar(w, a, b, u[r, 1], idx)
            for m in range(counts[r]):
                new_parts[o + m] = parts[idx[m]]
                new_w[o + m] = 1.0 / counts[r]
        else:
            for m in range(b - a):
                new_parts[o + m] = parts[a + m]
                new_w[o + m] = w[a + m]
    return new_parts, new_w, new_ptr
