"""Test-session settings: hypothesis profiles.

``make test`` uses ``repro``: every hypothesis test is derandomized (its examples
are a function of the test alone) and keeps no example database, so a run gives
the same verdict on every machine. ``DFCOA_HYPOTHESIS=explore make test`` searches
fresh random inputs on every run and replays earlier failures from
``.hypothesis/``; use it to hunt for new bugs, then pin what it finds as a test.
"""

from __future__ import annotations

import os

import numba
import pytest
from hypothesis import settings

settings.register_profile("repro", derandomize=True, database=None)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("DFCOA_HYPOTHESIS", "repro"))


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
