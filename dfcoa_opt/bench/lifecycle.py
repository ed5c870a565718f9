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
write end it holds itself, so it never sees the main process go; and every
process forked by the multiprocessing fork server holds the server's "alive"
pipe, so the server, which exits when that pipe closes, lives as long as any
worker. Measured before: after a SIGKILL of ``dfcoa bench``, the fork server
and both workers stayed alive indefinitely. With the watchdog, the workers
exit at once, and with them the fork server and the resource tracker.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import signal
import sys
import threading
from collections.abc import Iterator
from multiprocessing.connection import wait
from pathlib import Path
from types import FrameType


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


def quiet_resource_tracker() -> None:
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


def terminate(pool: object) -> None:
    """Terminate the worker processes of a ``ProcessPoolExecutor`` and shut it down.

    Running tasks are abandoned (a run can take minutes); pending ones are
    cancelled. ``concurrent.futures`` has no public way to stop a running task,
    so the processes are taken from the executor's ``_processes`` table.
    """
    for proc in list((getattr(pool, "_processes", None) or {}).values()):
        with contextlib.suppress(OSError, ValueError):
            proc.terminate()
    pool.shutdown(wait=True, cancel_futures=True)  # type: ignore[attr-defined]
