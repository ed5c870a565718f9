"""Test-session settings: hypothesis profiles.

``make test`` uses ``repro``: every hypothesis test is derandomized (its examples
are a function of the test alone) and keeps no example database, so a run gives
the same verdict on every machine. ``DFCOA_HYPOTHESIS=explore make test`` searches
fresh random inputs on every run and replays earlier failures from
``.hypothesis/``; use it to hunt for new bugs, then pin what it finds as a test.
"""

from __future__ import annotations

import os

from hypothesis import settings

settings.register_profile("repro", derandomize=True, database=None)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("DFCOA_HYPOTHESIS", "repro"))
