"""Timing of the scaling study (:mod:`benchmarks.scaling`): per-step times of every run.

Each (controller, N) run is ``Simulator(scenario, controller).run()`` with
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

import json
import math
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from benchmarks.scaling.samples import Sample, median_ms
from benchmarks.scaling.scenario import DEFAULT_MODEL, model_of, open_scenario
from dfcoa_opt.control.registry import make_controller
from dfcoa_opt.scenario.scenario import Scenario
from dfcoa_opt.sim import neighbours as sim_neighbours
from dfcoa_opt.sim import stepper as sim_stepper
from dfcoa_opt.sim.simulator import Simulator
from dfcoa_opt.world import lidar as lidar_module

#: Measured-step budget per (controller, N, round), s; past it the run is cut short (reported).
BUDGET_S = 60.0
#: Timed calls per variant in :func:`sensing_reference`.
SENSING_CALLS = 30


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
    original = sim_stepper.batch_proximity  # the simulator's neighbour query, once a step

    def timed_proximity(*args: Any, **kwargs: Any) -> Any:
        t0 = time.perf_counter()
        out = original(*args, **kwargs)
        query_times.append(time.perf_counter() - t0)
        return out

    sim_stepper.batch_proximity = timed_proximity
    note, log_step = "", math.nan
    try:
        log = sim.run()
        log_step = log.meta["wall_time"] / log.meta["steps"]
    except _OverBudget:
        note = f"cut at {len(ctrl.starts) - 1 - warmup} of {steps} steps (budget {budget:g} s)"
    finally:
        sim_stepper.batch_proximity = original
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

