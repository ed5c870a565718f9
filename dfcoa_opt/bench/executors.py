"""Executors: run :func:`~dfcoa_opt.bench.runner.execute` over many runs.

Three kinds, all yielding :class:`~dfcoa_opt.bench.runner.Outcome` objects as
runs finish (in completion order; the store does not care about order):

- ``serial``: in this process, in order;
- ``process``: a local process pool (``concurrent.futures``), the default;
- ``dask``: a Dask distributed cluster, given by its scheduler address or
  started locally (``LocalCluster``) -- needs the ``dask`` extra.

Workers only compute; the caller's process writes every file, so no two
processes ever write the same file and a remote cluster needs no shared disk
(the log comes back as bytes).
"""

from __future__ import annotations

import itertools
import os
from collections.abc import Iterable, Iterator, Sequence
from concurrent.futures import Future, ProcessPoolExecutor
from dataclasses import dataclass
from queue import SimpleQueue

from dfcoa_opt.bench.lifecycle import deferred, forkserver_context, init_worker, terminate
from dfcoa_opt.bench.runner import Outcome, execute
from dfcoa_opt.bench.sweep import RunSpec
from dfcoa_opt.control.registry import BUILTIN_MODULES
from dfcoa_opt.errors import DfcoaError

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


def run_all(runs: Sequence[RunSpec], config: ExecutorConfig) -> Iterator[Outcome]:
    """Execute ``runs``; yields each outcome as it finishes."""
    if not runs:
        return
    if config.kind == "serial" or (config.kind == "process" and config.jobs == 1):
        for run in runs:
            yield execute(run)
    elif config.kind == "process":
        yield from _processes(runs, config.jobs or os.cpu_count() or 1)
    else:
        yield from _dask(runs, config)


def _processes(runs: Sequence[RunSpec], jobs: int) -> Iterator[Outcome]:
    """At most ``2 * jobs`` runs in flight, so finished logs never pile up in memory.

    Workers start from a fork server, not by forking this process: once this
    process has run a parallel numba kernel, GNU OpenMP's threads are up and a
    forked child dies ("fork() called from a process already using GNU
    OpenMP"); ``make figures`` runs such kernels between sweeps. The server
    starts with SIGINT blocked (:func:`~dfcoa_opt.bench.lifecycle.forkserver_context`)
    and each worker runs :func:`~dfcoa_opt.bench.lifecycle.init_worker` (one
    numba thread, SIGINT ignored, exit with the main process). An interrupt or
    an abandoned generator terminates the workers at once instead of waiting
    for their runs.
    """
    queue = iter(runs)
    ctx = forkserver_context(WORKER_PRELOAD)
    pool = ProcessPoolExecutor(max_workers=min(jobs, len(runs)), mp_context=ctx,
                               initializer=init_worker)
    finished: SimpleQueue[Future[Outcome]] = SimpleQueue()
    try:
        with deferred():
            in_flight = _submit(pool, itertools.islice(queue, 2 * jobs), finished)
        while in_flight:
            fut = finished.get()  # waits in C and holds no lock when interrupted
            with deferred():
                outcome = fut.result()
                in_flight += _submit(pool, itertools.islice(queue, 1), finished) - 1
            yield outcome
    except BaseException:  # an interrupt, or the consumer stopped: stop the workers now
        terminate(pool)
        raise
    pool.shutdown(wait=True)


def _submit(pool: ProcessPoolExecutor, runs: Iterable[RunSpec],
            finished: SimpleQueue[Future[Outcome]]) -> int:
    """Submit ``runs``; each future goes into ``finished`` when done. Returns how many.

    Call it inside :func:`~dfcoa_opt.bench.lifecycle.deferred`, like every step
    of :func:`_processes` that takes a lock of the pool or of a future (and a
    submit may start a worker): SIGINT and SIGTERM raise an exception where
    they land. The only wait outside such a block is ``SimpleQueue.get``,
    which holds no lock when interrupted.
    """
    n = 0
    for run in runs:
        pool.submit(execute, run).add_done_callback(finished.put)
        n += 1
    return n


#: Imported once by the fork server (when it starts), so that every pool worker
#: forks with them loaded instead of importing them itself: about 1.2 s saved per
#: worker and pool (``make figures`` starts a pool per recipe). Importing runs no
#: numba kernel, so no OpenMP thread exists yet when the server forks.
WORKER_PRELOAD = ("dfcoa_opt.bench.runner", "dfcoa_opt.sim.simulator", "dfcoa_opt.metrics",
                  "dfcoa_opt.localization.mcl", *BUILTIN_MODULES)


def _dask(runs: Sequence[RunSpec], config: ExecutorConfig) -> Iterator[Outcome]:
    try:
        from distributed import Client, LocalCluster
        from distributed import as_completed as dask_completed
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
            done = dask_completed([client.submit(execute, r, key=f"run-{r.key}", pure=False)
                                   for r in runs])
            for fut in done:
                outcome = fut.result()
                fut.release()  # the cluster may forget the finished log
                yield outcome
    finally:
        if cluster is not None:
            cluster.close()
