"""Benchmark of the ``nmpc`` controller: solver choice, warm start, run time per scenario.

Run ``python -m benchmarks.bench_nmpc`` (about 5 min on the 2-core machine;
``--parts solvers`` alone takes about 2 min). Everything is measured in this one process, so
ratios compare like with like:

1. **solvers** -- the whole of S1 (``scenarios/dfcoa_s1.toml``) and the first
   ``S2_SECONDS`` s of S2 with each solver option (the default: condensed SQP compiled
   to C + IPOPT rescue; the same interpreted; multiple shooting, the default before,
   interpreted and compiled; SQP alone; IPOPT), ``ROUNDS`` interleaved rounds. Per
   option: median and p95 solve time per robot per step
   (``dfcoa_opt.metrics.solver.solve_time_stats``), mean iterations of the first solver
   (rescued solves left out; the compiled solver does not count them), failures,
   rescues and the run's wall time; the ratios are the
   medians of the old default and of IPOPT over the option's median.
2. **warm** -- the first ``WARM_STEPS`` steps of S1: the iterations of the
   controller's warm-started solves against a cold start of the very same problems
   (controls 0 at the current pose, no multipliers), per solver (interpreted, which
   counts iterations).
3. **scenarios** -- the wall time of one whole run of every scenario ``make figures``
   may run nmpc on (S1, S2, ``scenarios/bench/*.toml``, the two example scenarios),
   with the default parameters, with the old default (multiple shooting, interpreted)
   and with ``solver = "ipopt"``; ``large_100`` is measured on its first
   ``LARGE_100_SECONDS`` s and scaled to its ``t_max`` (an estimate, stated as such).
   The problems are built (and compiled, once per machine) before the timed runs.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from comparisons.nmpc import Nmpc
from dfcoa_opt.control.registry import build_controller
from dfcoa_opt.metrics.solver import solve_time_stats
from dfcoa_opt.scenario.loader import load_scenario
from dfcoa_opt.sim.simulator import Simulator

ROOT = Path(__file__).resolve().parents[1]
S1, S2 = ROOT / "scenarios/dfcoa_s1.toml", ROOT / "scenarios/dfcoa_s2.toml"
S2_SECONDS = 40.0
ROUNDS = 2
WARM_STEPS = 60
LARGE_100_SECONDS = 10.0
#: Solver options compared in part 1 (label, ``[controllers.nmpc]`` keys).
OLD = {"formulation": "multiple-shooting", "compiled": False}
OPTIONS = (("condensed, compiled + ipopt rescue (default)", {}),
           ("condensed, interpreted", {"compiled": False}),
           ("multiple shooting, compiled", {"formulation": "multiple-shooting"}),
           ("multiple shooting, interpreted (old default)", OLD),
           ("condensed, compiled, sqp alone", {"rescue": False}),
           ("ipopt (multiple shooting)", {"solver": "ipopt", "formulation": "multiple-shooting"}),
           ("ipopt (condensed)", {"solver": "ipopt"}))


class _Counting:
    """Wraps the controller: collects iterations and rescues of every step."""

    def __init__(self, inner: Nmpc) -> None:
        self.inner, self.iterations, self.rescues = inner, [], 0
        self.name, self.command, self.uses_scan = inner.name, inner.command, False

    @property
    def last_result(self):
        return self.inner.last_result

    def reset(self, scenario, rng):
        self.inner.reset(scenario, rng)

    def act(self, obs):
        out = self.inner.act(obs)  # iterations of the first solver (rescued solves left out)
        self.iterations.extend(self.inner.last_iterations[~self.inner.last_rescued].tolist())
        self.rescues += int(self.inner.last_rescued.sum())
        return out


def one_run(path: Path, params: dict, t_max: float | None = None) -> dict:
    """One nmpc run with ``params``; solve-time statistics, iterations and wall time."""
    overrides = {f"controllers.nmpc.{k}": v for k, v in params.items()}
    if t_max is not None:
        overrides["t_max"] = t_max
    sc = load_scenario(path, overrides=overrides)
    ctrl = _Counting(build_controller("nmpc", sc.spec.controllers, sc.source))
    t0 = time.perf_counter()
    log = Simulator(sc, ctrl).run()
    wall = time.perf_counter() - t0
    known = [i for i in ctrl.iterations if i >= 0]  # the compiled solver does not count
    return {**solve_time_stats(log), "wall": wall, "steps": log.meta["steps"], "n": sc.spec.team.n,
            "iterations": float(np.mean(known)) if known else float("nan"),
            "rescues": ctrl.rescues,
            "sim_time": float(log.t[-1]), "t_max": sc.spec.t_max,
            "reached": bool(log.meta["reached_goal"]),
            "events": int(log.collision_events.sum())}


def solvers() -> None:
    """Part 1: each solver option on S1 (whole) and S2 (first part), interleaved rounds."""
    for path, t_max in ((S1, None), (S2, S2_SECONDS)):
        runs: dict[str, list[dict]] = {label: [] for label, _ in OPTIONS}
        for _ in range(ROUNDS):
            for label, params in OPTIONS:
                runs[label].append(one_run(path, params, t_max))
        old = np.median([r["median"] for r in runs[OPTIONS[3][0]]])
        ref = np.median([r["median"] for r in runs[OPTIONS[5][0]]])
        what = path.stem + ("" if t_max is None else f", first {t_max:g} s")
        print(f"\n### {what}: solve time per robot per step ({ROUNDS} rounds, median of the "
              "rounds' medians and p95s)\n")
        print("| solver | median (ms) | p95 (ms) | old default / this | ipopt / this | mean "
              "iterations | failures | rescues | run wall (s) |")
        print("|---|---|---|---|---|---|---|---|---|")
        for label, rs in runs.items():
            med = np.median([r["median"] for r in rs])
            p95 = np.median([r["p95"] for r in rs])
            fails = "/".join(str(r["failures"]) for r in rs)
            rescues = "/".join(str(r["rescues"]) for r in rs)
            walls = "/".join(format(r["wall"], ".2f") for r in rs)
            its = np.mean([r["iterations"] for r in rs])
            print(f"| {label} | {1e3 * med:.3f} | {1e3 * p95:.3f} | {old / med:.2f}x | "
                  f"{ref / med:.2f}x | {'-' if np.isnan(its) else format(its, '.2f')} | "
                  f"{fails} of {rs[0]['entries']} | {rescues} | {walls} |", flush=True)


def warm_start(steps: int = WARM_STEPS) -> None:
    """Part 2: warm-started iterations against cold starts of the same problems on S1."""
    print(f"\n### Warm start: iterations over the first {steps} steps of S1 (4 robots)\n")
    print("| solver | warm (shifted plan + multipliers) | same problems, cold | cold / warm |")
    print("|---|---|---|---|")
    for solver in ("sqp", "ipopt"):
        sc = load_scenario(S1, overrides={"t_max": steps * 0.1,
                                          "controllers.nmpc.solver": solver,
                                          "controllers.nmpc.rescue": False,
                                          "controllers.nmpc.compiled": False})
        ctrl = build_controller("nmpc", sc.spec.controllers, sc.source)
        totals = {"warm": 0, "cold": 0}
        act = ctrl.act

        def timed_act(obs, act=act, ctrl=ctrl, totals=totals):
            ids = np.asarray(obs.robot_ids)
            plans = ctrl.plans
            if plans._t is not None and obs.t > plans._t:  # not the first step: compare
                plans._r = {k: v.copy() for k, v in plans._w.items()}
                plans._t = float(obs.t)
                u0, age = plans.shifted(float(obs.t), ids)
                _, params, lbg = ctrl._problems(obs, u0, age >= ctrl.p.horizon)
                h = ctrl.p.horizon
                zero = ctrl.problem.guesses(np.zeros((obs.n, h, 2)),
                                            np.repeat(obs.pose[:, None, :], h, axis=1))
                for i in range(obs.n):
                    totals["cold"] += ctrl.problem.solve(zero[i], params[i], lbg[i]).iterations
                out = act(obs)
                totals["warm"] += int(ctrl.last_iterations.sum())
                return out
            return act(obs)

        ctrl.act = timed_act
        Simulator(sc, ctrl).run()
        print(f"| {solver} | {totals['warm']} | {totals['cold']} | "
              f"{totals['cold'] / max(totals['warm'], 1):.2f}x |")


def scenarios() -> None:
    """Part 3: wall time of one whole run per scenario (large_100: scaled prefix), both solvers."""
    paths = [S1, S2, *sorted((ROOT / "scenarios/bench").glob("*.toml")),
             *sorted((ROOT / "scenarios").glob("example_*.toml"))]
    print("\n### One run per scenario: the default (condensed, compiled, ipopt rescue), the "
          "old default (multiple shooting, interpreted) and ipopt alone (multiple shooting)\n")
    print("| scenario | robots | simulated (s) | steps | wall (s) | ms per step | solve median "
          "(ms) | p95 (ms) | failures | rescues | reached goal | collisions | old wall (s) | "
          "old median / p95 (ms) | ipopt wall (s) | ipopt failures |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for path in paths:
        prefix = LARGE_100_SECONDS if path.stem == "large_100" else None
        for params in ({}, OLD):  # build (and compile) the problems outside the timed runs
            one_run(path, params, 0.1)
        r = one_run(path, {}, prefix)
        old = one_run(path, OLD, prefix)
        ip = one_run(path, {"solver": "ipopt", "formulation": "multiple-shooting"}, prefix)
        wall, old_wall, ip_wall = (f"{x['wall']:.1f}" for x in (r, old, ip))
        if prefix is not None:
            scale = load_scenario(path).spec.t_max / prefix
            wall = f"{r['wall']:.1f} for the first {prefix:g} s (est. {r['wall'] * scale:.0f})"
            old_wall = f"{old['wall']:.1f} (est. {old['wall'] * scale:.0f})"
            ip_wall = f"{ip['wall']:.1f} (est. {ip['wall'] * scale:.0f})"
        print(f"| {path.stem} | {r['n']} | {r['sim_time']:.1f} | {r['steps']} | {wall} | "
              f"{1e3 * r['wall'] / r['steps']:.1f} | {1e3 * r['median']:.3f} | "
              f"{1e3 * r['p95']:.3f} | {r['failures']} | {r['rescues']} | "
              f"{'yes' if r['reached'] else 'no'} | {r['events']} | {old_wall} | "
              f"{1e3 * old['median']:.3f} / {1e3 * old['p95']:.3f} | {ip_wall} | "
              f"{ip['failures']} |", flush=True)


def main() -> None:
    """Run the selected parts."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--parts", default="solvers,warm,scenarios",
                    help="comma-separated: solvers, warm, scenarios")
    parts = ap.parse_args().parts.split(",")
    t0 = time.perf_counter()
    for name, fn in (("solvers", solvers), ("warm", warm_start), ("scenarios", scenarios)):
        if name in parts:
            fn()
    print(f"\nbench_nmpc: {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
