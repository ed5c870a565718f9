"""The machine and software a result came from (report and benchmark headers)."""

from __future__ import annotations

import functools
import os
import platform
from collections.abc import Sequence
from importlib import metadata
from pathlib import Path

#: Packages listed in headers (distribution names).
PACKAGES: tuple[str, ...] = ("dfcoa-opt", "numpy", "scipy", "matplotlib", "osqp", "qpsolvers",
                             "casadi", "numba")


def package_version(dist: str) -> str:
    """Installed version of a distribution, or ``"not installed"``."""
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return "not installed"


def versions(packages: Sequence[str] | None = None) -> str:
    """``python 3.11.7, dfcoa-opt 0.1.0, numpy ...`` (default: :data:`PACKAGES`)."""
    return ", ".join([f"python {platform.python_version()}",
                      *(f"{p} {package_version(p)}" for p in packages or PACKAGES)])


def cpu_model() -> str:
    """CPU model from ``/proc/cpuinfo``, else ``platform.processor()``, else ``"unknown"``."""
    try:
        for line in Path("/proc/cpuinfo").read_text(errors="replace").splitlines():
            if line.startswith("model name") and ":" in line:
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


@functools.cache
def numpy_simd() -> str:
    """The widest SIMD level numpy dispatches its loops to on this machine, e.g. ``X86_V3``.

    numpy picks, at import, the widest of its compiled targets that the CPU
    supports (and ``NPY_DISABLE_CPU_FEATURES`` leaves on). Some float64 loops
    (``sin``, ``cos``, ``arctan2``, ``exp``, ``log``, ``power``) have AVX-512
    versions that round differently in the last bit, so two machines with
    different levels can give runs whose digests differ (docs/benchmarking.md,
    "Across machines"). Returns ``"unknown"`` when numpy does not say. Fixed
    once numpy is imported, so it is computed once per process.
    """
    try:
        from numpy._core import _multiarray_umath as umath
    except ImportError:  # numpy < 2
        return "unknown"
    found = [f for f in getattr(umath, "__cpu_dispatch__", [])
             if getattr(umath, "__cpu_features__", {}).get(f)]
    levels = found or list(getattr(umath, "__cpu_baseline__", []))[-1:]
    return levels[-1] if levels else "unknown"


def machine() -> str:
    """``<CPU model>, <n> cores, numpy SIMD <level> (cap <cap>)``.

    The level is :func:`numpy_simd`, the cap :func:`dfcoa_opt.core.runtime.dispatch.describe`.
    """
    from dfcoa_opt.core.runtime.dispatch import describe

    return (f"{cpu_model()}, {os.cpu_count() or '?'} cores, numpy SIMD {numpy_simd()} "
            f"(cap {describe()})")
