"""What the constraint-based methods share to build and solve their constraints.

- :mod:`~comparisons.constraints.distance`: for a point and what it must keep
  away from (another robot, a disc, a polygon), the nearest point, the signed
  distance and the unit normal, from which ``cbf`` builds its barriers and
  ``nmpc`` its half-planes;
- :mod:`~comparisons.constraints.world_shapes`: the nearest static shapes of every
  robot in its own run's map, all rows of a batch in one compiled call (``cbf``,
  ``nmpc``);
- :mod:`~comparisons.constraints.solvers`: the ``qpsolvers`` plumbing of the
  ``orca`` and ``cbf`` programs (options, retries, the installed-solver check).
"""
