"""``cbf``: the control-barrier-function QP safety filter (beyond the papers).

- :mod:`~comparisons.cbf.filter`: the filter ``CbfFilter`` (registered as
  ``cbf``; use it after any controller as ``<controller>+cbf``);
- :mod:`~comparisons.cbf.qp`: its programs (barrier rows, distributed and
  centralized QPs, the infeasibility policies).

Notes: ``docs/methods/cbf.md``.
"""

from comparisons.cbf.filter import MIN_DELTA, CbfFilter

__all__ = ["MIN_DELTA", "CbfFilter"]
