"""Benchmark row (f): ``make figures`` from a fresh clone (issues 7 and 21).

Run ``python -m benchmarks.bench_figures``. It clones this checkout's HEAD
into a temporary folder (no numba kernel cache, no result cache, no outputs)
and runs ``dfcoa figures`` there once, in a subprocess with this
virtualenv's Python, reporting its wall time (one sample: the run takes
minutes). A second row times what numba compilation costs in such a clone:
one second of every registered controller on three scenarios, first with the
clone's empty kernel cache, then again with the cache the first pass wrote.
Creating the virtualenv is not included (``make`` does it once per machine).
Then a row per recipe: its cost in that clone (simulation CPU-s plus rendering, the
``cost.json`` that ``dfcoa figures`` writes), against the recipe's budget.
``make bench`` includes these rows; set ``BENCH_FIGURES=0`` to leave them out.
There is no peer: row (f) is checked against the 15 min target alone.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.timing import row
from dfcoa_opt.bench.figures import COST_FILE

WHAT = "make figures from a fresh clone (dfcoa figures, 2 workers, venv present), one run"
ROOT = Path(__file__).resolve().parents[1]

#: One second of every controller on S1, crossing and corridor: every kernel compiles.
WARM_UP = """
import time
from dfcoa_opt.control.registry import available, build_controller
from dfcoa_opt.scenario.loader import load_scenario
from dfcoa_opt.sim.simulator import Simulator
t0 = time.perf_counter()
for name in available() + ["goto_slot+cbf", "goto_slot+orca"]:
    for path in ("scenarios/dfcoa_s1.toml", "scenarios/bench/crossing.toml",
                 "scenarios/bench/corridor.toml"):
        sc = load_scenario(path, overrides={"t_max": 1.0})
        Simulator(sc, build_controller(name, sc.spec.controllers, sc.source), 0).run()
print(time.perf_counter() - t0)
"""


def _clone(tmp: str) -> Path:
    """A fresh clone of HEAD in ``tmp`` (committed files only)."""
    dest = Path(tmp) / "clone"
    subprocess.run(["git", "clone", "--quiet", "--no-hardlinks", str(ROOT), str(dest)],
                   check=True)
    return dest


def _python(clone: Path, *args: str) -> subprocess.CompletedProcess:
    """Run this virtualenv's Python in ``clone`` on the clone's sources."""
    env = {**os.environ, "MPLBACKEND": "Agg", "PYTHONPATH": str(clone)}
    return subprocess.run([sys.executable, *args], check=True, cwd=clone, env=env,
                          capture_output=True, text=True)


def run() -> list[dict]:
    """Rows (f) and the numba compilation; an empty list when ``BENCH_FIGURES=0``."""
    if os.environ.get("BENCH_FIGURES", "1") == "0":
        print("BENCH_FIGURES=0: row (f), make figures in a fresh clone, and the numba row "
              "left out")
        return []
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        clone = _clone(tmp)
        cold = float(_python(clone, "-c", WARM_UP).stdout.split()[-1])
        warm = float(_python(clone, "-c", WARM_UP).stdout.split()[-1])
        rows.append(row(f"numba compilation in a fresh clone: every controller's kernels "
                        f"({cold - warm:.0f} s)", np.array([cold * 1e6]),
                        "same warm-up with the kernel cache it wrote", np.array([warm * 1e6])))
    with tempfile.TemporaryDirectory() as tmp:
        clone = _clone(tmp)
        t0 = time.perf_counter()
        _python(clone, "-m", "dfcoa_opt", "figures", "--out", f"{tmp}/out", "--no-progress")
        seconds = time.perf_counter() - t0
        rows.append(row(f"{WHAT} ({seconds:.0f} s)", np.array([seconds * 1e6])))
        rows += recipe_rows(clone / ".dfcoa-cache")
    return rows


def recipe_title(name: str) -> str:
    """The row title of recipe ``name``'s cost (``run.py`` matches its budget by it)."""
    return f"recipe {name}: CPU-s, simulation + render, fresh clone"


def recipe_rows(cache: Path) -> list[dict]:
    """One row per recipe: its cost in the clone (``cost.json`` of ``make_figures``), in us."""
    out = []
    for path in sorted(cache.glob(f"*/{COST_FILE}")):
        cost = json.loads(path.read_text())
        out.append(row(recipe_title(cost["recipe"]), np.array([cost["cost_cpu_s"] * 1e6])))
    return out


if __name__ == "__main__":
    for r in run():
        print(f"{r['what']}: {r['median_us'] / 1e6:.1f} s")
