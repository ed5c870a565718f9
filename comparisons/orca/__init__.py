"""``orca``: ORCA and the improved velocity obstacle of paper 001.

- :mod:`~comparisons.orca.filter`: the safety filter ``OrcaFilter`` (``orca``,
  used as ``<controller>+orca``) and the navigator ``orca_nav``;
- :mod:`~comparisons.orca.lines`, :mod:`~comparisons.orca.lp`,
  :mod:`~comparisons.orca.velocities`: ORCA half-planes between robots, the exact
  2D solver and the batched update (numba);
- :mod:`~comparisons.orca.obstacles`, :mod:`~comparisons.orca.obstacle_set`: static
  polygons the RVO2 way;
- :mod:`~comparisons.orca.worlds`: the static obstacles of every run of a batch
  (each run's own world, merged into one table per mode);
- :mod:`~comparisons.orca.ivo`: paper 001's improved VO of polygons and discs;
- :mod:`~comparisons.orca.qp`: the same selection through ``qpsolvers``;
- :mod:`~comparisons.orca.safe`: the safe discrete-time mode;
- :mod:`~comparisons.orca.neighbours`, :mod:`~comparisons.orca.crowd`: neighbour
  search and an RVO2-style crowd for oracle tests and benchmarks.

Notes: ``docs/methods/orca_ivo.md``, ``docs/methods/orca_qp.md``.
"""
