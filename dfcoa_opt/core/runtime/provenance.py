"""The machine and software a result came from (report and benchmark headers)."""

from __future__ import annotations

import os
import platform
from collections.abc import Sequence
from importlib import metadata
from pathlib import Path

from dfcoa_opt.core.runtime import dispatch

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


def machine() -> str:
    """``<CPU model>, <n> cores, numpy SIMD <level> (cap <cap>)``.

    The level is :func:`dfcoa_opt.core.runtime.dispatch.numpy_simd`, the cap
    :func:`dfcoa_opt.core.runtime.dispatch.describe`.
    """
    return (f"{cpu_model()}, {os.cpu_count() or '?'} cores, numpy SIMD "
            f"{dispatch.numpy_simd()} (cap {dispatch.describe()})")
