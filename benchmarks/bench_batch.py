"""Batched simulation: the cost per run-step of a batch of E = 20 runs against E = 1.

Each row times whole batches (:class:`~dfcoa_opt.sim.batch.BatchSimulator`)
of one scenario with E = 1 and E = 20 seeds, interleaved, and divides each
batch's stepping time by its logged run-steps (the sum of its runs' steps). The
reference is the same controller at E = 1 in the same repetitions, so the
ratio says how many times cheaper a run-step is in a batch of 20: the
targets are 8x for the simulator with ``goto_slot`` on the corridor, 3x for
every batch-native controller on clutter and 2x for ``nmpc``. Runs are cut at
``T_MAX`` (``nmpc``: ``T_MAX_NMPC``) so that ``make bench`` stays short.

``python -m benchmarks.bench_batch [controller ...]`` prints the rows.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from benchmarks.timing import REPS, print_rows, row
from dfcoa_opt.scenario.loader import load_scenario
from dfcoa_opt.sim.batch import BatchSimulator
from dfcoa_opt.sim.simulator import batch_controllers

ROOT = Path(__file__).resolve().parents[1]
#: Simulated seconds per run.
T_MAX = 15.0
T_MAX_NMPC = 4.0
#: Runs in the batch.
E = 20
#: (controller, scenario, target ratio): the rows, in order.
CASES = [("goto_slot", "corridor", 8.0), *((c, "clutter", 3.0) for c in (
    "goto_slot", "goto_slot+cbf", "goto_slot+orca", "orca_nav", "consensus", "consensus_ivo",
    "virtual_spring", "virtual_spring_basic", "lf_vo", "dfcoa", "reshape")),
    ("nmpc", "clutter", 2.0)]
#: As the comparison runs them.
SETTINGS = {"controllers.virtual_spring.offset_frame": "leader",
            "controllers.virtual_spring_basic.offset_frame": "leader",
            "controllers.cbf.solver": "exact"}


def per_run_step(controller: str, scenario: str, runs: int) -> tuple[float, float]:
    """Wall time (us) of one batch's stepping divided by its run-steps, and that time (s).

    The scenarios (a seeded clutter field is drawn per seed) and controllers are
    built before the clock starts, as a single run's are.
    """
    t_max = T_MAX_NMPC if controller == "nmpc" else T_MAX
    sc = load_scenario(ROOT / "scenarios" / "bench" / f"{scenario}.toml", 0,
                       {**SETTINGS, "t_max": t_max})
    sim = BatchSimulator(sc, batch_controllers(controller, sc, runs), list(range(runs)))
    t0 = time.perf_counter()
    logs = sim.run_all()
    wall = time.perf_counter() - t0
    return wall * 1e6 / sum(log.n_steps for log in logs), wall


def case_row(controller: str, scenario: str, target: float) -> dict:
    """One row: E = 20 against E = 1 in :data:`~benchmarks.timing.REPS` interleaved repetitions."""
    for runs in (1, E):  # warm-up: numba compilation, the scenario's leader track
        per_run_step(controller, scenario, runs)
    batch: list[np.ndarray] = []
    single: list[np.ndarray] = []
    for rep in range(REPS):
        turns = [(E, batch), (1, single)]
        for runs, out in (turns if rep % 2 == 0 else turns[::-1]):
            out.append(np.array([per_run_step(controller, scenario, runs)[0]]))
    return row(title(controller, scenario), batch, "the same, E = 1", single)


def title(controller: str, scenario: str) -> str:
    """A case's row title (``benchmarks/run.py`` matches its target by it)."""
    return f"batch of {E}, per run-step, {controller} on {scenario}"


def run(only: list[str] | None = None) -> list[dict]:
    """Every row of :data:`CASES` (or of the controllers in ``only``)."""
    rows = []
    for controller, scenario, target in CASES:
        if only and controller not in only:
            continue
        rows.append(case_row(controller, scenario, target))
    return rows


if __name__ == "__main__":
    print_rows(run(sys.argv[1:] or None))
