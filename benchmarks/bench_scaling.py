"""Scaling study (issue 7): cost per step of every registered controller against team size N.

Run ``python -m benchmarks.bench_scaling`` (full study, writes ``benchmarks/scaling.md``,
``scaling.csv`` and ``scaling.png``) or ``python -m benchmarks.bench_scaling --quick``
(smoke configuration, prints only unless ``--out`` is given).

Modules: the scenario (open field, grid formation, LiDAR on for every controller because
``dfcoa`` needs it) is :mod:`benchmarks.scaling_scenario`; peak memory (a fresh subprocess
per controller, ``--memory-child``) :mod:`benchmarks.scaling_memory`; the summary, CSV,
plot and stdout tables :mod:`benchmarks.scaling_report`; ``scaling.md``
:mod:`benchmarks.scaling_markdown`. This one times the runs and holds the command line.
The simulator's own share of a step (LiDAR, neighbour query, the rest) is reported
separately.

Timing. Each (controller, N) run is ``Simulator(scenario, controller).run()`` with
``t_max`` covering ``warmup + steps`` steps. A wrapper times every ``act`` call (the
controller's cost per step); the whole step is the time between two successive
``act`` starts (the rest of the step, logging, and the next step's sensing). The
LiDAR scan and the neighbour query are timed by wrappers installed for the run
only. The first ``warmup`` steps are dropped; numba kernels are compiled (or loaded
from the cache) by a small run of every controller before anything is timed.
Every (controller, N) pair is measured in ``rounds`` interleaved rounds and the
step times are pooled: medians and min-max are over all measured steps. Ratios
are against the smallest N of the same controller, measured in the same process.
The two N-dependent sensing parts (LiDAR disc candidates, neighbour query) are also
timed against same-process variants (:func:`sensing_reference`).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.scaling_markdown import markdown
from benchmarks.scaling_memory import memory_child, peak_memory
from benchmarks.scaling_report import median_ms, plot, print_summary, summarise, write_csv
from benchmarks.scaling_scenario import DEFAULT_MODEL, model_of, open_scenario
from dfcoa_opt.control.registry import available, make_controller
from dfcoa_opt.core.runtime.provenance import machine, versions
from dfcoa_opt.scenario.scenario import Scenario
from dfcoa_opt.sim import neighbours as sim_neighbours
from dfcoa_opt.sim import simulator as sim_module
from dfcoa_opt.sim.simulator import Simulator
from dfcoa_opt.world import lidar as lidar_module

OUT_DIR = Path(__file__).resolve().parent
SIZES = (4, 16, 64, 256, 1000)
QUICK_SIZES = (4, 16, 64)
#: Measured-step budget per (controller, N, round), s; past it the run is cut short (reported).
BUDGET_S = 60.0
#: Timed calls per variant in :func:`sensing_reference`.
SENSING_CALLS = 30


# --------------------------------------------------------------------------- timing
class _OverBudget(Exception):
    """Raised from inside a run when its measured steps exceed the budget."""


class _TimedController:
    """Controller wrapper: records the start and duration of every ``act`` call (s).

    Every other attribute (``name``, ``command``, ``last_result``, ``last_steering``)
    is read from the wrapped controller, so the simulator logs what it would log.
    """

    def __init__(self, inner: Any, warmup: int, budget: float) -> None:
        self.inner = inner
        self.warmup = warmup
        self.budget = budget
        self.starts: list[float] = []
        self.durations: list[float] = []

    def __getattr__(self, key: str) -> Any:
        if key == "inner":
            raise AttributeError(key)
        return getattr(self.inner, key)

    def reset(self, scenario: Scenario, rng: np.random.Generator) -> None:
        """Reset the wrapped controller."""
        self.inner.reset(scenario, rng)

    def act(self, obs: Any) -> Any:
        """Time the wrapped ``act``; stop the run once the measured steps exceed the budget."""
        t0 = time.perf_counter()
        if len(self.starts) > self.warmup and t0 - self.starts[self.warmup] > self.budget:
            raise _OverBudget
        self.starts.append(t0)
        out = self.inner.act(obs)
        self.durations.append(time.perf_counter() - t0)
        return out


class _TimedLidar:
    """LiDAR wrapper recording the duration of every ``scan`` call (s)."""

    def __init__(self, inner: Any) -> None:
        self.inner = inner
        self.durations: list[float] = []

    def __getattr__(self, key: str) -> Any:
        if key == "inner":
            raise AttributeError(key)
        return getattr(self.inner, key)

    def scan(self, *args: Any, **kwargs: Any) -> Any:
        """Time the wrapped scan."""
        t0 = time.perf_counter()
        out = self.inner.scan(*args, **kwargs)
        self.durations.append(time.perf_counter() - t0)
        return out


@dataclass
class Sample:
    """Per-step times (s) of one or more runs of one controller at one N.

    Attributes:
        act: Controller ``act`` durations.
        step: Whole-step durations (successive ``act`` starts).
        lidar: LiDAR scan durations (sensing of the step that follows).
        query: Neighbour-query (``proximity``) durations.
        rounds: Median ``act`` time of each round, s (noise indicator).
        log_step: ``wall_time / steps`` of each run's log (warm-up included), s.
        notes: Caps and skips.
    """

    act: list[float] = field(default_factory=list)
    step: list[float] = field(default_factory=list)
    lidar: list[float] = field(default_factory=list)
    query: list[float] = field(default_factory=list)
    rounds: list[float] = field(default_factory=list)
    log_step: list[float] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


def timed_run(scenario: Scenario, controller_id: str, warmup: int, steps: int,
              budget: float = BUDGET_S) -> tuple[dict[str, np.ndarray], float, str]:
    """One simulator run with timers; drop the first ``warmup`` steps.

    Args:
        scenario: Scenario whose ``t_max`` covers ``warmup + steps`` steps.
        controller_id: Registry id.
        warmup: Steps not measured.
        steps: Steps measured.
        budget: Largest measured time, s; the run stops early past it.

    Returns:
        ``(times, log mean step s, note)``: arrays of per-step times in s under
        ``act``, ``step``, ``lidar``, ``query``; the note says when the run was cut.
    """
    ctrl = _TimedController(make_controller(controller_id), warmup, budget)
    sim = Simulator(scenario, ctrl)
    lidar = _TimedLidar(sim.lidar) if sim.lidar is not None else None
    if lidar is not None:
        sim.lidar = lidar
    query_times: list[float] = []
    original = sim_module.proximity

    def timed_proximity(*args: Any, **kwargs: Any) -> Any:
        t0 = time.perf_counter()
        out = original(*args, **kwargs)
        query_times.append(time.perf_counter() - t0)
        return out

    sim_module.proximity = timed_proximity
    note, log_step = "", math.nan
    try:
        log = sim.run()
        log_step = log.meta["wall_time"] / log.meta["steps"]
    except _OverBudget:
        note = f"cut at {len(ctrl.starts) - 1 - warmup} of {steps} steps (budget {budget:g} s)"
    finally:
        sim_module.proximity = original
    starts = np.asarray(ctrl.starts)
    m = len(starts) - 1  # complete steps: act start k to act start k + 1
    sl = slice(warmup, m)
    times = {"act": np.asarray(ctrl.durations[:m])[sl], "step": np.diff(starts)[sl],
             "lidar": np.asarray(lidar.durations[1:m + 1] if lidar is not None else [])[sl],
             "query": np.asarray(query_times[1:m + 1])[sl]}
    return times, log_step, note


def warm_up(controllers: Sequence[str]) -> None:
    """Run every controller at N = 16 and 64 (numba compile or cache load, both query branches)."""
    for cid in controllers:
        sc = open_scenario(16, model_of(cid), 3)
        timed_run(sc, cid, 0, 3)
        sc = open_scenario(64, model_of(cid), 3)  # the KD-tree branch of the neighbour query
        timed_run(sc, cid, 0, 3)


def measure(controllers: Sequence[str], sizes: Sequence[int], warmup: int, steps: int,
            rounds: int, budget: float, log: Callable[[str], None] = print
            ) -> tuple[dict[tuple[str, int], Sample], dict[int, float]]:
    """Time every (controller, N) pair in ``rounds`` interleaved rounds.

    Args:
        controllers: Registry ids.
        sizes: Team sizes N.
        warmup: Unmeasured steps at the start of each run.
        steps: Measured steps per run.
        rounds: Runs per pair (interleaved: every pair once per round).
        budget: Measured-time budget per run, s.
        log: Progress printer.

    Returns:
        ``(samples, build_seconds)``: the pooled times per pair and the scenario build
        time per N (first model), s.
    """
    scenarios: dict[tuple[int, str], Scenario] = {}
    build: dict[int, float] = {}
    samples = {(c, n): Sample() for c in controllers for n in sizes}
    skipped: set[tuple[str, int]] = set()
    for r in range(rounds):
        for n in sizes:
            for cid in controllers:
                key = (cid, n)
                if key in skipped:
                    continue
                robots = model_of(cid)
                skey = (n, json.dumps(robots, sort_keys=True))
                if skey not in scenarios:
                    t0 = time.perf_counter()
                    scenarios[skey] = open_scenario(n, robots, warmup + steps)
                    build.setdefault(n, time.perf_counter() - t0)
                times, log_step, note = timed_run(scenarios[skey], cid, warmup, steps, budget)
                s = samples[key]
                for name in ("act", "step", "lidar", "query"):
                    getattr(s, name).extend(times[name].tolist())
                s.log_step.append(log_step)
                if len(times["act"]):
                    s.rounds.append(float(np.median(times["act"])))
                if note:  # later rounds would be cut as well: skip them
                    s.notes.append(f"round {r + 1}: {note}")
                    if r + 1 < rounds:
                        skipped.add(key)
                        s.notes.append("later rounds skipped")
                log(f"round {r + 1}/{rounds}  N={n:5d}  {cid:22s} act "
                    f"{median_ms(times['act']):9.3f} ms  step {median_ms(times['step']):9.3f} ms"
                    + (f"  [{note}]" if note else ""))
    return samples, build


def sensing_reference(sizes: Sequence[int], calls: int = 20) -> list[dict[str, float]]:
    """Same-process references for the simulator's two N-dependent sensing parts.

    At each N (the scenario's start poses, ``goto_slot``'s unicycle scenario):

    * LiDAR scan with the library's candidate choice, with every robot-disc pair
      tested in the kernel (``CANDIDATES_MIN_PAIRS`` set out of reach) and with the pair
      threshold at 0 (bucket-grid candidates whenever the coverage condition allows),
      and the library's candidate-list step (``Lidar._discs``) alone;
    * the simulator's neighbour query ``proximity`` (K-nearest table, closest pair,
      contacts) against ``neighbour_table`` alone (the K-nearest table only).

    The module constant is changed for the timed calls only and restored.

    Args:
        sizes: Team sizes.
        calls: Timed calls per variant (after one untimed call).

    Returns:
        One dict per N with medians in ms.
    """

    def med(fn: Callable[..., object], *args: Any) -> float:
        fn(*args)
        ts = []
        for _ in range(calls):
            t0 = time.perf_counter()
            fn(*args)
            ts.append(time.perf_counter() - t0)
        return float(np.median(ts)) * 1e3

    rows = []
    saved = lidar_module.CANDIDATES_MIN_PAIRS
    for n in sizes:
        sc = open_scenario(n, DEFAULT_MODEL, 1)
        spec = sc.spec
        lidar = lidar_module.Lidar(spec.sensors.lidar, sc.world.grid)
        pose = sc.initial_pose
        pos = np.ascontiguousarray(pose[:, :2])
        radii, owner = np.full(n, spec.robots.radius), np.arange(n)
        row = {"n": n}
        try:
            for name, threshold in (("lidar_default", saved), ("lidar_all_pairs", 2**62),
                                    ("lidar_kdtree", 0)):
                lidar_module.CANDIDATES_MIN_PAIRS = threshold
                row[name] = med(lidar.scan, pose, pos, radii, owner)
            lidar_module.CANDIDATES_MIN_PAIRS = saved
            row["lidar_candidates"] = med(lidar._discs, pose, pos, radii, owner)
            row["lidar_kdtree_used"] = float(len(lidar._discs(pose, pos, radii, owner)[3]) > 0)
        finally:
            lidar_module.CANDIDATES_MIN_PAIRS = saved
        args = (pos, spec.sensors.comm_radius, spec.sensors.max_neighbors)
        row["proximity"] = med(sim_neighbours.proximity, *args, 2.0 * spec.robots.radius)
        row["neighbour_table"] = med(sim_neighbours.neighbour_table, *args)
        rows.append(row)
    return rows


# --------------------------------------------------------------------------- main
def _ints(text: str) -> list[int]:
    return [int(x) for x in text.split(",") if x.strip()]


def parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    """Command-line options (see ``--help``)."""
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_scaling",
                                 description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=_ints, default=None,
                    help=f"team sizes, comma-separated (default {','.join(map(str, SIZES))})")
    ap.add_argument("--controllers", default=None,
                    help="controller ids, comma-separated (default: every registered one)")
    ap.add_argument("--steps", type=int, default=None, help="measured steps per run (30)")
    ap.add_argument("--warmup", type=int, default=None, help="unmeasured steps per run (5)")
    ap.add_argument("--rounds", type=int, default=None, help="interleaved rounds (5)")
    ap.add_argument("--budget", type=float, default=BUDGET_S,
                    help="measured seconds per run before it is cut short (60)")
    ap.add_argument("--memory-n", type=int, default=None,
                    help="team size of the peak-memory runs (largest size); 0 = skip")
    ap.add_argument("--memory-steps", type=int, default=10, help="steps of a memory run")
    ap.add_argument("--out", type=Path, default=None,
                    help="folder for scaling.md/.csv/.png (default benchmarks/; --quick: none)")
    ap.add_argument("--quick", action="store_true",
                    help="smoke run: N=4,16,64, 2+5 steps, 1 round, memory at N=64, no files")
    ap.add_argument("--memory-child", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--memory-traced", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    quick = args.quick
    args.sizes = args.sizes or list(QUICK_SIZES if quick else SIZES)
    args.steps = args.steps or (5 if quick else 30)
    args.warmup = args.warmup if args.warmup is not None else (2 if quick else 5)
    args.rounds = args.rounds or (1 if quick else 5)
    if args.memory_n is None:
        args.memory_n = max(args.sizes)
    if args.out is None and not quick:
        args.out = OUT_DIR
    return args


def main(argv: Sequence[str] | None = None) -> int:
    """Run the study; print the tables; write the files unless ``--quick`` without ``--out``.

    Returns:
        Process exit code (0).
    """
    args = parse_args(argv)
    if args.memory_child:
        print(json.dumps(memory_child(args.memory_child, args.memory_n, args.memory_steps,
                                      args.memory_traced)))
        return 0
    t_start = time.perf_counter()
    controllers = (args.controllers.split(",") if args.controllers else available())
    sizes = sorted(set(args.sizes))
    print(f"CPU: {machine()}; {versions()}")
    print(f"controllers: {', '.join(controllers)}; sizes {sizes}; {args.rounds} round(s) of "
          f"{args.warmup} + {args.steps} steps")
    warm_up(controllers)
    samples, build = measure(controllers, sizes, args.warmup, args.steps, args.rounds,
                             args.budget)
    summary = summarise(samples, controllers, sizes)
    print_summary(summary, controllers, sizes)
    sensing = sensing_reference(sizes, SENSING_CALLS)
    for r in sensing:
        print(f"sensing N={r['n']:5d}: LiDAR as chosen {r['lidar_default']:.3f} ms, all pairs "
              f"{r['lidar_all_pairs']:.3f}, candidates {r['lidar_kdtree']:.3f}; proximity "
              f"{r['proximity']:.3f} ms, neighbour_table {r['neighbour_table']:.3f}")
    memory: dict[str, dict[str, float]] = {}
    ref_n = min(sizes)
    if args.memory_n:
        memory = peak_memory(controllers, args.memory_n, ref_n, args.memory_steps)
    elapsed = time.perf_counter() - t_start
    print(f"\nwhole run: {elapsed:.1f} s")
    if args.out is not None:
        cfg = {"rounds": args.rounds, "warmup": args.warmup, "steps": args.steps,
               "budget": args.budget, "memory_n": args.memory_n, "memory_ref_n": ref_n,
               "memory_steps": args.memory_steps, "sensing_calls": SENSING_CALLS}
        args.out.mkdir(parents=True, exist_ok=True)
        write_csv(summary, args.out / "scaling.csv")
        plot(summary, controllers, sizes, args.out / "scaling.png")
        (args.out / "scaling.md").write_text(
            markdown(summary, controllers, sizes, memory, build, cfg, elapsed, sensing))
        print(f"wrote {args.out / 'scaling.md'}, scaling.csv, scaling.png")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
