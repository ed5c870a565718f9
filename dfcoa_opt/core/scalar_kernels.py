"""Scalar numba helpers shared by the kernels (one implementation each).

Each is bit-identical to the numpy function it stands for (``tests/test_vfh_kernel.py``,
``tests/test_robots.py``), so a kernel that uses them gives the numbers of the
vectorised reference path. On this machine numba's ``sin``, ``cos``, ``hypot``
and ``fmod`` equal numpy's bit for bit, but ``arctan2`` and ``arcsin`` do not
(numpy uses its own SIMD versions): kernels leave those to numpy.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def wrap1(a: float) -> float:  # pragma: no cover - numba
    """Scalar :func:`~dfcoa_opt.core.geometry.wrap_angle` to (-pi, pi], rad, bit-identical.

    ``mod(a + pi, 2 pi) - pi`` with NumPy's float ``mod`` (``fmod``, plus ``2 pi``
    when negative, ``+0`` for zero) and ``-pi`` mapped to ``pi``. ``fmod(x, 2 pi)``
    is exact and equals ``x`` for ``|x| < 2 pi``, so that common case skips it.
    """
    two_pi = 2.0 * np.pi
    m = a + np.pi
    if not -two_pi < m < two_pi:
        m = np.fmod(m, two_pi)
    if m < 0.0:
        m += two_pi
    elif m == 0.0:
        m = 0.0
    w = m - np.pi
    return np.pi if w == -np.pi else w


@numba.njit(cache=True)
def clip1(x: float, lo: float, hi: float) -> float:  # pragma: no cover - numba
    """Scalar ``np.clip`` (``x`` kept unless strictly outside, so NaN and -0.0 pass)."""
    if x < lo:
        return lo
    if x > hi:
        return hi
    return x
