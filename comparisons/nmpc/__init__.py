"""``nmpc``: distributed nonlinear MPC formation controller (beyond the papers).

- :mod:`~comparisons.nmpc.controller`: the controller ``Nmpc`` (registered as
  ``nmpc``), its fallback ``goto_command`` and ``solve_time_stats`` of a log;
- :mod:`~comparisons.nmpc.problem`: the casadi program of one robot;
- :mod:`~comparisons.nmpc.geometry`: slot references, neighbour predictions and
  the distance half-planes;
- :mod:`~comparisons.nmpc.plans`: every robot's last plan, by global id
  (``env * N + robot`` in a batch of runs);

Notes: ``docs/methods/nmpc.md``.
"""

from comparisons.nmpc.controller import Nmpc, goto_command, solve_time_stats

__all__ = ["Nmpc", "goto_command", "solve_time_stats"]
