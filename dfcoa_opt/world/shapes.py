"""Exact geometric obstacles: polygons, circles and rectangles.

The world keeps these next to the rasterised grid, for methods that need exact
geometry (paper 001's polygon velocity obstacles). Rasterisation rule, used by
:meth:`dfcoa_opt.world.grid.OccupancyGrid.from_shapes`: a cell is occupied iff
its centre lies inside the shape.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.geometry import circle_polygon, points_in_polygon, polygon_signed_area


@dataclass(frozen=True)
class Polygon:
    """A simple polygon.

    Attributes:
        vertices: ``((x, y), ...)`` in m, counter-clockwise, first vertex not repeated.
    """

    vertices: tuple[tuple[float, float], ...]

    def __post_init__(self) -> None:
        if len(self.vertices) < 3:
            raise ValueError("a polygon needs at least 3 vertices")
        if polygon_signed_area(self.vertices) <= 0.0:
            raise ValueError("polygon vertices must be counter-clockwise with non-zero area")

    def as_array(self) -> NDArray[np.float64]:
        """Vertices as a ``(V, 2)`` array in m."""
        return np.asarray(self.vertices, dtype=float)

    def contains(self, points: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Which of ``points`` ``(P, 2)`` (m) lie inside."""
        return points_in_polygon(points, self.vertices)

    def bounds(self) -> tuple[float, float, float, float]:
        """``(xmin, ymin, xmax, ymax)`` in m: no point outside is :meth:`contains`-inside."""
        v = self.as_array()
        return (float(v[:, 0].min()), float(v[:, 1].min()), float(v[:, 0].max()),
                float(v[:, 1].max()))

    def to_polygon(self) -> Polygon:
        """This polygon."""
        return self


@dataclass(frozen=True)
class Rectangle:
    """An axis-aligned rectangle.

    Attributes:
        min: Lower-left corner ``(x, y)`` in m.
        max: Upper-right corner ``(x, y)`` in m.
    """

    min: tuple[float, float]
    max: tuple[float, float]

    def __post_init__(self) -> None:
        if not (self.max[0] > self.min[0] and self.max[1] > self.min[1]):
            raise ValueError("rectangle max must exceed min in x and y")

    def to_polygon(self) -> Polygon:
        """The rectangle as a counter-clockwise :class:`Polygon`."""
        (x0, y0), (x1, y1) = self.min, self.max
        return Polygon(((x0, y0), (x1, y0), (x1, y1), (x0, y1)))

    def contains(self, points: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Which of ``points`` ``(P, 2)`` (m) lie inside (half-open on the max sides)."""
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        return (
            (p[:, 0] >= self.min[0]) & (p[:, 0] < self.max[0])
            & (p[:, 1] >= self.min[1]) & (p[:, 1] < self.max[1])
        )

    def bounds(self) -> tuple[float, float, float, float]:
        """``(xmin, ymin, xmax, ymax)`` in m: no point outside is :meth:`contains`-inside."""
        return (*self.min, *self.max)


@dataclass(frozen=True)
class Circle:
    """A disc.

    Attributes:
        center: ``(x, y)`` in m.
        radius: Radius in m, > 0.
    """

    center: tuple[float, float]
    radius: float

    def __post_init__(self) -> None:
        if not self.radius > 0.0:
            raise ValueError("circle radius must be > 0")

    def contains(self, points: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Which of ``points`` ``(P, 2)`` (m) lie inside or on the circle."""
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        d = p - np.asarray(self.center)
        return np.hypot(d[:, 0], d[:, 1]) <= self.radius  # no overflow for huge radii

    def bounds(self) -> tuple[float, float, float, float]:
        """``(xmin, ymin, xmax, ymax)`` in m: no point outside is :meth:`contains`-inside."""
        (x, y), r = self.center, self.radius
        return (x - r, y - r, x + r, y + r)

    def to_polygon(self, n: int = 32) -> Polygon:
        """A circumscribed ``n``-gon (contains the disc), counter-clockwise."""
        r_out = self.radius / np.cos(np.pi / n)
        return Polygon(tuple(map(tuple, circle_polygon(self.center, r_out, n))))


Shape = Polygon | Rectangle | Circle


def polygon_arrays(shapes: Sequence[Shape], n: int = 32) -> list[NDArray[np.float64]]:
    """Each shape's ``to_polygon().as_array()`` (m), the circles' ``n``-gons made together.

    The same numbers as one :meth:`Circle.to_polygon` per circle (the same
    operations, element by element), without a :class:`Polygon` per circle:
    a seeded clutter field has about a hundred.
    """
    out: list[NDArray[np.float64] | None] = [
        None if isinstance(s, Circle) else s.to_polygon().as_array() for s in shapes]
    disc = [k for k, s in enumerate(shapes) if isinstance(s, Circle)]
    if disc:
        circles = [shapes[k] for k in disc]
        r_out = np.array([c.radius for c in circles]) / np.cos(np.pi / n)  # type: ignore[union-attr]
        rings = circle_polygon([c.center for c in circles], r_out, n)  # type: ignore[union-attr]
        for k, ring in zip(disc, rings, strict=True):
            out[k] = ring
    return out  # type: ignore[return-value]
