"""``reshape``: a formation that reshapes itself to get through (issue 20, work in progress).

- :mod:`~comparisons.reshape.region`: convex obstacle-free regions around the
  leader's look-ahead segment (IRIS style).
"""
