"""Resampling of Monte Carlo localization (:mod:`dfcoa_opt.sim.localization.mcl`).

**Low-variance resampling** (Thrun Table 4.4) with the **KLD** sample size of
Fox (2003): ``n = (k - 1) / (2 eps) [1 - 2/(9(k-1)) + sqrt(2/(9(k-1))) z]^3``
for ``k`` occupied histogram bins.

Every per-particle loop runs in numba (``cache=True``).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

_KEY_OFFSET = 1 << 19  # bin indices are shifted by this and packed 21 bits each in an int64
_KEY_MAX = (1 << 21) - 1  # (clipped: far-away bins merge, which only lowers k)


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
