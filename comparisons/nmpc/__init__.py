"""``nmpc``: distributed nonlinear MPC formation controller (beyond the papers).

- :mod:`~comparisons.nmpc.controller`: the controller ``Nmpc`` (registered as
  ``nmpc``); :mod:`~comparisons.nmpc.fallback`: its fallback ``goto_command``;
- :mod:`~comparisons.nmpc.spec`: what one robot's problem is made of (``ProblemSpec``);
- :mod:`~comparisons.nmpc.problem`: the casadi program of one robot;
- :mod:`~comparisons.nmpc.geometry`: slot references, neighbour predictions and
  the distance half-planes;
- :mod:`~comparisons.nmpc.plans`: every robot's last plan, by global id
  (``env * N + robot`` in a batch of runs);

The solve-time statistics of a run, ``solve_time_stats``, moved to
:mod:`dfcoa_opt.metrics.solver` (a statistic of a run log); the old name still
imports from here, with a :class:`DeprecationWarning`, until 0.3.

Notes: ``docs/methods/nmpc.md``.
"""

import importlib
import warnings
from typing import Any

from comparisons.nmpc.controller import Nmpc, goto_command

__all__ = ["Nmpc", "goto_command"]

#: Names that moved out of this package -> the module that holds them since 0.2.
MOVED_NAMES = {"solve_time_stats": "dfcoa_opt.metrics.solver"}


def __getattr__(name: str) -> Any:
    """A moved name (:data:`MOVED_NAMES`), from its new module, with a DeprecationWarning."""
    if name not in MOVED_NAMES:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    new = MOVED_NAMES[name]
    warnings.warn(f"{__name__}.{name} moved to {new}.{name}; the old name goes in 0.3",
                  DeprecationWarning, stacklevel=2)
    return getattr(importlib.import_module(new), name)
