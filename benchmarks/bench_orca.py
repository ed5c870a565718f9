"""Benchmark: one ORCA step against RVO2 (``pyrvo`` ``do_step``), side by side.

Run ``python -m benchmarks.bench_orca``. RVO2's Circle: N agents on a circle
(N = 1000 at radius 800 m; N = 100, 250 at radius 0.8 N m), agent defaults
(15, 10, 10, 10, 1.5, 2), dt 0.25 s, preferred velocity towards the antipode.
Both simulators advance from the same start; each sample times one step of
each, alternately, so the machine's noise hits both alike. Ours is
:meth:`comparisons.orca.crowd.OrcaCrowd.step` (grid kNN + ORCA lines + exact
LP, numba, both cores); the reference is pyrvo's ``do_step`` (C++, single
thread as built on PyPI). The preferred velocities are set outside the timed
region for both.
"""

from __future__ import annotations

import time

import numpy as np

from benchmarks.bench_lidar import print_rows, row
from comparisons.orca.crowd import OrcaCrowd, circle_positions, goal_velocities

STEPS = 60
#: (agents, circle radius in m)
CASES = ((100, 80.0), (250, 200.0), (1000, 800.0))


def run() -> list[dict]:
    """Rows: our step vs pyrvo ``do_step`` per case (skipped when pyrvo is missing)."""
    try:
        import pyrvo
    except ImportError:
        print("bench_orca: pyrvo not installed (pip install -e '.[dev]'); skipped")
        return []
    rows = []
    for n, radius in CASES:
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
            t0 = time.perf_counter()
            sim.do_step()
            ref[s] = time.perf_counter() - t0
            t0 = time.perf_counter()
            crowd.step(pref)
            ours[s] = time.perf_counter() - t0
        rows.append(row(f"ORCA step, Circle N={n}", 1e6 * ours, "pyrvo do_step", 1e6 * ref))
    return rows


if __name__ == "__main__":
    print_rows(run())
