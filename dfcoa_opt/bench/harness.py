"""``dfcoa bench``: run a sweep into a results store, with progress and resume.

>>> from dfcoa_opt.bench.harness import run_sweep                # doctest: +SKIP
>>> run_sweep("scenarios/sweeps/comparison.toml", "results/comparison")
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from dfcoa_opt.bench.executors import ExecutorConfig, run_all
from dfcoa_opt.bench.store import ResultsStore
from dfcoa_opt.bench.sweep import Sweep, describe_runs, load_sweep


@dataclass(frozen=True)
class SweepResult:
    """What a sweep did.

    Attributes:
        store: The results store.
        sweep: The expanded sweep.
        ran: Runs executed now.
        failed: Of those, how many failed (their rows say why).
        skipped: Runs already done (resumed).
    """

    store: ResultsStore
    sweep: Sweep
    ran: int
    failed: int
    skipped: int

    def summary(self) -> str:
        """One line for the terminal."""
        return (f"{self.sweep.name}: {describe_runs(self.sweep.runs)}; ran {self.ran} "
                f"({self.failed} failed), {self.skipped} already done -> {self.store.root}")


def _progress(total: int, desc: str, enabled: bool | None):
    from tqdm import tqdm

    if enabled is None:
        enabled = sys.stdout.isatty()
    return tqdm(total=total, desc=desc, unit="run", disable=not enabled, file=sys.stderr,
                dynamic_ncols=True, smoothing=0.1)


def run_sweep(sweep: str | Path | Sweep, out: str | Path, config: ExecutorConfig | None = None,
              rerun: bool = False, seeds: int | None = None,
              progress: bool | None = None,
              overrides: dict[str, Any] | None = None) -> SweepResult:
    """Run every pending run of a sweep and store the rows.

    Args:
        sweep: Sweep file (or an already loaded :class:`Sweep`).
        out: Results folder.
        config: Executor (default: local processes, one per core).
        rerun: Run everything again, even runs that have a row.
        seeds: Replace the sweep's seed count (only when ``sweep`` is a path).
        overrides: Dotted scenario keys set in every run (only when ``sweep`` is a path).
        progress: Show a progress bar; default: only when stdout is a terminal.

    Returns:
        Counts and the store; ``results.csv`` is rewritten at the end.

    Raises:
        ScenarioError: Bad sweep file (before any run starts).
    """
    sw = sweep if isinstance(sweep, Sweep) else load_sweep(sweep, seeds, overrides)
    store = ResultsStore(out)
    store.write_manifest(sw)
    todo = store.pending(sw.runs, rerun)
    failed = 0
    bar = _progress(len(todo), sw.name, progress)
    try:
        for outcome in run_all(todo, config or ExecutorConfig()):
            store.write(outcome)
            failed += outcome.row["status"] != "ok"
            bar.update()
            if failed:
                bar.set_postfix(failed=failed, refresh=False)
    finally:
        bar.close()
        store.write_csv()
    return SweepResult(store, sw, len(todo), failed, len(sw.runs) - len(todo))
