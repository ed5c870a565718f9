"""Test-session settings: hypothesis profiles.

``make test`` uses ``repro``: every hypothesis test is derandomized (its examples
are a function of the test alone) and keeps no example database, so a run gives
the same verdict on every machine. ``DFCOA_HYPOTHESIS=explore make test`` searches
fresh random inputs on every run and replays earlier failures from
``.hypothesis/``; use it to hunt for new bugs, then pin what it finds as a test.
"""

from __future__ import annotations

import dfcoa_opt  # noqa: F401 - first: caps numpy's SIMD dispatch before numpy loads

# isort: split
import os

import numba
import pytest
from hypothesis import settings

settings.register_profile("repro", derandomize=True, database=None)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("DFCOA_HYPOTHESIS", "repro"))


@pytest.fixture(autouse=True, scope="session")
def _one_numba_thread_per_xdist_worker():
    """Under ``pytest -n`` (``make test``), each worker runs numba on one thread.

    The workers already use every core; a parallel region of a second thread then
    waits for a descheduled core, every call (measured 2026-11-25 on four test
    modules: 31 s with two threads per worker against 13 s with one). The sweep
    workers of ``make figures`` run the same way. Rows of every ``prange`` kernel
    are independent, so results agree; ``tests/test_parallel_kernels.py`` checks
    that with every thread (fixture ``all_numba_threads``).
    """
    if os.environ.get("PYTEST_XDIST_WORKER"):
        numba.set_num_threads(1)
    yield


@pytest.fixture
def all_numba_threads(monkeypatch) -> int:
    """Every thread numba has (``NUMBA_NUM_THREADS``); skips the test when that is one.

    The kernels then get every thread they are given, whatever their size and the
    machine's load (``dfcoa_opt.core.runtime.threads`` would otherwise keep small calls on one).
    """
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("numba has one thread here: no thread count to compare")
    from dfcoa_opt.core.runtime import threads

    monkeypatch.setattr(threads, "PARALLEL_MIN_ROWS", 0)
    monkeypatch.setattr(threads, "free_cores", lambda: numba.config.NUMBA_NUM_THREADS)
    return numba.config.NUMBA_NUM_THREADS


@pytest.fixture(scope="module")
def one_numba_thread():
    """Run the numba ``prange`` kernels on one thread in this module (restored after).

    For tiny examples (property tests: <= 12 robots): on a loaded 2-core machine every parallel
    region waits for a descheduled thread: measured 3 s with one thread against 24-84 s
    with two for the same 150 crowd examples. Rows are independent, so results agree.
    """
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    yield
    numba.set_num_threads(before)


@pytest.fixture(autouse=True, scope="module")
def _plugins_leave_with_their_module():
    """Ids a test module registers (plugins, test doubles) are unregistered after it.

    A sweep's ``controllers = ["*"]`` expands to every registered id, so a plugin
    that one module's ``dfcoa compare`` loaded would add runs to another module's
    sweeps (``tests/test_sweep_atomic.py`` checks the shipped sweeps' run keys),
    depending on which modules share a worker. Built-in ids (entry points) stay.
    """
    from dfcoa_opt.core import registry

    tables = [r for r in vars(registry).values() if isinstance(r, registry.Registry)]
    before = [set(r._table) for r in tables]
    yield
    for r, kept in zip(tables, before, strict=True):
        declared = {ep.name for ep in r.entry_points()}
        for name in set(r._table) - kept - declared:
            del r._table[name]
