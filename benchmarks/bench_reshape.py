"""Benchmark: ``reshape``'s planning time, and ``reshape_passage``'s time per team step.

Run ``python -m benchmarks.bench_reshape``.

- Planning: one run of ``reshape`` per scenario (seed 0) after a warm-up run
  (numba compilation, the first configuration-space layers); each sample is
  one replanning (free region, formation routes, formation choice,
  assignment, guidance), timed inside the controller (``Reshape.plan_times``).
  Targets: median <= 5 ms for N <= 20, <= 50 ms for N = 100. No peer: the
  toolkit has no other formation planner.
- Per team step: every ``act`` call of ``reshape_passage`` (planning when due,
  tracking, the filter) on training worlds of the held-out families, with
  ``reshape`` on the same worlds as the reference, in the same process.
  Targets: median <= 20 ms for 5 robots, <= 50 ms for 10, on one core; the
  rows give the 99th percentile too.
"""

from __future__ import annotations

import time
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
#: (held-out family, team size) of the per-step rows; training seeds only.
STEP_CASES = (("cellular", 5), ("rooms_10", 10))
STEP_SEEDS = (0, 1, 2)
#: the settings under which the held-out benchmark judges every method
JUDGED = {"stop_on_collision": True, "stop_on_deadlock": True, "controllers.cbf.solver": "exact"}


def plan_times_us(path: Path, seed: int = 0) -> np.ndarray:
    """Planning time of every replanning of one ``reshape`` run, us."""
    scenario = load_scenario(path, seed=seed)
    ctrl = build_controller("reshape", scenario.spec.controllers, scenario.source)
    Simulator(scenario, ctrl, seed).run()
    return 1e6 * np.asarray(ctrl.plan_times)


def step_times_us(controller: str, path: Path, seed: int) -> np.ndarray:
    """Wall time of every ``act`` call (one team step) of one run, us."""
    scenario = load_scenario(path, seed=seed, overrides=JUDGED)
    ctrl = build_controller(controller, scenario.spec.controllers, scenario.source)
    times: list[float] = []
    act = ctrl.act

    def timed(obs):  # noqa: ANN001, ANN202 - the controller's own signature
        t0 = time.perf_counter()
        out = act(obs)
        times.append(time.perf_counter() - t0)
        return out

    ctrl.act = timed
    Simulator(scenario, ctrl, seed).run()
    return 1e6 * np.asarray(times)


def run() -> list[dict]:
    """Rows: the planning time per scenario; the time per team step, with its p99."""
    plan_times_us(ROOT / CASES[0][0])  # warm-up: numba kernels
    rows = []
    for rel, n in CASES:
        t = plan_times_us(ROOT / rel)
        rows.append(row(f"reshape planning per replanning, {Path(rel).stem} (N={n})", t))
    for family, n in STEP_CASES:
        path = ROOT / "scenarios" / "heldout" / f"{family}.toml"
        ours = [step_times_us("reshape_passage", path, s) for s in STEP_SEEDS]
        ref = [step_times_us("reshape", path, s) for s in STEP_SEEDS]
        r = row(f"reshape_passage per team step, {family} training seeds "
                f"{STEP_SEEDS[0]}-{STEP_SEEDS[-1]} (N={n})", ours, "reshape", ref)
        r["p99_us"] = float(np.percentile(np.concatenate(ours), 99))
        rows.append(r)
    return rows


if __name__ == "__main__":
    for r in run():
        extra = f", p99 {r['p99_us']:.0f}" if "p99_us" in r else ""
        print(f"{r['what']}: median {r['median_us']:.0f} us (min {r['min_us']:.0f}, "
              f"max {r['max_us']:.0f}{extra}, n={r['samples']})")
