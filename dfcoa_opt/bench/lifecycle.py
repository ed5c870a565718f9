"""Stopping a sweep cleanly: interrupts in the main process, orphan-proof workers.

Main process: :func:`interruptible` turns SIGINT and SIGTERM into
:class:`Interrupted` (a ``BaseException``, so no ``except Exception`` swallows
it); the executors stop dispatching and terminate their workers, and the
harness reports what was saved (:class:`SweepInterrupted`). The CLI prints one
line and exits with ``128 + signal`` (130 for SIGINT, 143 for SIGTERM).

Workers (:func:`init_worker`, the initializer of every process pool): they
ignore SIGINT (Ctrl-C reaches the whole process group; the main process stops
them, and they print no traceback), and a daemon thread waits on the main
process's sentinel -- a pipe that only the main process holds open -- and ends
the worker when it closes, i.e. when the main process died, even by SIGKILL.

Why the thread is needed: a pool worker blocks reading its call queue, whose
write end it holds itself, so it never sees the main process go. And the fork
server exits when its "alive" pipe reaches end of file, but the main process
hands the write end of that pipe to every process the server forks (CPython
does so on purpose, so that those processes could use the server too), so the
server lives as long as any worker does. Measured before: after a SIGKILL of
``dfcoa bench``, the fork server and both workers stayed alive indefinitely.
With the watchdog, the workers exit at once, and with them the fork server and
the resource tracker.

The fork server is started by :func:`forkserver_context` with SIGINT
blocked, a mask it keeps for life and that the workers inherit: without it, a
Ctrl-C during the server's second of preloading imports printed a
``KeyboardInterrupt`` traceback from it.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import multiprocessing.forkserver
import multiprocessing.resource_tracker
import os
import signal
import sys
import threading
from collections.abc import Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import spawn
from multiprocessing.connection import wait
from multiprocessing.context import ForkServerContext, ForkServerProcess
from pathlib import Path
from types import FrameType
from typing import Any


class Interrupted(BaseException):
    """SIGINT or SIGTERM arrived in the main process.

    Attributes:
        signum: The signal number.
    """

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


class SweepInterrupted(BaseException):
    """A sweep stopped on a signal, with every finished run saved.

    Attributes:
        saved: Runs of the sweep with a row.
        total: Runs of the sweep.
        root: The results folder.
        signum: The signal number.
    """

    def __init__(self, saved: int, total: int, root: Path, signum: int) -> None:
        super().__init__(f"interrupted: {saved} of {total} runs saved in {root}; run the same "
                         "command to resume")
        self.saved, self.total, self.root, self.signum = saved, total, root, signum

    @property
    def exit_code(self) -> int:
        """``128 + signal``: 130 for SIGINT, 143 for SIGTERM."""
        return 128 + self.signum


def _raise(signum: int, _frame: FrameType | None) -> None:
    raise Interrupted(signum)


@contextlib.contextmanager
def interruptible() -> Iterator[None]:
    """SIGINT and SIGTERM raise :class:`Interrupted` inside the block (main thread only)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = {s: signal.signal(s, _raise) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, handler in old.items():
            signal.signal(s, handler)


@contextlib.contextmanager
def deferred() -> Iterator[None]:
    """SIGINT and SIGTERM wait for the end of the block, then act (main thread only).

    For short steps that must not be cut in two, as :class:`Interrupted`
    raised where the signal lands would:

    - taking and releasing a lock that another thread needs (a pool's or a
      future's, which the pool's manager thread takes too: left held, the
      shutdown waits for that thread for ever);
    - starting a pool worker: the fork server forks it only after the request
      (a second or more while the server still imports its preload), and a
      main process that stopped in between left a worker that found its
      pool's semaphores gone and printed a ``FileNotFoundError`` traceback.

    A signal caught here is raised again when the block ends, with the
    handlers in place before it.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []

    def catch(signum: int, _frame: FrameType | None) -> None:
        caught.append(signum)

    old = {s: signal.signal(s, catch) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, handler in old.items():
            signal.signal(s, handler)
        for s in dict.fromkeys(caught):
            signal.raise_signal(s)


def _exit_with_parent() -> None:
    """Block until the main process's sentinel closes, then end this process."""
    parent = multiprocessing.parent_process()
    if parent is None:
        return
    wait([parent.sentinel])
    os._exit(1)


def init_worker(numba_threads: int | None = 1) -> None:
    """Pool-worker initializer: ignore SIGINT, die with the main process, one numba thread.

    Args:
        numba_threads: numba threads of the worker (None: leave numba alone).
            Sweep workers run one each: the runs already fill the cores, and with
            one OpenMP thread per core in every worker, 2 workers on 2 cores made
            runs with parallel kernels 3-4x slower.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    threading.Thread(target=_exit_with_parent, name="exit-with-parent", daemon=True).start()
    if numba_threads is not None:
        import numba

        numba.set_num_threads(numba_threads)


_MAIN_KEYS = ("init_main_from_path", "init_main_from_name")
_LAUNCH = threading.Lock()


class _WorkerProcess(ForkServerProcess):
    """A forkserver process that does not import the caller's ``__main__``.

    multiprocessing runs the main script (or ``-m`` module) again in every new
    process, so that functions defined there can be unpickled; a script that
    calls :func:`dfcoa_opt.sweep` at its top level, with no
    ``if __name__ == "__main__":`` guard, then ran its sweep again in every
    worker, which failed with ``BrokenProcessPool``. Workers need nothing of
    ``__main__``: they build controllers from the registry's modules, entry
    points and plugin files, and a sweep whose controller was registered in the
    caller only runs in the caller (:func:`dfcoa_opt.api.sweep`).
    """

    @staticmethod
    def _Popen(process_obj: ForkServerProcess) -> Any:  # noqa: N802 - multiprocessing's name
        prepare = spawn.get_preparation_data
        with _LAUNCH:  # the start reads the function by name: swap it for this start only
            spawn.get_preparation_data = lambda name: {  # type: ignore[assignment]
                k: v for k, v in prepare(name).items() if k not in _MAIN_KEYS}
            try:
                return ForkServerProcess._Popen(process_obj)
            finally:
                spawn.get_preparation_data = prepare  # type: ignore[assignment]


class _WorkerContext(ForkServerContext):
    """The forkserver context whose processes skip ``__main__`` (:class:`_WorkerProcess`)."""

    Process = _WorkerProcess  # type: ignore[assignment]


_CONTEXT = _WorkerContext()


def forkserver_context(preload: Sequence[str]) -> ForkServerContext:
    """The ``forkserver`` context, with its server running (started once per process).

    Its processes do not run the caller's main script again (:class:`_WorkerProcess`).

    The server is spawned with SIGINT blocked in the calling thread: a blocked
    signal stays blocked across ``fork`` and ``exec``, so a Ctrl-C can no
    longer interrupt the server's preloading imports (about a second, during
    which it printed a ``KeyboardInterrupt`` traceback), nor a worker before
    :func:`init_worker` runs. (The resource tracker gets the same protection
    from CPython itself.) A SIGINT or SIGTERM that reaches this process
    meanwhile acts once both are started (:func:`deferred`).

    Args:
        preload: Modules the server imports when it starts (ignored when it
            already runs).

    Returns:
        The context for ``ProcessPoolExecutor(mp_context=...)``.
    """
    _quiet_resource_tracker()
    ctx = _CONTEXT
    ctx.set_forkserver_preload(list(preload))
    with deferred():
        # The tracker first: starting it unblocks SIGINT (it blocks SIGINT and SIGTERM
        # while it spawns the tracker, which ignores both, then unblocks them).
        multiprocessing.resource_tracker.ensure_running()
        mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            multiprocessing.forkserver.ensure_running()
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)
    return ctx


def _quiet_resource_tracker() -> None:
    """Keep the resource tracker's leaked-semaphore warning off stderr after an interrupt.

    Terminated workers leave the pool's queue semaphores to multiprocessing's
    resource tracker, which unlinks them -- its job -- but also warns about each
    on stderr, under the one line an interrupt prints. The tracker is a separate
    process started with this interpreter's ``-W`` options, so the filter goes
    into ``sys.warnoptions`` before the first pool starts it.
    """
    option = "ignore:resource_tracker:UserWarning"
    if option not in sys.warnoptions:
        sys.warnoptions.append(option)


def terminate(pool: ProcessPoolExecutor) -> None:
    """Terminate the worker processes of a ``ProcessPoolExecutor`` and shut it down.

    Running tasks are abandoned (a run can take minutes); pending ones are
    cancelled. ``concurrent.futures`` has no public way to stop a running task,
    so the processes are taken from the executor's ``_processes`` table.

    A worker killed while it sends its result (a run's log: often more than a
    pipe holds) leaves half a message in the result pipe, and the pool's
    manager thread, which ``shutdown`` joins, waits for the rest for ever: this
    process holds the pipe's write end too, so no end of file comes. It is
    closed here (only workers write to it), so the thread gets end of file as
    soon as the workers are gone, and finds the pool broken. Without it, one
    interrupted sweep in about 60 hung.
    """
    for proc in list((pool._processes or {}).values()):
        with contextlib.suppress(OSError, ValueError):
            proc.terminate()
    results = pool._result_queue
    if results is not None:
        results._writer.close()
    pool.shutdown(wait=True, cancel_futures=True)
