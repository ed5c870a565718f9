"""The numba ``prange`` kernels give the same numbers on every thread count.

The test workers of ``make test`` run numba on one thread (tests/conftest.py), as
the sweep workers of ``make figures`` do; users get every core. These tests run
the parallel kernels with all of numba's threads and with one, on batches large
enough for every thread to take rows, and require bit-identical results.
"""

from __future__ import annotations

from pathlib import Path

import numba
import numpy as np
import pytest

from comparisons.orca import lp
from comparisons.orca.crowd import OrcaCrowd, circle_positions
from dfcoa_opt.scenario.loader import load_scenario
from dfcoa_opt.sim.simulator import run_scenario

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"


def _on(threads: int, fn):
    before = numba.get_num_threads()
    numba.set_num_threads(threads)
    try:
        return fn()
    finally:
        numba.set_num_threads(before)


def test_exact_2d_solver_rows_do_not_depend_on_the_thread_count(all_numba_threads):
    rng = np.random.default_rng(11)
    n, k = 600, 12
    ang = rng.uniform(0.0, 2.0 * np.pi, (n, k))
    directions = np.stack([np.cos(ang), np.sin(ang)], axis=-1)
    points = rng.normal(0.0, 0.4, (n, k, 2))
    count = rng.integers(0, k + 1, n)
    args = (points, directions, count, np.zeros(n, np.int64), rng.normal(0.0, 1.0, (n, 2)),
            np.ones(n))
    many = _on(all_numba_threads, lambda: lp.solve_lines(*args))
    one = _on(1, lambda: lp.solve_lines(*args))
    assert (many[1] == lp.LEAST_VIOLATION).any() and (many[1] == lp.FEASIBLE).any()
    for a, b in zip(many, one, strict=True):
        np.testing.assert_array_equal(a, b)


def test_orca_crowd_steps_do_not_depend_on_the_thread_count(all_numba_threads):
    def run() -> np.ndarray:
        crowd = OrcaCrowd(circle_positions(300, 40.0))
        for _ in range(20):
            crowd.step(-crowd.positions / 40.0)
        return crowd.positions.copy()

    np.testing.assert_array_equal(_on(all_numba_threads, run), _on(1, run))


@pytest.mark.parametrize("controller", ["lf_vo", "orca_nav", "goto_slot+cbf"])
def test_large_team_runs_do_not_depend_on_the_thread_count(all_numba_threads, controller):
    def run() -> str:
        sc = load_scenario(SCENARIOS / "bench" / "large_100.toml",
                           overrides={"t_max": 3.0, "controllers.cbf.solver": "exact"})
        return run_scenario(sc, controller).digest()

    assert _on(all_numba_threads, run) == _on(1, run)


def test_small_calls_and_a_busy_machine_get_one_thread(monkeypatch):
    from dfcoa_opt.core.runtime import threads

    monkeypatch.setattr(threads, "PARALLEL_MIN_ROWS", 1000)
    monkeypatch.setattr(threads, "free_cores", lambda: 8)
    assert threads.threads_for(999) == 1
    assert threads.threads_for(1000) == numba.get_num_threads()
    monkeypatch.setattr(threads, "free_cores", lambda: 1)  # every other core busy
    assert threads.threads_for(10**6) == 1
    seen = []
    monkeypatch.setattr(lp, "_solve_batch", lambda *a: seen.append(numba.get_num_threads()))
    before = numba.get_num_threads()
    lp.solve_lines(np.zeros((5, 1, 2)), np.ones((5, 1, 2)), np.zeros(5, int), np.zeros(5, int),
                   np.zeros((5, 2)), np.ones(5))
    assert seen == [1] and numba.get_num_threads() == before


def test_the_load_average_leaves_the_free_cores(monkeypatch):
    import os

    from dfcoa_opt.core.runtime import threads

    monkeypatch.setattr(threads, "_load", (-np.inf, 0))
    monkeypatch.setattr(os, "cpu_count", lambda: 4)
    monkeypatch.setattr(os, "getloadavg", lambda: (2.2, 0.0, 0.0))
    assert threads.free_cores() == 2  # 4 cores, 2.2 busy, this process's own thread among them
    monkeypatch.setattr(os, "getloadavg", lambda: (9.0, 0.0, 0.0))
    assert threads.free_cores() == 2  # read at most once a second
    monkeypatch.setattr(threads, "_load", (-np.inf, 0))
    assert threads.free_cores() == 1
