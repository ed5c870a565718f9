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

from typing import Any

from comparisons.nmpc.controller import Nmpc
from comparisons.nmpc.fallback import goto_command
from dfcoa_opt.core.moved import moved_attribute

__all__ = ["Nmpc", "goto_command"]

#: Names that moved out of this package -> the module that holds them since 0.2.
MOVED_NAMES = {"solve_time_stats": "dfcoa_opt.metrics.solver"}


def __getattr__(name: str) -> Any:
    """A moved name (:data:`MOVED_NAMES`), from its new module, with a DeprecationWarning."""
    return moved_attribute(__name__, name, MOVED_NAMES, "0.3")
