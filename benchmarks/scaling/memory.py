"""Peak memory of the scaling study (:mod:`benchmarks.scaling`), one subprocess per run.

A fresh subprocess per controller (``python -m benchmarks.scaling.memory <id> --n N
--steps S [--traced]``: this module's own command line, which prints the JSON of
:func:`memory_child`; :func:`peak_memory` starts it) loads the kernels with a 4-robot run,
resets its peak-RSS counter (``/proc/self/clear_refs``), then builds and runs N = 1000
(and, as the reference, N = 4 in another subprocess) for a few steps and reports the
peak RSS growth (``VmHWM`` - ``VmRSS`` before) and the whole process's peak; the
N = 1000 child then repeats the build and run under ``tracemalloc`` (Python and numpy
allocations only; memory allocated inside numba kernels is not traced).
"""

from __future__ import annotations

import argparse
import gc
import json
import math
import subprocess
import sys
import time
import tracemalloc
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from benchmarks.scaling.scenario import model_of, open_scenario
from dfcoa_opt.control.registry import make_controller
from dfcoa_opt.sim.simulator import Simulator

#: Working directory of the child processes (the repository root, so ``-m benchmarks`` works).
REPO = Path(__file__).resolve().parents[2]
#: The module the child processes run (this one, :func:`main`): it imports nothing that
#: imports it back.
CHILD_MODULE = "benchmarks.scaling.memory"


def _status_kib(key: str) -> int:
    """A ``/proc/self/status`` field in KiB (``VmRSS``, ``VmHWM``)."""
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith(key + ":"):
                return int(line.split()[1])
    raise KeyError(key)


def _reset_peak() -> bool:
    """Reset this process's peak RSS (``VmHWM``) to its current RSS; False if not allowed."""
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
        return True
    except OSError:
        return False


def memory_child(controller_id: str, n: int, steps: int, traced: bool) -> dict[str, float]:
    """Run in a fresh process: peak memory of building and of running ``n`` robots.

    A 4-robot run first loads the numba kernels. The peak-RSS counter is then reset
    (``/proc/self/clear_refs``) before the scenario build and again before the run,
    so each phase has its own peak. ``ru_maxrss`` is not used: Linux keeps it across
    ``execve``, so a child would report its parent's peak.

    Args:
        controller_id: Registry id.
        n: Team size.
        steps: Steps after the first one.
        traced: Also repeat the build and run under ``tracemalloc``.

    Returns:
        MiB: ``process_peak_mb`` (whole-process peak RSS: interpreter, libraries,
        JIT, scenario, run), ``build_growth_mb`` and ``run_growth_mb`` (peak RSS of
        the phase minus the RSS before it; nan when the counter cannot be reset)
        and, when traced, ``traced_build_mb`` and ``traced_run_mb`` (tracemalloc
        peaks of the phases); ``seconds``: the run's wall time, s.
    """
    robots = model_of(controller_id)
    Simulator(open_scenario(4, robots, 2), make_controller(controller_id)).run()
    gc.collect()
    top = _status_kib("VmHWM")
    growth = []
    scenario = None
    seconds = math.nan
    for phase in ("build", "run"):
        reset = _reset_peak()
        base = _status_kib("VmRSS")
        if phase == "build":
            scenario = open_scenario(n, robots, steps)
        else:
            t0 = time.perf_counter()
            Simulator(scenario, make_controller(controller_id)).run()
            seconds = time.perf_counter() - t0
        peak = _status_kib("VmHWM")
        top = max(top, peak)
        growth.append((peak - base) / 1024.0 if reset else math.nan)
    out = {"process_peak_mb": top / 1024.0, "build_growth_mb": growth[0],
           "run_growth_mb": growth[1], "seconds": seconds}
    if traced:
        del scenario
        gc.collect()
        tracemalloc.start()
        scenario = open_scenario(n, robots, steps)
        out["traced_build_mb"] = tracemalloc.get_traced_memory()[1] / 2**20
        tracemalloc.reset_peak()
        Simulator(scenario, make_controller(controller_id)).run()
        out["traced_run_mb"] = tracemalloc.get_traced_memory()[1] / 2**20
        tracemalloc.stop()
    return out


def peak_memory(controllers: Sequence[str], n: int, ref_n: int, steps: int,
                log: Callable[[str], None] = print) -> dict[str, dict[str, float]]:
    """Peak memory per controller from fresh subprocesses (N = ``n`` and the reference ``ref_n``).

    Returns:
        Per controller: the fields of :func:`memory_child` for N = ``n`` and, prefixed
        ``ref_``, for N = ``ref_n`` (MiB), or ``error`` / ``ref_error``.
    """
    out: dict[str, dict[str, float]] = {}
    for cid in controllers:
        res: dict[str, Any] = {}
        for size, traced, prefix in ((n, True, ""), (ref_n, False, "ref_")):
            cmd = [sys.executable, "-m", CHILD_MODULE, cid, "--n", str(size),
                   "--steps", str(steps)]
            if traced:
                cmd.append("--traced")
            try:
                proc = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True,
                                      timeout=600, check=True)
                got = json.loads(proc.stdout.strip().splitlines()[-1])
                res.update({prefix + k: v for k, v in got.items()})
            except (subprocess.SubprocessError, ValueError, IndexError) as exc:
                res[prefix + "error"] = f"{type(exc).__name__}: {str(exc)[:200]}"
        out[cid] = res
        log(f"memory {cid:22s} N={n}: RSS growth build {res.get('build_growth_mb', math.nan):5.1f}"
            f" run {res.get('run_growth_mb', math.nan):5.1f} MiB (N={ref_n}: "
            f"{res.get('ref_build_growth_mb', math.nan):4.1f} / "
            f"{res.get('ref_run_growth_mb', math.nan):4.1f}), process peak "
            f"{res.get('process_peak_mb', math.nan):5.0f} MiB")
    return out


def main(argv: Sequence[str] | None = None) -> int:
    """The child process: print the JSON of :func:`memory_child` on one line.

    Returns:
        Process exit code (0).
    """
    ap = argparse.ArgumentParser(prog=f"python -m {CHILD_MODULE}",
                                 description="One peak-memory run of the scaling study "
                                             "(started by peak_memory, one per process).")
    ap.add_argument("controller", help="controller id")
    ap.add_argument("--n", type=int, required=True, help="team size")
    ap.add_argument("--steps", type=int, default=10, help="steps after the first one")
    ap.add_argument("--traced", action="store_true",
                    help="also repeat the build and run under tracemalloc")
    args = ap.parse_args(argv)
    print(json.dumps(memory_child(args.controller, args.n, args.steps, args.traced)))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
