"""Benchmark row (f): ``make figures`` from an empty result cache (issue 7).

Run ``python -m benchmarks.bench_figures``. It runs ``dfcoa figures`` once, in
a subprocess, into a fresh temporary output folder and result cache, and
reports its wall time (one sample: the run takes minutes). The numba kernel
cache is whatever this checkout has: warm after any earlier run, cold on a
fresh clone, where compiling the kernels adds about 30 s of CPU per worker.
``make bench`` includes the row; set ``BENCH_FIGURES=0`` to leave it out.
There is no peer: the row is checked against the 5 min target alone.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.timing import row

WHAT = "make figures from an empty result cache (dfcoa figures, 2 workers), one run"


def run() -> list[dict]:
    """Time one ``dfcoa figures``; an empty list when ``BENCH_FIGURES=0``."""
    if os.environ.get("BENCH_FIGURES", "1") == "0":
        print("BENCH_FIGURES=0: row (f), make figures, left out")
        return []
    root = Path(__file__).resolve().parents[1]
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [sys.executable, "-m", "dfcoa_opt", "figures", "--out", f"{tmp}/out",
               "--cache", f"{tmp}/cache", "--scenarios", str(root / "scenarios"),
               "--no-progress"]
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, cwd=root, env={**os.environ, "MPLBACKEND": "Agg"})
        seconds = time.perf_counter() - t0
    return [row(f"{WHAT} ({seconds:.0f} s)", np.array([seconds * 1e6]))]


if __name__ == "__main__":
    for r in run():
        print(f"{r['what']}: {r['median_us'] / 1e6:.1f} s")
