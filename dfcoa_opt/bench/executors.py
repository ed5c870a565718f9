"""Executors: run the runs of a sweep, batched, and yield their rows as the runs end.

Runs that differ only in their seed (the same scenario file, overrides and
controller) are grouped into batches (:func:`batches`) and each batch is
simulated as one (:func:`~dfcoa_opt.bench.runner.execute_batch`), with the same
rows as one run at a time. Three kinds, all yielding
:class:`~dfcoa_opt.bench.runner.Outcome` objects as runs finish (in completion
order; the store does not care about order):

- ``serial``: in this process, batch after batch;
- ``process``: a local process pool (``concurrent.futures``), the default; each
  worker sends a run's row back as soon as the run ends;
- ``dask``: a Dask distributed cluster, given by its scheduler address or
  started locally (``LocalCluster``) -- needs the ``dask`` extra; each run's
  row comes back when the run ends too (through a Dask ``Queue``).

Workers only compute; the caller's process writes every file, so no two
processes ever write the same file and a remote cluster needs no shared disk
(the log comes back as bytes).
"""

from __future__ import annotations

import contextlib
import itertools
import math
import os
import threading
from collections.abc import Iterable, Iterator, Sequence
from concurrent.futures import Future, ProcessPoolExecutor
from dataclasses import dataclass
from queue import SimpleQueue
from typing import Any

from dfcoa_opt.bench.lifecycle import deferred, forkserver_context, init_worker, terminate
from dfcoa_opt.bench.runner import Outcome, execute_batch
from dfcoa_opt.bench.sweep.specs import RunSpec
from dfcoa_opt.core.errors import DfcoaError
from dfcoa_opt.core.plugins import load_plugins
from dfcoa_opt.core.plugins import loaded as loaded_plugins
from dfcoa_opt.core.registry import CONTROLLERS, ESTIMATORS, FILTERS

EXECUTORS = ("serial", "process", "dask")


@dataclass(frozen=True)
class ExecutorConfig:
    """How to run a sweep.

    Attributes:
        kind: ``serial``, ``process`` or ``dask``.
        jobs: Worker processes for ``process`` (default: the core count).
        scheduler: Dask scheduler address, e.g. ``tcp://host:8786``.
        dask_local: Start a local Dask cluster with this many worker processes.
    """

    kind: str = "process"
    jobs: int | None = None
    scheduler: str | None = None
    dask_local: int | None = None

    def __post_init__(self) -> None:
        if self.kind not in EXECUTORS:
            raise DfcoaError(f"executor '{self.kind}' unknown; choose {', '.join(EXECUTORS)}")
        if self.jobs is not None and self.jobs < 1:
            raise DfcoaError(f"--jobs: must be >= 1, got {self.jobs}")
        if self.kind == "dask" and (self.scheduler is None) == (self.dask_local is None):
            raise DfcoaError("the dask executor needs exactly one of --scheduler ADDR and "
                             "--dask-local N")
        if self.dask_local is not None and self.dask_local < 1:
            raise DfcoaError(f"--dask-local: must be >= 1, got {self.dask_local}")


#: Most runs in one batch, and most robot rows (runs x robots): a batch's logs are
#: held until its runs end (20 runs of 100 robots: about 250 MB).
BATCH_RUNS = 20
BATCH_ROWS = 2000


def batches(runs: Sequence[RunSpec], jobs: int = 1) -> list[list[RunSpec]]:
    """Group runs that differ only in their seed into batches, the most work first.

    A group is cut into batches of at most :data:`BATCH_RUNS` runs and
    :data:`BATCH_ROWS` robot rows, and smaller ones when there are too few runs
    to give every worker two batches. The batches are ordered by their work,
    runs x robots x steps (``t_max / dt``), largest first, and in the runs'
    order where that is equal: workers that take them in this order end
    close together (longest processing time first). The comparison recipe's
    batch of ``nmpc`` on ``large_100`` (100 robots) is a third of its
    simulation; started last, one worker ran it alone for about 25 s on 2 cores.

    Args:
        runs: The runs to execute.
        jobs: Workers that will share the batches.
    """
    groups: dict[tuple[str, str, str], list[RunSpec]] = {}
    for r in runs:
        groups.setdefault((r.scenario_file, r.overrides, r.controller), []).append(r)
    size = max(1, min(BATCH_RUNS, math.ceil(len(runs) / (2 * jobs))))
    out: list[tuple[float, list[RunSpec]]] = []
    for group in groups.values():
        n, steps = _size(group[0])
        step = max(1, min(size, BATCH_ROWS // max(n, 1)))
        out += [(len(b) * n * steps, b) for b in
                (group[i:i + step] for i in range(0, len(group), step))]
    return [b for _, b in sorted(out, key=lambda item: -item[0])]


def _size(run: RunSpec) -> tuple[int, float]:
    """A run's team size and steps (``t_max / dt``), from its file and overrides.

    What cannot be read counts as one robot and one step (the run itself reports it).
    """
    from dfcoa_opt.scenario.overrides import read_toml
    from dfcoa_opt.scenario.schema import ScenarioSpec

    try:
        data = read_toml(run.scenario_file)
        over = run.overrides_dict
        n = int(over.get("team.n", data.get("team", {}).get("n", 1)))
        dt = float(over.get("dt", data.get("dt", ScenarioSpec.dt)))
        steps = float(over.get("t_max", data.get("t_max", ScenarioSpec.t_max))) / dt
    except Exception:  # noqa: BLE001 - the run itself reports a bad file
        return 1, 1.0
    return max(n, 1), max(steps, 1.0)


def run_all(runs: Sequence[RunSpec], config: ExecutorConfig) -> Iterator[Outcome]:
    """Execute ``runs`` in batches; yields each outcome as its run ends."""
    if not runs:
        return
    if config.kind == "serial" or (config.kind == "process" and config.jobs == 1):
        for batch in batches(runs):
            yield from execute_batch(batch)
    elif config.kind == "process":
        jobs = config.jobs or os.cpu_count() or 1
        yield from _processes(batches(runs, jobs), jobs)
    else:
        yield from _dask(runs, config)


class WorkerPool:
    """Worker processes that execute batches and stream each run's outcome back.

    Workers start from a fork server, not by forking this process: once this
    process has run a parallel numba kernel, GNU OpenMP's threads are up and a
    forked child dies ("fork() called from a process already using GNU
    OpenMP"); ``make figures`` runs such kernels between sweeps. The server
    starts with SIGINT blocked (:func:`~dfcoa_opt.bench.lifecycle.forkserver_context`)
    and each worker runs :func:`~dfcoa_opt.bench.lifecycle.init_worker` (one
    numba thread, SIGINT ignored, exit with the main process).

    Each worker puts a run's outcome on a pipe as soon as the run ends; a
    thread of this process moves them to ``finished``, where the futures of
    the batches also arrive when a batch is done (its result: how many
    outcomes it sent), so a batch counts as finished once both are in.

    Args:
        jobs: Worker processes.
    """

    def __init__(self, jobs: int) -> None:
        self.jobs = jobs
        ctx = forkserver_context(worker_preload())
        self.results = ctx.SimpleQueue()
        self.pool = ProcessPoolExecutor(max_workers=jobs, mp_context=ctx,
                                        initializer=_init_batch_worker, initargs=(self.results,))
        self.finished: SimpleQueue[Any] = SimpleQueue()
        threading.Thread(target=_forward, args=(self.results, self.finished), name="outcomes",
                         daemon=True).start()

    def run(self, work: Sequence[Sequence[RunSpec]]) -> Iterator[Outcome]:
        """Execute the batches, at most ``2 * jobs`` in flight (finished logs never pile up).

        An interrupt or an abandoned generator terminates the workers at once
        instead of waiting for their runs.
        """
        queue = iter(enumerate(work))
        sent: dict[int, int] = {}
        got: dict[int, int] = {}
        try:
            with deferred():
                in_flight = _submit(self.pool, itertools.islice(queue, 2 * self.jobs),
                                    self.finished)
            while in_flight:
                item = self.finished.get()  # waits in C and holds no lock when interrupted
                with deferred():
                    if isinstance(item, Future):
                        b = item.batch  # type: ignore[attr-defined]
                        sent[b] = item.result()
                    else:
                        b, outcome = item
                        got[b] = got.get(b, 0) + 1
                    if sent.get(b) == got.get(b, 0):
                        in_flight += _submit(self.pool, itertools.islice(queue, 1),
                                             self.finished) - 1
                if not isinstance(item, Future):
                    yield outcome
        except BaseException:  # an interrupt, or the consumer stopped: stop the workers now
            self.terminate()
            raise

    def terminate(self) -> None:
        """Stop the workers at once (their runs in progress are abandoned)."""
        terminate(self.pool)
        self.results._writer.close()  # type: ignore[attr-defined]  # the thread gets EOF

    def close(self) -> None:
        """Let the workers finish and exit."""
        self.pool.shutdown(wait=True)
        self.results.put(None)  # ends the thread


#: Pools kept for the sweeps of a :func:`kept_workers` block, by worker count.
_KEPT: dict[int, WorkerPool] = {}


@contextlib.contextmanager
def kept_workers(config: ExecutorConfig) -> Iterator[None]:
    """One process pool for every sweep of the block (with the process executor).

    ``dfcoa tune`` runs one short sweep per trial; starting workers for each
    (their imports, numba caches and compiled solvers) took seconds a trial.
    Other executors are unchanged.
    """
    jobs = config.jobs or os.cpu_count() or 1
    if config.kind != "process" or jobs == 1 or jobs in _KEPT:
        yield
        return
    pool = _KEPT[jobs] = WorkerPool(jobs)
    try:
        yield
    except BaseException:
        _KEPT.pop(jobs, None)
        pool.terminate()
        raise
    _KEPT.pop(jobs, None)
    pool.close()


def _processes(work: Sequence[Sequence[RunSpec]], jobs: int) -> Iterator[Outcome]:
    """The batches on worker processes: the kept pool's, or a pool of their own."""
    kept = _KEPT.get(jobs)
    if kept is not None:
        yield from kept.run(work)
        return
    pool = WorkerPool(min(jobs, len(work)))
    yield from pool.run(work)  # (it terminates its workers when interrupted)
    pool.close()


_RESULTS: Any = None


def _init_batch_worker(results: Any) -> None:
    """Pool-worker initializer: :func:`~dfcoa_opt.bench.lifecycle.init_worker`, and the pipe."""
    global _RESULTS
    init_worker()
    _RESULTS = results


def _execute_streaming(batch: int, runs: Sequence[RunSpec], plugins: Sequence[str]) -> int:
    """In a worker: execute one batch, sending ``(batch, outcome)`` as each run ends.

    ``plugins``: the caller's loaded plugins (:mod:`dfcoa_opt.core.plugins`),
    imported first (once per worker).
    """
    load_plugins(plugins)
    n = 0
    for outcome in execute_batch(runs):
        _RESULTS.put((batch, outcome))
        n += 1
    return n


def _forward(results: Any, finished: SimpleQueue[Any]) -> None:
    """Move the workers' outcomes to ``finished`` until ``None`` or end of file."""
    with contextlib.suppress(EOFError, OSError):
        while (item := results.get()) is not None:
            finished.put(item)


def _submit(pool: ProcessPoolExecutor, work: Iterable[tuple[int, Sequence[RunSpec]]],
            finished: SimpleQueue[Any]) -> int:
    """Submit batches; each future (tagged ``.batch``) goes into ``finished`` when done.

    Call it inside :func:`~dfcoa_opt.bench.lifecycle.deferred`, like every step
    of :func:`_processes` that takes a lock of the pool or of a future (and a
    submit may start a worker): SIGINT and SIGTERM raise an exception where
    they land. The only wait outside such a block is ``SimpleQueue.get``,
    which holds no lock when interrupted.

    Returns:
        How many were submitted.
    """
    n = 0
    for b, runs in work:
        fut = pool.submit(_execute_streaming, b, runs, loaded_plugins())
        fut.batch = b  # type: ignore[attr-defined]
        fut.add_done_callback(finished.put)
        n += 1
    return n


def worker_preload() -> tuple[str, ...]:
    """The modules the fork server imports once, when it starts.

    Every pool worker then forks with them loaded instead of importing them
    itself: about 1.2 s saved per worker and pool (``make figures`` starts a pool
    per recipe). They are the run path and the modules of every installed
    controller, filter and estimator entry point. Importing runs no numba
    kernel, so no OpenMP thread exists yet when the server forks.
    """
    return tuple(dict.fromkeys(("dfcoa_opt.bench.runner", "dfcoa_opt.sim.simulator",
                                "dfcoa_opt.metrics", *CONTROLLERS.modules(),
                                *FILTERS.modules(), *ESTIMATORS.modules())))


def _dask(runs: Sequence[RunSpec], config: ExecutorConfig) -> Iterator[Outcome]:
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise DfcoaError("the dask executor needs the 'dask' extra: "
                         "pip install 'dfcoa-opt[dask]'") from None
    cluster = None
    if config.dask_local is not None:
        cluster = LocalCluster(n_workers=config.dask_local, threads_per_worker=1,
                               processes=True, dashboard_address=None)
    try:
        try:
            client = Client(cluster if cluster is not None else config.scheduler, timeout="10s")
        except (OSError, TimeoutError) as exc:
            raise DfcoaError(f"--scheduler: cannot reach Dask scheduler "
                             f"'{config.scheduler}': {exc}") from None
        with client:
            yield from _dask_stream(client, runs)
    finally:
        if cluster is not None:
            cluster.close()


def _dask_stream(client: Any, runs: Sequence[RunSpec]) -> Iterator[Outcome]:
    """Each run's outcome as it ends, from batches on a Dask cluster.

    A batch's task scatters each outcome on its worker as its run ends and puts
    the future in a Dask ``Queue``; this process takes them in order of arrival.
    A batch that Dask runs again (its worker died) sends its runs again: a run
    already received is skipped. A task that raised raises here.
    """
    import uuid

    from distributed import Queue

    queue = Queue(f"dfcoa-{uuid.uuid4().hex}", client=client)
    workers = sum(client.nthreads().values()) or 1
    tasks = [client.submit(_execute_to_queue, b, queue.name, loaded_plugins(),
                           key=f"batch-{b[0].key}", pure=False) for b in batches(runs, workers)]
    seen: set[str] = set()
    while len(seen) < len(runs):
        try:
            item = queue.get(timeout=1.0)
        except TimeoutError:
            for task in tasks:
                if task.status == "error":
                    task.result()  # raises the task's exception here
            continue
        outcome = item.result()
        item.release()  # the cluster may forget the finished log
        if outcome.row["key"] not in seen:
            seen.add(outcome.row["key"])
            yield outcome
    for task in tasks:
        task.release()


def _execute_to_queue(runs: Sequence[RunSpec], queue: str, plugins: Sequence[str]) -> int:
    """On a Dask worker: execute one batch, putting each outcome (scattered) in ``queue``.

    ``plugins`` are imported first (:func:`_execute_streaming`).
    """
    from distributed import Queue, get_client

    load_plugins(plugins)
    client, out, n = get_client(), Queue(queue), 0
    for outcome in execute_batch(runs):
        out.put(client.scatter(outcome, direct=True))
        n += 1
    return n
