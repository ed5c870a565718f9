"""The static obstacles of every run of a batch, for the ``orca`` filter's hard lines.

The runs of a batch share one world, unless the scenario draws a clutter field
from its seed (``scenarios[e].world`` then differs between runs). Each world is
prepared once, as the filter prepares it for a single run, and the worlds are
merged into tables that one call serves for the rows of every run, each row
seeing only its own run's world:

- mode ``orca``: one :class:`~comparisons.orca.obstacle_set.ObstacleSet` with a
  k-d tree per world (:func:`~comparisons.orca.obstacle_set.merge_obstacles`);
- mode ``ivo``: an :class:`~comparisons.orca.ivo.IvoObstacles` of every world's
  segments and discs;
- mode ``next_step`` (and the safe mode): every world's polygon edges, padded to
  the longest list with segments far away (``FAR``), gathered per row.

A row's lines are then the lines it gets in a run simulated alone, bit for bit:
the same arithmetic on the same obstacles in the same order; only the padding
of the line tables (never read past each row's count) is wider.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from comparisons.orca.ivo import IvoObstacles
from comparisons.orca.ivo.ellipse import polygon_segments
from comparisons.orca.ivo.polygons import FAR
from comparisons.orca.obstacle_set import ObstacleSet, merge_obstacles, prepare_obstacles
from dfcoa_opt.world.shapes import Circle, polygon_arrays

if TYPE_CHECKING:
    from dfcoa_opt.scenario.scenario import Scenario

FloatArray = NDArray[np.float64]


class StaticWorlds:
    """The distinct static worlds of a batch's runs, prepared for the hard lines.

    Args:
        scenarios: One scenario per run (run ``e`` = ``scenarios[e]``); runs whose
            scenarios share a world object share its tables.
        orca_tree: Build the RVO2 obstacle trees (mode ``orca``; costly for large maps).
        ivo_max_segment: Split polygon edges of mode ``ivo`` into pieces no longer
            than this, m; None: whole edges.

    Attributes:
        world_of: ``(E,)`` the world of each run.
        obstacles: The merged obstacle trees (mode ``orca``), or None when not
            built or no world has an edge.
        ivo_items: Per world, mode ``ivo``'s items: its non-circle polygon edges
            ``(S, 4)`` and its circles as discs ``(C, 3)``, m.
        ivo: The same, padded and stacked for :func:`~comparisons.orca.ivo.ivo_lines`.
    """

    def __init__(self, scenarios: Sequence[Scenario], orca_tree: bool,
                 ivo_max_segment: float | None) -> None:
        index: dict[int, int] = {}
        self._shapes = []
        for sc in scenarios:
            if id(sc.world) not in index:
                index[id(sc.world)] = len(self._shapes)
                self._shapes.append(sc.world.shapes)
        self.world_of = np.array([index[id(sc.world)] for sc in scenarios], dtype=np.intp)
        self.obstacles: ObstacleSet | None = None
        if orca_tree and any(self.polygons):
            self.obstacles = merge_obstacles([prepare_obstacles(p) for p in self.polygons])
        self.ivo_items = [_ivo_items(shapes, ivo_max_segment) for shapes in self._shapes]
        self.ivo = IvoObstacles.from_worlds(self.ivo_items)

    @property
    def n_worlds(self) -> int:
        """Number of distinct worlds ``W``."""
        return len(self._shapes)

    @cached_property
    def polygons(self) -> list[list[FloatArray]]:
        """Per world, every shape as a polygon ``(M, 2)``, m (a circle as its 32-gon)."""
        return [polygon_arrays(shapes) for shapes in self._shapes]

    @cached_property
    def segments(self) -> FloatArray:
        """``(W, S, 2, 2)`` each world's polygon edges (mode ``next_step``, the safe mode), m.

        Padded past a world's own edges with zero-length segments at ``FAR``.
        """
        edges = [polygon_segments(polys).reshape(-1, 2, 2) for polys in self.polygons]
        out = np.full((len(edges), max(len(e) for e in edges), 2, 2), FAR)
        for w, e in enumerate(edges):
            out[w, :len(e)] = e
        return out

    def row_world(self, env: NDArray[np.intp] | None) -> NDArray[np.intp] | None:
        """The world of each row of runs ``env``; None when every run has one world."""
        if env is None or self.n_worlds == 1:
            return None
        return self.world_of[env]

    def row_segments(self, world: NDArray[np.intp] | None) -> FloatArray:
        """Polygon edges ``(S, 2, 2)`` of the only world, or ``(R, S, 2, 2)`` each row's, m."""
        return self.segments[0] if world is None else self.segments[world]


def _ivo_items(shapes, max_segment: float | None) -> tuple[FloatArray, FloatArray]:
    """Mode ``ivo``'s items of one world: non-circle edges ``(S, 4)`` and discs ``(C, 3)``, m."""
    discs = np.array([(*shape.center, shape.radius) for shape in shapes
                      if isinstance(shape, Circle)], dtype=float).reshape(-1, 3)
    segments = polygon_segments([shape.to_polygon().as_array() for shape in shapes
                                 if not isinstance(shape, Circle)], max_segment)
    return segments, discs
