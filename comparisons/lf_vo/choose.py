"""``lf_vo``'s choice of a sample in a numba kernel, and the turn-rate roots the kernels share.

:func:`vo_choose` picks each robot's sample as ``lf_vo`` does with the numpy
reference (:func:`comparisons.lf_vo.equations.vo_cost`, ``argmin`` over the safe
samples, ``argmax`` of the clearance when none is safe), with the same
floating-point operations per cost, computed for the safe samples only. Each
row is chosen from its own row alone, so the rows of a batch of runs go
through one call.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@numba.njit(cache=True)
def _roots(w, w_stride, root):  # pragma: no cover - numba
    """Fill ``root``: per sample, the first sample ``w_stride`` steps back with the same ``w``."""
    n_s = w.shape[0]
    for s in range(n_s):
        root[s] = s
        if w_stride > 0 and s >= w_stride and w[s - w_stride] == w[s]:
            root[s] = root[s - w_stride]


@numba.njit(cache=True)
def _choose(theta, v, w, v_ref, w_ref, theta_t, clear, tau, pref_weight, heading_weight,
            turn_weight, w_stride, best, fell):  # pragma: no cover - numba
    """Fill ``best`` and ``fell`` ``(N,)`` (see :func:`vo_choose`)."""
    n, n_s = v.shape
    cp, sp, cg = np.empty(n_s), np.empty(n_s), np.empty(n_s)
    done = np.zeros(n_s, np.bool_)
    root = np.empty(n_s, np.int64)
    for i in range(n):
        th = theta[i]
        psi_ref = th + w_ref[i] * tau
        vr = v_ref[i]
        rx = vr * math.cos(psi_ref)
        ry = vr * math.sin(psi_ref)
        _roots(w[i], w_stride, root)
        done[:] = False
        k = -1
        low = np.inf
        for s in range(n_s):
            if not clear[i, s] >= 0.0:
                continue
            r = root[s]
            if not done[r]:  # the heading aimed for, once per distinct w
                psi = th + w[i, r] * tau
                cp[r] = math.cos(psi)
                sp[r] = math.sin(psi)
                cg[r] = math.cos(psi - theta_t[i])
                done[r] = True
            dvx = v[i, s] * cp[r] - rx
            dvy = v[i, s] * sp[r] - ry
            short = vr - v[i, s] * cg[r]
            if not (short >= 0.0 or short != short):  # np.maximum(short, 0.0)
                short = 0.0
            if k >= 0 and pref_weight >= 0.0 and dvx == dvx and dvy == dvy:
                # hypot >= max(|dvx|, |dvy|), and rounding is monotone: a cost >= low loses
                big = max(abs(dvx), abs(dvy))
                if (pref_weight * big + heading_weight * short
                        + turn_weight * abs(w[i, s] - w_ref[i])) >= low:
                    continue
            cost = (pref_weight * math.hypot(dvx, dvy) + heading_weight * short
                    + turn_weight * abs(w[i, s] - w_ref[i]))
            if cost != cost:  # np.argmin: the first NaN
                k = s
                break
            if k < 0 or cost < low:
                k, low = s, cost
        fell[i] = k < 0
        if k < 0:  # np.argmax of the clearance: the first maximum (or NaN)
            k, high = 0, clear[i, 0]
            for s in range(n_s):
                c = clear[i, s]
                if c != c:
                    k = s
                    break
                if c > high:
                    k, high = s, c
        best[i] = k


def vo_choose(theta: ArrayLike, v: ArrayLike, w: ArrayLike, v_ref: ArrayLike, w_ref: ArrayLike,
              theta_t: ArrayLike, clear: ArrayLike, tau: float, pref_weight: float,
              heading_weight: float, turn_weight: float = 0.0,
              w_stride: int = 0) -> tuple[IntArray, NDArray[np.bool_]]:
    """Each robot's sample: the cheapest safe one, else the one with the largest clearance.

    The same choice as ``np.argmin(np.where(clear >= 0, vo_cost(...), inf), axis=1)``
    with :func:`comparisons.lf_vo.equations.vo_cost` (bit for bit the same costs:
    the same operations in the same order), replaced by ``np.argmax(clear,
    axis=1)`` on the rows without a safe sample. Costs are computed for the
    safe samples only, the trigonometry once per distinct turn rate
    (``w_stride`` as in :func:`vo_clearance`).

    Args:
        theta: ``(N,)`` current headings, rad.
        v: ``(N, S)`` sampled speeds, m/s.
        w: ``(N, S)`` sampled turn rates, rad/s.
        v_ref: ``(N,)`` preferred speeds (eq 4), m/s.
        w_ref: ``(N,)`` preferred turn rates (eq 4), rad/s.
        theta_t: ``(N,)`` target directions (eq 10), rad.
        clear: ``(N, S)`` clearances (:func:`vo_clearance`), m; safe when ``>= 0``.
        tau: Time over which the heading turns, s.
        pref_weight: Weight of the velocity distance, s/m.
        heading_weight: Weight of the progress shortfall, s/m.
        turn_weight: Weight of the turn-rate distance to ``w_ref``, s/rad.
        w_stride: Samples ``s`` and ``s - w_stride`` often share ``w``; any value is exact.

    Returns:
        ``(best (N,), fell (N,))``: the chosen sample's index and whether the row
        had no safe sample.
    """
    vv = np.ascontiguousarray(v, dtype=np.float64)
    n = vv.shape[0]
    if vv.ndim != 2 or vv.shape[1] == 0:
        raise ValueError(f"vo_choose needs (N, S) samples with S >= 1, got {vv.shape}")

    def per_robot(a: ArrayLike) -> FloatArray:
        return np.ascontiguousarray(a, dtype=np.float64).reshape(n)

    best = np.empty(n, dtype=np.int64)
    fell = np.empty(n, dtype=np.bool_)
    _choose(per_robot(theta), vv, np.ascontiguousarray(w, dtype=np.float64), per_robot(v_ref),
            per_robot(w_ref), per_robot(theta_t), np.ascontiguousarray(clear, dtype=np.float64),
            float(tau), float(pref_weight), float(heading_weight), float(turn_weight),
            int(w_stride), best, fell)
    return best, fell
