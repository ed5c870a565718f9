"""``make figures``: every paper table and figure, through the benchmark harness.

The figure recipes (a sweep file and a renderer each) are registered in
:mod:`dfcoa_opt.bench.recipes`, one module per paper or group.
``make_figures`` runs each recipe's sweep into a result cache
(``.dfcoa-cache/<recipe>/``; runs already there are reused, so a second
``make figures`` only re-renders), renders into ``paper_figures/<recipe>/`` and
writes the index ``paper_figures/README.md``. Renderers of sweep recipes read
saved rows and logs only; they never simulate.

``Artefact``, ``recipe`` and ``recipes`` of release 0.1 are still importable
from here (they live in :mod:`dfcoa_opt.bench.recipes`).
"""

from __future__ import annotations

import json
import os
import pickle
import sys
import time
from collections.abc import Sequence
from concurrent.futures import Future, ProcessPoolExecutor
from dataclasses import asdict
from pathlib import Path
from typing import Any

from dfcoa_opt.bench.executors import ExecutorConfig, worker_preload
from dfcoa_opt.bench.harness import run_sweep
from dfcoa_opt.bench.lifecycle import (
    deferred,
    forkserver_context,
    init_worker,
    interruptible,
    terminate,
)
from dfcoa_opt.bench.recipes import Artefact, Recipe, Renderer, recipe, registered
from dfcoa_opt.core.atomic import atomic_write
from dfcoa_opt.core.errors import DfcoaError, did_you_mean

#: The 0.1 name of :func:`dfcoa_opt.bench.recipes.registered`.
recipes = registered

__all__ = ["Artefact", "Recipe", "make_figures", "recipe", "recipes",
           "write_index"]


def make_figures(scenarios: Path, out: Path, cache: Path,
                 config: ExecutorConfig | None = None, only: Sequence[str] | None = None,
                 seeds: int | None = None, progress: bool | None = None,
                 overrides: dict[str, Any] | None = None, compact: bool = True,
                 snapshots: int | None = None) -> Path:
    """Run every recipe's sweep (reusing cached runs) and render its artefacts.

    After the last render, the logs that a renderer read are pruned to the
    fields it read, exact, and the others compacted
    (:func:`~dfcoa_opt.bench.results.logs.compact_store`: trajectories only, about 3 %
    of a full log); rows stay whole, so every table is the same. A renderer
    that asks for a compacted log or a pruned field (its code changed since)
    gets those runs simulated again and renders once more.

    Args:
        scenarios: Scenario root; recipe sweeps are relative to it.
        out: Output folder (``paper_figures``).
        cache: Result cache; one results folder per recipe.
        config: Executor for the sweeps (default: local processes).
        only: Run only these recipes (the index still lists every rendered one).
        seeds: Override every sweep's seed count (quick smoke runs).
        overrides: Dotted scenario keys set in every run (e.g. ``{"t_max": 5.0}``);
            with ``seeds``, a reduced configuration for smoke tests.
        progress: Progress bars; default when stdout is a terminal.
        compact: Compact the logs no figure reads (False: keep every full log).
        snapshots: Failure snapshots a report draws at most per scenario
            (:func:`~dfcoa_opt.bench.report.failures.snapshot_limit`; None: every
            one). For reduced runs, where every variant fails and drawing each
            failure would test one function a hundred times.

    Returns:
        Path of the index ``README.md``.

    Raises:
        DfcoaError: Unknown recipe name, bad sweep or scenario file.
    """
    todo = registered()
    names = [r.name for r in todo]
    for name in only or ():
        if name not in names:
            raise DfcoaError(f"--only: unknown recipe '{name}'{did_you_mean(name, names)}; "
                             f"available: {', '.join(names)}")
    start = time.perf_counter()
    config = config or ExecutorConfig()
    jobs = config.jobs or os.cpu_count() or 1
    with interruptible(), _Renderer(jobs if config.kind == "process" and jobs > 1 else 0,
                                    cache, judged=seeds is None and not overrides,
                                    snapshots=snapshots) as renderer:
        for r in todo:
            if only and r.name not in only:
                continue
            t0 = time.perf_counter()
            dest = out / r.name
            dest.mkdir(parents=True, exist_ok=True)
            if r.sweep is None:
                renderer.submit(r, scenarios, dest, "computed")
                continue
            # a run another recipe has already simulated (same key, code, scenario
            # file, overrides, controller and seed) is copied, not simulated again
            result = run_sweep(scenarios / r.sweep, cache / r.name, config, seeds=seeds,
                               progress=progress, overrides=overrides,
                               reuse=[cache / n for n in names if n != r.name])
            reused = f", {result.reused} of them from other recipes" if result.reused else ""
            renderer.submit(r, result.store.root, dest,
                            f"{result.ran} runs ({result.failed} failed), {result.skipped} "
                            f"cached{reused}, simulated in {time.perf_counter() - t0:.1f} s")
        renderer.finish()
        for r, dest in renderer.redo:  # a compacted log was wanted: those runs again
            restored = restore_logs(cache / r.name)
            result = run_sweep(scenarios / str(r.sweep), cache / r.name, config, seeds=seeds,
                               progress=progress, overrides=overrides)
            renderer.render_now(r, result.store.root, dest, f"{restored} compacted runs "
                                                            "simulated again for their logs")
        if compact:
            _compact(cache, renderer.reads, renderer.pool)
    print(f"figures: {time.perf_counter() - start:.1f} s in all", file=sys.stderr)
    return write_index(out, names)


def _compact(cache: Path, reads: dict[str, dict[str, set[str]]],
             pool: ProcessPoolExecutor | None) -> None:
    """Shrink each rendered recipe's logs: pruned to the fields read, or compacted if unread.

    The render processes (``pool``, when there are) share the files.
    """
    from dfcoa_opt.bench.results.logs import compact_store

    compacted = pruned = saved = 0
    for name, keys in reads.items():
        if (cache / name / "logs").is_dir():
            c, p, b = compact_store(cache / name, keys, pool)
            compacted, pruned, saved = compacted + c, pruned + p, saved + b
    total = sum(p.stat().st_size for p in cache.rglob("*") if p.is_file())
    print(f"cache: {compacted} logs no figure reads compacted, {pruned} pruned to the fields "
          f"figures read ({saved / 2**20:.0f} MB saved); {cache} holds {total / 2**20:.0f} MB",
          file=sys.stderr)


def restore_logs(root: Path) -> int:
    """Drop the runs whose logs are compacted or pruned, so that the sweep runs them again.

    Returns:
        How many rows were dropped.
    """
    from dfcoa_opt.sim.log import is_compact, is_pruned

    count = 0
    for path in sorted((root / "logs").glob("*.npz")):
        if is_compact(path) or is_pruned(path):
            (root / "rows" / f"{path.stem}.json").unlink(missing_ok=True)
            path.unlink()
            count += 1
    return count


#: What a render returns: its artefacts, its wall time (s), and the logs it read (run key ->
#: fields).
_Rendered = tuple[list[Artefact], float, dict[str, set[str]]]


def _render(render: Renderer, source: Path, is_store: bool,
            dest: Path, snapshots: int | None = None) -> _Rendered:
    """Run one renderer (in the render process or inline); ``source``: store root or scenarios.

    Returns:
        The artefacts, the rendering's wall time (s) and the runs whose logs it read, with
        the fields read.
    """
    from dfcoa_opt.bench.report.failures import snapshot_limit
    from dfcoa_opt.bench.results.logs import tracing
    from dfcoa_opt.bench.results.store import ResultsStore

    t0 = time.perf_counter()
    with tracing() as keys, snapshot_limit(snapshots):
        arts = render(ResultsStore(source) if is_store else source, dest)
    return arts, time.perf_counter() - t0, keys


class _Renderer:
    """Renders recipes in worker processes, side by side and while the next sweep simulates.

    Rendering (matplotlib) runs in this process between sweeps otherwise, and
    the pool's workers wait: 35 s of the comparison figures' ``make figures``
    left a core idle. With ``workers`` > 0, renderers go to that many render
    processes, several recipes at once, and the artefact lists are written in
    submission order as they finish; a renderer that cannot be pickled (a
    local function) renders inline.
    """

    def __init__(self, workers: int, cache: Path, judged: bool = True,
                 snapshots: int | None = None) -> None:
        self.cache, self.judged, self.snapshots = cache, judged, snapshots
        self.pool: ProcessPoolExecutor | None = None
        if workers:  # the sweeps' fork server: started here, so with their preload
            ctx = forkserver_context(worker_preload())
            self.pool = ProcessPoolExecutor(max_workers=workers, mp_context=ctx,
                                            initializer=init_worker, initargs=(None,))
        self.pending: list[tuple[Recipe, Path, str, Future[_Rendered]]] = []
        #: Recipe -> the runs whose logs its render read -> the fields read (recipes with a
        #: sweep).
        self.reads: dict[str, dict[str, set[str]]] = {}
        #: Recipes whose render wanted a compacted log, to render again.
        self.redo: list[tuple[Recipe, Path]] = []

    def __enter__(self) -> _Renderer:
        return self

    def submit(self, r: Recipe, source: Path, dest: Path, done: str) -> None:
        """Render ``r`` from ``source`` (store root, or scenario root without a sweep).

        ``done`` (what the sweep did) starts the recipe's progress line.
        """
        args = (r.render, source, r.sweep is not None, dest, self.snapshots)
        fut: Future[_Rendered] = Future()
        if self.pool is not None and _picklable(r.render):
            with deferred():  # the first submit starts the render process
                fut = self.pool.submit(_render, *args)
        else:  # inline: a compacted log goes to _collect as from a render process
            from dfcoa_opt.bench.results.logs import LogCompacted

            try:
                fut.set_result(_render(*args))
            except LogCompacted as exc:
                fut.set_exception(exc)
        self.pending.append((r, dest, done, fut))
        with deferred():  # takes the futures' locks, which the pool's manager thread needs
            self._collect(block=False)

    def render_now(self, r: Recipe, source: Path, dest: Path, done: str) -> None:
        """Render ``r`` in this process and write its artefact list at once."""
        fut: Future[_Rendered] = Future()
        fut.set_result(_render(r.render, source, True, dest, self.snapshots))
        self.pending.append((r, dest, done, fut))
        self._collect(block=True)

    def finish(self) -> None:
        """Wait for every render and write their artefact lists."""
        self._collect(block=True)

    def _collect(self, block: bool) -> None:
        """Write the artefact lists of finished renders, in submission order."""
        from dfcoa_opt.bench.results.logs import LogCompacted

        while self.pending and (block or self.pending[0][3].done()):
            r, dest, done, fut = self.pending.pop(0)
            try:
                arts, seconds, keys = fut.result()
            except LogCompacted as exc:
                print(f"{r.name}: {exc}; rendering again after its sweep", file=sys.stderr)
                self.redo.append((r, dest))
                continue
            if r.sweep is not None:
                self.reads[r.name] = keys
            atomic_write(dest / "artefacts.json", json.dumps(
                {"recipe": r.name, "title": r.title, "sweep": r.sweep,
                 "artefacts": [asdict(a) for a in arts]}, indent=1) + "\n")
            stale = remove_stale(dest, arts)
            cost = record_cost(r, self.cache, seconds)
            print(f"{r.name}: {done}; {len(arts)} artefacts rendered in {seconds:.1f} s"
                  + (f", {stale} stale file(s) removed" if stale else "")
                  + f"; {cost_text(r, cost, self.judged)}", file=sys.stderr)

    def __exit__(self, *exc: object) -> None:
        try:
            if exc[0] is None:
                self._collect(block=True)
        except BaseException:
            if self.pool is not None:
                terminate(self.pool)
            raise
        if self.pool is not None:
            if exc[0] is None:
                self.pool.shutdown(cancel_futures=True)
            else:  # an error or an interrupt: do not wait for the render in progress
                terminate(self.pool)


#: Each recipe's cost, in its cache folder (read by ``make bench``).
COST_FILE = "cost.json"


def record_cost(r: Recipe, cache: Path, render_seconds: float) -> float:
    """Write ``<cache>/<recipe>/cost.json`` and return the recipe's cost, CPU-s.

    The cost is what the recipe's budget bounds (:mod:`dfcoa_opt.bench.recipes`): its
    runs' simulation time (:meth:`~dfcoa_opt.bench.results.store.ResultsStore.simulation_cpu`,
    cached runs counted at what they took) plus ``render_seconds``, its rendering's wall
    time.
    """
    from dfcoa_opt.bench.results.store import ResultsStore

    folder = cache / r.name
    simulation = ResultsStore(folder).simulation_cpu() if r.sweep is not None else 0.0
    cost = simulation + render_seconds
    folder.mkdir(parents=True, exist_ok=True)
    atomic_write(folder / COST_FILE, json.dumps(
        {"recipe": r.name, "simulation_cpu_s": simulation, "render_s": render_seconds,
         "cost_cpu_s": cost, "budget_cpu_s": r.budget}, indent=1) + "\n")
    return cost


def cost_text(r: Recipe, cost: float, judged: bool = True) -> str:
    """``"cost 765 CPU-s of a 1000 budget"``, with ``OVER BUDGET`` when it is over.

    ``judged`` False (a run reduced by ``seeds`` or ``overrides``): the cost alone, as
    the budget bounds the recipe's own configuration.
    """
    if not judged:
        return f"cost {cost:.0f} CPU-s (reduced run: no budget applies)"
    if r.budget is None:
        return f"cost {cost:.0f} CPU-s (no budget)"
    over = " OVER BUDGET" if cost > r.budget else ""
    return f"cost {cost:.0f} CPU-s of a {r.budget:g} budget{over}"


def remove_stale(dest: Path, arts: Sequence[Artefact]) -> int:
    """Delete the files of a recipe's folder that its latest render did not write.

    A recipe folder holds generated files only (its ``artefacts.json`` lists
    them); a file left by an earlier version of the recipe (an older figure
    name, a dropped table) would otherwise stay in ``paper_figures/`` looking
    current. Returns how many files were removed.
    """
    keep = {"artefacts.json", *(a.path for a in arts)}
    stale = [p for p in dest.rglob("*")
             if p.is_file() and p.relative_to(dest).as_posix() not in keep]
    for p in stale:
        p.unlink()
    return len(stale)


def _picklable(obj: object) -> bool:
    try:
        pickle.dumps(obj)
    except Exception:  # noqa: BLE001 - any pickling failure means: render inline
        return False
    return True


def write_index(out: Path, order: Sequence[str]) -> Path:
    """``README.md`` listing every rendered recipe's artefacts and paper counterparts."""
    lines = ["# Generated tables and figures", "",
             "Everything in this folder is written by `make figures` (`dfcoa figures`); "
             "nothing here is edited by hand. Paper tables list the paper's value beside ours. "
             "Each folder is one figure recipe (`dfcoa_opt/bench/recipes/`): a sweep file under "
             "`scenarios/sweeps/` and a renderer that reads only the saved results.", ""]
    for name in order:
        meta = out / name / "artefacts.json"
        if not meta.is_file():
            continue
        info = json.loads(meta.read_text(encoding="utf-8"))
        source = (f"sweep `scenarios/{info['sweep']}`" if info["sweep"]
                  else "no sweep (computed directly, nothing simulated)")
        lines += [f"## {info['title']}", "", f"Recipe `{name}`, {source}.",
                  "", "| file | paper counterpart | what |", "|---|---|---|"]
        lines += [f"| [`{name}/{a['path']}`]({name}/{a['path']}) | {a['paper']} | {a['what']} |"
                  for a in info["artefacts"]]
        lines.append("")
    return atomic_write(out / "README.md", "\n".join(lines))
