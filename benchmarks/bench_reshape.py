"""Benchmark: ``reshape``'s planning time per replanning (issue 20 targets).

Run ``python -m benchmarks.bench_reshape``. One run of ``reshape`` per
scenario (seed 0) after a warm-up run (numba compilation, the first
configuration-space layers); each sample is one replanning (free region,
formation routes, formation choice, assignment, guidance), timed inside the
controller (``Reshape.plan_times``). Targets: median <= 5 ms for N <= 20, <= 50 ms
for N = 100. No peer: the toolkit has no other formation planner.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from benchmarks.timing import row
from dfcoa_opt.control.registry import build_controller
from dfcoa_opt.scenario.loader import load_scenario
from dfcoa_opt.sim.simulator import Simulator

ROOT = Path(__file__).resolve().parents[1]
#: (scenario file, team size) of the rows.
CASES = (("scenarios/bench/corridor.toml", 5), ("scenarios/bench/clutter.toml", 5),
         ("scenarios/bench/large_20.toml", 20), ("scenarios/bench/large_100.toml", 100))


def plan_times_us(path: Path, seed: int = 0) -> np.ndarray:
    """Planning time of every replanning of one ``reshape`` run, us."""
    scenario = load_scenario(path, seed=seed)
    ctrl = build_controller("reshape", scenario.spec.controllers, scenario.source)
    Simulator(scenario, ctrl, seed).run()
    return 1e6 * np.asarray(ctrl.plan_times)


def run() -> list[dict]:
    """Rows: median and range of the planning time per scenario."""
    plan_times_us(ROOT / CASES[0][0])  # warm-up: numba kernels
    rows = []
    for rel, n in CASES:
        t = plan_times_us(ROOT / rel)
        rows.append(row(f"reshape planning per replanning, {Path(rel).stem} (N={n})", t))
    return rows


if __name__ == "__main__":
    for r in run():
        print(f"{r['what']}: median {r['median_us']:.0f} us (min {r['min_us']:.0f}, "
              f"max {r['max_us']:.0f}, n={r['samples']})")
