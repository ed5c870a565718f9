"""How many threads a parallel (``prange``) kernel may use: only where they pay.

The parallel kernels (ORCA's neighbour query, lines and exact 2D solver, the
improved VO's lines, ``lf_vo``'s velocity-obstacle rollouts) give the same
numbers on any thread count (``tests/test_parallel_kernels.py``), so this only
decides speed. Measured on a 2-core AMD EPYC (ORCA crowd step, RVO2's Circle,
median of 30 steps):

- on an idle machine two threads pay from about 100 robots on: 1.2x at 100
  (36 against 44 us), 1.35x at 250, 1.46x at 1000, 1.40x at 10,000;
- with one other busy process on the machine, every parallel region waits for
  a descheduled thread: about 15 ms a step at any size, against 0.03 ms (25
  robots) to 5 ms (10,000) on one thread, so threads lose 3x to 500x.

So a kernel call gets more than one thread only with at least
:data:`PARALLEL_MIN_ROWS` rows (robots, or robots of every run of a batch) and
only as many as the cores the load average leaves free (:func:`free_cores`).
Sweep workers run one thread each anyway (the runs fill the cores).
``DFCOA_PARALLEL_MIN_ROWS`` sets the threshold (0: always, as numba's own
setting allows).
"""

from __future__ import annotations

import contextlib
import math
import os
import time
from collections.abc import Iterator

import numba

#: Rows below which a parallel kernel runs on one thread (``DFCOA_PARALLEL_MIN_ROWS``).
PARALLEL_MIN_ROWS = int(os.environ.get("DFCOA_PARALLEL_MIN_ROWS", "1000"))
#: Seconds a load-average reading is reused.
LOAD_TTL = 1.0
_load: tuple[float, int] = (-math.inf, 0)


def free_cores() -> int:
    """Cores the 1-minute load average leaves to this process (its own thread included).

    ``cpu_count - load + 1`` rounded down, at least 1; read at most once per
    :data:`LOAD_TTL` seconds. Where the load is unknown, every core.
    """
    global _load
    now = time.monotonic()
    if now - _load[0] > LOAD_TTL:
        cores = os.cpu_count() or 1
        try:
            free = int(cores - os.getloadavg()[0] + 1.0)
        except OSError:
            free = cores
        _load = (now, max(1, min(cores, free)))
    return _load[1]


def threads_for(rows: int) -> int:
    """Threads a parallel kernel should use for ``rows`` rows (module docstring)."""
    if rows < PARALLEL_MIN_ROWS:
        return 1
    return max(1, min(numba.get_num_threads(), free_cores()))


@contextlib.contextmanager
def kernel_threads(rows: int) -> Iterator[None]:
    """Run the parallel kernels called inside the block on :func:`threads_for` threads.

    Never raises numba's thread count: inside a sweep worker (one thread) it
    changes nothing.
    """
    have = numba.get_num_threads()
    want = threads_for(rows)
    if want >= have:
        yield
        return
    numba.set_num_threads(want)
    try:
        yield
    finally:
        numba.set_num_threads(have)
