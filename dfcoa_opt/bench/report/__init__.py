"""Reports of saved results: tables, statistics, plots, trajectories, failures, ladders.

:func:`~dfcoa_opt.bench.report.document.make_report` writes ``report.md`` (with
``.csv`` and PNGs) of a results folder from its rows and logs only; it never
simulates. The names of the former module ``dfcoa_opt.bench.report``
(``make_report``, ``load_rows``, ``aggregate``, ...) are read from
:mod:`~dfcoa_opt.bench.report.document` on first use.
"""

from __future__ import annotations

import importlib
from typing import Any


def __getattr__(name: str) -> Any:
    """A name of :mod:`dfcoa_opt.bench.report.document`, imported on first use."""
    document = importlib.import_module(f"{__name__}.document")
    try:
        return getattr(document, name)
    except AttributeError:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
