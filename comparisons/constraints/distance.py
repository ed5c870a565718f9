"""Distance-constraint builders shared by the ``cbf`` safety filter and the ``nmpc`` controller.

One builder per geometry, each returning the same three things for a point and
the thing it must keep away from: the nearest point ``q`` of that thing, the
signed distance ``delta`` (negative inside an obstacle, m) and the unit normal
``n`` pointing from ``q`` towards the point (outwards for an obstacle). A method
turns them into its own constraint:

- ``cbf`` (:mod:`comparisons.cbf`): the barrier ``h = delta |delta| - D^2``
  (``= ||p - q||^2 - D^2`` outside) with gradient ``2 |delta| n`` in ``p``, held
  by ``dh/dt >= -gamma h``;
- ``nmpc`` (:mod:`comparisons.nmpc`): the half-plane ``n . (x - q) >= D`` at
  each predicted position ``x`` of the horizon, linearised where the previous
  plan put the robot (exact for a disc's tangent and for convex polygons, whose
  nearest-point half-plane contains the whole obstacle).

Geometries:

- **robot pairs** (:func:`pair_geometry`): another robot's centre, ``q = p_j``,
  ``delta = ||p_i - p_j||``;
- **discs** (circles of the map, moving obstacles): ``q = c + r n``,
  ``delta = ||p - c|| - r``;
- **polygons** (rectangles and polygons of the map): the nearest point of the
  boundary (:func:`dfcoa_opt.core.geometry.closest_point_on_segment`), negative
  ``delta`` inside (even-odd rule of :func:`dfcoa_opt.core.geometry.points_in_polygons`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from comparisons.constraints.geometry_kernels import (
    discs_kernel,
    nearest_kernel,
    pairs_kernel,
    polygons_kernel,
)
from dfcoa_opt.core.geometry import polygon_edges
from dfcoa_opt.world.shapes import Circle

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Nearest:
    """Nearest points of ``K`` things to each of ``P`` points, nearest first.

    Attributes:
        point: ``(P, K, 2)`` nearest point ``q`` of each thing, m.
        delta: ``(P, K)`` signed distance, m (negative inside; ``inf`` in unused slots).
        normal: ``(P, K, 2)`` unit normal from ``q`` towards the point (outward).
        mask: ``(P, K)`` which slots hold a thing within reach.
    """

    point: FloatArray
    delta: FloatArray
    normal: FloatArray
    mask: NDArray[np.bool_]


def pair_geometry(position: FloatArray, other: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Distance and unit normal from other robots' centres to each robot's centre.

    Args:
        position: ``(N, 2)`` robot centres, m.
        other: ``(N, K, 2)`` centres of the robots each one keeps away from, m.

    Returns:
        ``(delta (N, K) m, normal (N, K, 2))``; coincident centres get the normal
        ``(1, 0)``.
    """
    other = np.ascontiguousarray(other, dtype=float)
    delta, normal = np.empty(other.shape[:2]), np.empty(other.shape)
    pairs_kernel(np.ascontiguousarray(position, dtype=float), other, delta, normal)
    return delta, normal


@dataclass(frozen=True)
class StaticObstacles:
    """The map's exact shapes, split into discs and polygons for the builders.

    Attributes:
        discs: ``(C, 3)`` circle centre x, y and radius, m.
        edge_a: ``(Q, V, 2)`` polygon edge starts (padded, :func:`polygon_edges`), m.
        edge_b: ``(Q, V, 2)`` polygon edge ends, m.
    """

    discs: FloatArray
    edge_a: FloatArray
    edge_b: FloatArray

    @classmethod
    def from_shapes(cls, shapes) -> StaticObstacles:
        """Circles as exact discs, every other shape as its polygon."""
        discs = np.array([(*s.center, s.radius) for s in shapes if isinstance(s, Circle)],
                         dtype=float).reshape(-1, 3)
        polys = [s.to_polygon().as_array() for s in shapes if not isinstance(s, Circle)]
        a, b = polygon_edges(polys)
        return cls(discs, a.reshape(len(polys), a.shape[1], 2),
                   b.reshape(len(polys), b.shape[1], 2))

    def nearest(self, points: FloatArray, max_count: int, reach: float) -> Nearest:
        """The ``max_count`` nearest obstacles of each point within ``reach`` (signed distance).

        Args:
            points: ``(P, 2)`` query points, m.
            max_count: Slots per point ``K``.
            reach: Obstacles farther than this (signed distance, m) are left out.

        Returns:
            :class:`Nearest` with ``K = max_count`` slots, nearest first.
        """
        p = np.ascontiguousarray(points, dtype=float).reshape(-1, 2)
        q, normal = np.empty((len(p), max_count, 2)), np.empty((len(p), max_count, 2))
        delta, mask = np.empty((len(p), max_count)), np.empty((len(p), max_count), dtype=bool)
        nearest_kernel(p, self.discs, self.edge_a, self.edge_b, float(reach), q, delta, normal,
                       mask)
        return Nearest(q, delta, normal, mask)


def disc_nearest(points: FloatArray, discs: FloatArray) -> tuple[FloatArray, FloatArray,
                                                                  FloatArray]:
    """Nearest boundary point, signed distance and outward normal of every disc.

    Args:
        points: ``(P, 2)`` query points, m.
        discs: ``(C, 3)`` centre x, y and radius, m, the same for every point; or
            ``(P, C, 3)``, each point's own discs (e.g. the moving obstacles it senses).

    Returns:
        ``(q (P, C, 2), delta (P, C), normal (P, C, 2))``; a point at a centre gets the
        normal ``(1, 0)``.
    """
    p = np.ascontiguousarray(points, dtype=float).reshape(-1, 2)
    discs = np.asarray(discs, dtype=float)
    per_point = np.ascontiguousarray(np.broadcast_to(discs, (len(p), *discs.shape[-2:])))
    q, normal = np.empty((*per_point.shape[:2], 2)), np.empty((*per_point.shape[:2], 2))
    delta = np.empty(per_point.shape[:2])
    discs_kernel(p, per_point, q, delta, normal)
    return q, delta, normal


def polygon_nearest(points: FloatArray, edge_a: FloatArray, edge_b: FloatArray
                    ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Nearest boundary point, signed distance and outward normal of every polygon.

    Args:
        points: ``(P, 2)`` query points, m.
        edge_a: ``(Q, V, 2)`` edge starts, m.
        edge_b: ``(Q, V, 2)`` edge ends, m.

    Returns:
        ``(q (P, Q, 2), delta (P, Q), normal (P, Q, 2))``: ``delta < 0`` inside, and the
        normal then points from the point to ``q`` (out of the polygon). A point on the
        boundary gets the outward normal of its edge.
    """
    p = np.ascontiguousarray(points, dtype=float).reshape(-1, 2)
    shape = (len(p), len(edge_a))
    q, delta, normal = np.empty((*shape, 2)), np.empty(shape), np.empty((*shape, 2))
    polygons_kernel(p, np.ascontiguousarray(edge_a, dtype=float),
                    np.ascontiguousarray(edge_b, dtype=float), q, delta, normal)
    return q, delta, normal


def barrier(delta: FloatArray, normal: FloatArray, margin: float | FloatArray
            ) -> tuple[FloatArray, FloatArray]:
    """The CBF ``h = delta |delta| - D^2`` and its gradient ``2 |delta| n`` in the point.

    Outside (``delta >= 0``) this is ``||p - q||^2 - D^2``, the squared-distance
    barrier, convex in ``p`` for a disc, a convex polygon or another robot.

    Args:
        delta: Signed distances, m.
        normal: ``(..., 2)`` unit normals.
        margin: Safe distance ``D`` (broadcast), m.

    Returns:
        ``(h m^2, grad (..., 2) m)``.
    """
    return delta * np.abs(delta) - np.square(margin), 2.0 * np.abs(delta)[..., None] * normal
