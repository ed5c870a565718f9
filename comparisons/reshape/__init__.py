"""``reshape``: a formation that reshapes itself to get through (beyond the papers, issue 20).

- :mod:`~comparisons.reshape.controller`: the controller ``Reshape`` (registered
  as ``reshape``, batched): distributed CBF tracking of every run's robots;
- :mod:`~comparisons.reshape.params`: its parameters, ``ReshapeParams``
  (``Reshape.Params``);
- :mod:`~comparisons.reshape.central`: the central formation planning of one run;
- :mod:`~comparisons.reshape.region`: convex obstacle-free regions around the
  leader's look-ahead segment (IRIS style);
- :mod:`~comparisons.reshape.planner`: the choice of template, rotation, scale
  and position inside a region.
"""

from comparisons.reshape.controller import Reshape

__all__ = ["Reshape"]
