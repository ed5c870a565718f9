"""``dfcoa bench``: run a sweep into a results store, with progress and resume.

>>> from dfcoa_opt.bench.harness import run_sweep                # doctest: +SKIP
>>> run_sweep("scenarios/sweeps/comparison.toml", "results/comparison")
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import sys
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from dfcoa_opt.bench import precision
from dfcoa_opt.bench.executors import ExecutorConfig, run_all
from dfcoa_opt.bench.lifecycle import Interrupted, SweepInterrupted, deferred, interruptible
from dfcoa_opt.bench.results.store import ResultsStore
from dfcoa_opt.bench.sweep.expand import load_sweep
from dfcoa_opt.bench.sweep.specs import (
    DICT_SOURCE,
    RunSpec,
    Sweep,
    describe_runs,
    safe_name,
    shorten,
)


@dataclass(frozen=True)
class SweepResult:
    """What a sweep did.

    Attributes:
        store: The results store.
        sweep: The expanded sweep.
        ran: Runs executed now.
        failed: Of those, how many failed (their rows say why).
        skipped: Runs already done (resumed, or reused).
        reused: Of those, how many were taken from another store (``reuse``).
        errors: Each distinct error of the runs that failed now -> how many runs had it.
    """

    store: ResultsStore
    sweep: Sweep
    ran: int
    failed: int
    skipped: int
    reused: int = 0
    errors: Mapping[str, int] = field(default_factory=dict)

    def summary(self) -> str:
        """For the terminal: one line, then each distinct error of the failed runs once."""
        reused = f" ({self.reused} reused from other stores)" if self.reused else ""
        lines = [f"{self.sweep.name}: {describe_runs(self.sweep.runs)}; ran {self.ran} "
                 f"({self.failed} failed), {self.skipped} already done{reused} -> "
                 f"{self.store.root}"]
        lines += [f"  failed ({n} run{'s' if n > 1 else ''}): {error}"
                  for error, n in sorted(self.errors.items(), key=lambda e: -e[1])]
        return "\n".join(lines)


def _progress(total: int, desc: str, enabled: bool | None):
    from tqdm import tqdm

    if enabled is None:
        enabled = sys.stdout.isatty()
    return tqdm(total=total, desc=desc, unit="run", disable=not enabled, file=sys.stderr,
                dynamic_ncols=True, smoothing=0.1)


def default_folder(sweep: Sweep, seeds: int | None = None,
                   overrides: Mapping[str, Any] | None = None) -> Path:
    """The results folder of a sweep when none is given.

    A sweep file: ``results/<sweep name>`` (``dfcoa bench``; a name longer than
    :data:`~dfcoa_opt.bench.sweep.expand.NAME_MAX` characters shortened with a hash,
    :func:`~dfcoa_opt.bench.sweep.expand.shorten`). A sweep given as a
    dict (the Python facade's): ``results/<name>-<8 hex digits>``, the digits
    the start of the SHA-256 over the dict's canonical JSON (``sweep.sha256``,
    as the manifest records it) with the ``seeds`` and ``overrides`` it runs
    with. The same dict resumes in its folder; a different one gets its own,
    so two sweeps never share rows.

    Args:
        sweep: The loaded sweep.
        seeds: The seed count that replaces the sweep's, if any.
        overrides: Dotted scenario keys set in every run, if any.
    """
    if sweep.source != DICT_SOURCE:
        return Path("results") / shorten(sweep.name)
    content = json.dumps([sweep.sha256, seeds, dict(overrides or {})], sort_keys=True,
                         default=str)
    digest = hashlib.sha256(content.encode()).hexdigest()[:8]
    return Path("results") / f"{safe_name(sweep.name)}-{digest}"


def run_sweep(sweep: str | Path | Sweep, out: str | Path, config: ExecutorConfig | None = None,
              rerun: bool = False, seeds: int | None = None,
              progress: bool | None = None,
              overrides: dict[str, Any] | None = None,
              reuse: Sequence[str | Path] = ()) -> SweepResult:
    """Run every pending run of a sweep and store the rows.

    With ``max_seeds`` in the sweep, cells whose success rate is not yet precise
    enough get more seeds after each round (:mod:`dfcoa_opt.bench.precision`),
    and the manifest lists them.

    The whole sweep is validated first (:func:`~dfcoa_opt.bench.sweep.expand.load_sweep`),
    and ``manifest.json``, ``sweep.toml`` and ``results.csv`` are written only
    once a run has finished (or none is left to run), and list finished rows
    only: a sweep that fails before that leaves an existing results folder as it
    was.

    Args:
        sweep: Sweep file (or an already loaded :class:`Sweep`).
        out: Results folder.
        config: Executor (default: local processes, one per core).
        rerun: Run everything again, even runs that have a row.
        seeds: Replace the sweep's seed count (only when ``sweep`` is a path).
        overrides: Dotted scenario keys set in every run (only when ``sweep`` is a path).
        progress: Show a progress bar; default: only when stdout is a terminal.
        reuse: Other results folders: a pending run that one of them has finished
            under the same key, code, scenario file, overrides, controller and seed
            is copied from there instead of simulated (:meth:`ResultsStore.adopt`);
            not with ``rerun``.

    Returns:
        Counts and the store; ``results.csv`` is rewritten at the end.

    Raises:
        ScenarioError: Bad sweep file (before any run starts; nothing is written).
        SweepInterrupted: SIGINT or SIGTERM arrived; every finished run is saved.
    """
    sw = sweep if isinstance(sweep, Sweep) else load_sweep(sweep, seeds, overrides)
    store = ResultsStore(out)
    others = [] if rerun else [ResultsStore(p) for p in reuse if Path(p).is_dir()]
    reused = [0]
    recorded: list[Sweep | None] = [None]  # the sweep the manifest records; None: untouched

    def record() -> None:
        """Write the manifest (and the sweep file's copy) of ``sw`` once a run of it is stored.

        Until then the folder's manifest, sweep file and ``results.csv`` stay as they
        were: a sweep that stops before its first run finishes changes none of them.
        """
        if recorded[0] is not sw:
            store.write_manifest(sw)
            recorded[0] = sw

    def pending(runs: Sequence[RunSpec]) -> list[RunSpec]:
        todo = store.pending(runs, rerun)
        left = [r for r in todo if not store.adopt(r, others)]
        reused[0] += len(todo) - len(left)
        return left

    todo = pending(sw.runs)
    if reused[0]:  # rows taken from other stores are finished runs
        record()
    ran = failed = 0
    errors: Counter[str] = Counter()
    bar = _progress(len(todo), sw.name, progress)
    try:
        with interruptible():
            while True:
                with contextlib.closing(run_all(todo, config or ExecutorConfig())) as outcomes:
                    for outcome in outcomes:
                        with deferred():  # a row and the manifest that lists it, or neither
                            store.write(outcome)
                            record()
                        ran += 1
                        if outcome.row["status"] != "ok":
                            failed += 1
                            errors[str(outcome.row.get("error") or "no message")] += 1
                        bar.update()
                        if failed:
                            bar.set_postfix(failed=failed, refresh=False)
                grown, todo = _grow(sw, store, pending)
                if grown is not sw:
                    sw = grown
                    record()
                    bar.total += len(todo)
                    bar.refresh()
                if not todo:
                    break
            record()  # also when every run was done already
    except Interrupted as exc:
        saved = sum(store.read_row(r.key) is not None for r in sw.runs)
        raise SweepInterrupted(saved, len(sw.runs), store.root, exc.signum) from None
    finally:
        bar.close()
        if recorded[0] is not None:  # the rows of the recorded sweep, finished ones only
            store.write_csv()
    return SweepResult(store, sw, ran, failed, len(sw.runs) - ran, reused[0], dict(errors))


def _grow(sw: Sweep, store: ResultsStore,
          pending: Callable[[Sequence[RunSpec]], list[RunSpec]]) -> tuple[Sweep, list[RunSpec]]:
    """Add the seeds that cells need until some are to run (none without ``max_seeds``).

    Seeds added by an earlier, interrupted call may already have rows: they join
    the sweep without running, and the next seeds are decided from them.

    Returns:
        The sweep with its added runs (``sw`` itself when none) and the runs to execute.
    """
    while sw.max_seeds:
        rows = [row for r in sw.runs if (row := store.read_row(r.key)) is not None]
        extra = precision.extra_runs(sw.runs, precision.success_by_key(rows),
                                     sw.spec.max_half_width, sw.max_seeds,
                                     sw.spec.decide_at)
        if not extra:
            break
        sw = sw.extended(extra)
        todo = pending(extra)
        if todo:
            return sw, todo
    return sw, []
