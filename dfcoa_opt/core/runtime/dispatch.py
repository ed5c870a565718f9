"""One numeric dispatch for every result: numpy's SIMD loops capped at ``X86_V3`` on x86-64.

numpy picks, when it is imported, the widest SIMD version of its loops that the
CPU has. Some float64 loops (``sin``, ``cos``, ``arctan2``, ``exp``, ``log``,
``power``) have AVX-512 (``X86_V4``) versions that round differently in the last
bit, and a chaotic run (a robot that deadlocks or not) amplifies that bit into
another outcome. OpenBLAS, under ``np.linalg`` and ``np.dot``, likewise picks
its kernels by CPU. So ``import dfcoa_opt`` caps both, before numpy loads, at
``X86_V3`` (AVX2 and FMA, which every x86-64 CPU since about 2015 has):

- ``NPY_DISABLE_CPU_FEATURES`` gets numpy's dispatch targets above the cap (added
  to any the user set);
- ``OPENBLAS_CORETYPE`` (unless set) gets the OpenBLAS kernels of the cap
  (``Haswell``), when the CPU has them.

Measured on an AVX-512 machine (AMD EPYC, numpy 2.4.6), on the comparison's
168 runs of seeds 0-1: numpy at its native ``AVX512_ICL`` changes 92 run
digests against ``X86_V3``, OpenBLAS's ``SkylakeX`` kernels (what an AVX-512
Intel CPU gets) 11 (every ``reshape`` run), ``X86_V2`` none.

Both variables are read once, when numpy and OpenBLAS load, so the cap holds
in every process that imports ``dfcoa_opt`` before numpy: ``dfcoa`` and
``python -m dfcoa_opt`` (``make figures``), and a script or notebook whose first
import is ``dfcoa_opt``. Processes started from those (sweep workers, a local
Dask cluster) inherit the variables. Where numpy was imported first, the first
run warns once (:func:`check`) with the fix.

``DFCOA_SIMD_CAP`` sets the cap: ``X86_V3`` (default), ``X86_V2`` (numpy's
baseline: SSE4.2, no AVX; the same bits as ``X86_V3`` in the measurement above)
or ``native`` (no cap: numpy's AVX-512 loops where the CPU has them, not the
bits of other machines). Other architectures (arm64, ...) are not capped: their
loops are their own.

numba's kernels need no cap: without fast-math, LLVM contracts no multiply-add
into an FMA (none in the 65 compiled signatures of the comparison), compiling
them for ``haswell`` instead of the host CPU changes none of the 168 digests,
and the libm functions they call (``sin``, ``hypot``, ...) are the C library's,
whose FMA versions every ``X86_V3`` CPU runs.
"""

from __future__ import annotations

import functools
import os
import platform
import sys
import warnings

#: Environment variable that sets the cap.
CAP_VARIABLE = "DFCOA_SIMD_CAP"
#: The values of :data:`CAP_VARIABLE`; ``native`` = no cap.
CAPS = ("X86_V2", "X86_V3", "native")
#: The cap when :data:`CAP_VARIABLE` is unset.
DEFAULT_CAP = "X86_V3"

# numpy >= 2.4 names its x86 dispatch targets by level (X86_V3, X86_V4, ...), older
# numpy by feature (AVX2, AVX512F, ...): the targets above each cap, in either naming.
_ABOVE = {
    "new": {"X86_V3": ("X86_V4", "AVX512_ICL", "AVX512_SPR"),
            "X86_V2": ("X86_V3", "X86_V4", "AVX512_ICL", "AVX512_SPR")},
    "old": {"X86_V3": ("AVX512F", "AVX512CD", "AVX512_KNL", "AVX512_KNM", "AVX512_SKX",
                       "AVX512_CLX", "AVX512_CNL", "AVX512_ICL", "AVX512_SPR")},
}
_ABOVE["old"]["X86_V2"] = ("AVX", "F16C", "FMA3", "AVX2", *_ABOVE["old"]["X86_V3"])
#: OpenBLAS core type of each cap, and the CPU flags (``/proc/cpuinfo``) its kernels need.
BLAS_CORE = {"X86_V3": ("Haswell", frozenset({"avx2", "fma"})),
             "X86_V2": ("Nehalem", frozenset({"sse4_2"}))}

_warned = False


@functools.cache
def requested_cap() -> str:
    """The cap :data:`CAP_VARIABLE` asks for (:data:`DEFAULT_CAP` when unset).

    Read once per process, like numpy's own variables. A value that is not one
    of :data:`CAPS` warns in one line and gives the default (this runs at
    ``import dfcoa_opt``, where an exception would stop every import).
    """
    value = os.environ.get(CAP_VARIABLE, "").strip()
    if not value:
        return DEFAULT_CAP
    for cap in CAPS:
        if value.lower() == cap.lower():
            return cap
    warnings.warn(f"{CAP_VARIABLE}={value!r} is not one of {', '.join(CAPS)}; using "
                  f"{DEFAULT_CAP}", stacklevel=3)
    return DEFAULT_CAP


def is_x86() -> bool:
    """Whether this is an x86-64 machine, the only kind the cap applies to."""
    return platform.machine().lower() in ("x86_64", "amd64")


def _numpy_naming() -> str:
    """``new`` (numpy >= 2.4: targets named by level) or ``old``; read without importing numpy."""
    from importlib import metadata

    try:
        major, minor = (int(p) for p in metadata.version("numpy").split(".")[:2])
    except (metadata.PackageNotFoundError, ValueError):
        return "new"
    return "new" if (major, minor) >= (2, 4) else "old"


def targets_above(cap: str) -> tuple[str, ...]:
    """The dispatch targets numpy has above ``cap`` (none for ``native``), in its naming."""
    return () if cap == "native" else _ABOVE[_numpy_naming()][cap]


def _cpu_flags() -> frozenset[str]:
    """The CPU's feature flags from ``/proc/cpuinfo`` (empty where there is none)."""
    try:
        with open("/proc/cpuinfo", errors="replace") as f:
            for line in f:
                if line.startswith("flags") and ":" in line:
                    return frozenset(line.split(":", 1)[1].split())
    except OSError:
        pass
    return frozenset()


def pin() -> None:
    """Cap numpy's dispatch and OpenBLAS's kernels (module docstring); call before numpy loads.

    Does nothing on other architectures, with ``DFCOA_SIMD_CAP=native``, when
    numpy is already imported (then :func:`check` warns), or when the user
    chose numpy's targets with ``NPY_ENABLE_CPU_FEATURES`` (which numpy does not
    accept together with ``NPY_DISABLE_CPU_FEATURES``).
    """
    cap = requested_cap()
    if cap == "native" or not is_x86() or "numpy" in sys.modules \
            or os.environ.get("NPY_ENABLE_CPU_FEATURES"):
        return
    have = os.environ.get("NPY_DISABLE_CPU_FEATURES", "").replace(",", " ").split()
    os.environ["NPY_DISABLE_CPU_FEATURES"] = " ".join(
        [*have, *(t for t in targets_above(cap) if t not in have)])
    core, needs = BLAS_CORE[cap]
    if "OPENBLAS_CORETYPE" not in os.environ and needs <= _cpu_flags():
        os.environ["OPENBLAS_CORETYPE"] = core


def above_cap(level: str, cap: str) -> bool:
    """Whether numpy's dispatch ``level`` passes ``cap``.

    Args:
        level: As :func:`numpy_simd` gives it.
        cap: One of :data:`CAPS`.
    """
    return cap != "native" and any(level in _ABOVE[naming][cap] for naming in _ABOVE)


def check() -> None:
    """Warn once per process when numpy runs above the cap (it was imported before ``dfcoa_opt``).

    The warning names the fix: import ``dfcoa_opt`` first, or start Python with
    ``NPY_DISABLE_CPU_FEATURES`` set; ``DFCOA_SIMD_CAP=native`` accepts the
    machine's own loops.
    """
    global _warned
    if _warned or not is_x86():
        return
    cap, level = requested_cap(), numpy_simd()
    if above_cap(level, cap):
        _warned = True
        warnings.warn(f"numpy dispatches to {level}, above the {cap} cap that gives the same "
                      f"numbers on every x86-64 machine (numpy was imported before dfcoa_opt): "
                      f"import dfcoa_opt first, or start Python with NPY_DISABLE_CPU_FEATURES="
                      f"'{' '.join(targets_above(cap))}'; {CAP_VARIABLE}=native keeps "
                      f"{level}", stacklevel=3)


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


def describe() -> str:
    """The cap in force, for rows and report headers: ``X86_V3``, ``native`` or ``none (arm64)``."""
    return requested_cap() if is_x86() else f"none ({platform.machine() or 'unknown'})"
