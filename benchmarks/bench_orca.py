"""Benchmark: one ORCA step against RVO2 (``pyrvo`` ``do_step``), side by side.

Run ``python -m benchmarks.bench_orca``. RVO2's Circle: N agents on a circle
(N = 1000 at radius 800 m; N = 100, 250 at radius 0.8 N m), agent defaults
(15, 10, 10, 10, 1.5, 2), dt 0.25 s, preferred velocity towards the antipode.
Both simulators advance from the same start; each sample times one step of
each, alternately, so the machine's noise hits both alike. Ours is
:meth:`comparisons.orca.crowd.OrcaCrowd.step` (grid kNN + ORCA lines + exact
LP, numba); the reference is pyrvo's ``do_step`` (C++, single thread as built
on PyPI). The preferred velocities are set outside the timed region for both.
The main rows run ours on one thread too (``numba.set_num_threads(1)``), so
thread for thread; the "all cores" rows give ours every numba thread that
:mod:`dfcoa_opt.core.runtime.threads` lets a call of that size use on the machine's load
(one below 1000 agents or on a busy machine), and say so. The per-step pairs
are split into :data:`~benchmarks.timing.REPS` blocks for the ratio's spread.
"""

from __future__ import annotations

import time

import numba
import numpy as np

from benchmarks.timing import blocks, print_rows, row
from comparisons.orca.crowd import OrcaCrowd, circle_positions, goal_velocities

STEPS = 60
#: (agents, circle radius in m)
CASES = ((100, 80.0), (250, 200.0), (1000, 800.0), (10_000, 8000.0))


def run() -> list[dict]:
    """Rows: our step vs pyrvo ``do_step`` per case (skipped when pyrvo is missing)."""
    try:
        import pyrvo
    except ImportError:
        print("bench_orca: pyrvo not installed (pip install -e '.[dev]'); skipped")
        return []
    rows = []
    all_threads = numba.get_num_threads()
    for threads in (1, all_threads):
        numba.set_num_threads(threads)
        try:
            for n, radius in CASES:
                ours, ref = _paired_steps(pyrvo, n, radius)
                label = ("one thread" if threads == 1 else
                         f"all cores ({threads} threads, as dfcoa_opt.core.runtime.threads allows)")
                rows.append(row(f"ORCA step, Circle N={n}, {label}", blocks(1e6 * ours),
                                "pyrvo do_step (one thread)", blocks(1e6 * ref)))
        finally:
            numba.set_num_threads(all_threads)
    return rows


def _paired_steps(pyrvo, n: int, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Per-step times (s) of our step and pyrvo's, step for step from the same start."""
    start = circle_positions(n, radius)
    goals = -start
    sim = pyrvo.RVOSimulator()
    sim.set_time_step(0.25)
    sim.set_agent_defaults(15.0, 10, 10.0, 10.0, 1.5, 2.0)
    for p in start:
        sim.add_agent(tuple(p))
    crowd = OrcaCrowd(start.copy())
    crowd.step(goal_velocities(crowd.positions, goals))  # warm-up (numba compile)
    ours, ref = np.empty(STEPS), np.empty(STEPS)
    for s in range(STEPS):
        pref = goal_velocities(crowd.positions, goals)
        for i in range(n):
            sim.set_agent_pref_velocity(i, (float(pref[i, 0]), float(pref[i, 1])))
        first_ours = s % 2 == 1
        if first_ours:
            t0 = time.perf_counter()
            crowd.step(pref)
            ours[s] = time.perf_counter() - t0
        t0 = time.perf_counter()
        sim.do_step()
        ref[s] = time.perf_counter() - t0
        if not first_ours:
            t0 = time.perf_counter()
            crowd.step(pref)
            ours[s] = time.perf_counter() - t0
    return ours, ref


if __name__ == "__main__":
    print_rows(run())
