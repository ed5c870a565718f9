"""Paper 001's improved velocity obstacle (IVO, section III.B, eq 8-11) of static obstacles.

- :mod:`~comparisons.orca.ivo.polygons`: the IVO lines of polygon edges through
  their enclosing ellipses, and :func:`ivo_lines`, which merges polygons and discs
  (of one world, or of each robot's own world in a batch of runs,
  :class:`IvoObstacles`);
- :mod:`~comparisons.orca.ivo.kernel`: the numba core of the ellipse lines;
- :mod:`~comparisons.orca.ivo.discs`: the closed form for a static disc and
  eq 9's horizon rules;
- :mod:`~comparisons.orca.ivo.ellipse`: the enclosing ellipse of a segment (eq 8)
  and its support function.
"""

from comparisons.orca.ivo.kernel import BISECT_ITERS, GOLDEN_ITERS, N_REFINE, N_SAMPLES
from comparisons.orca.ivo.polygons import IvoObstacles, ivo_line, ivo_lines

__all__ = ["BISECT_ITERS", "GOLDEN_ITERS", "N_REFINE", "N_SAMPLES", "IvoObstacles", "ivo_line",
           "ivo_lines"]
