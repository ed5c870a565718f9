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

from dfcoa_opt.core.geometry import circle_polygon, points_in_polygon, polygon_signed_area
from dfcoa_opt.core.polygons import polygon_defect


@dataclass(frozen=True)
class Polygon:
    """A simple polygon.

    Refused (``ValueError``): fewer than 3 vertices, a polygon that is not
    simple (:func:`~dfcoa_opt.core.polygons.polygon_defect`: edges that cross or
    touch, a repeated vertex, a zero-length edge; the even-odd inside test
    and the clearance would disagree on it), clockwise order or zero area.

    Attributes:
        vertices: ``((x, y), ...)`` in m, counter-clockwise, first vertex not repeated.
    """

    vertices: tuple[tuple[float, float], ...]

    def __post_init__(self) -> None:
        if len(self.vertices) < 3:
            raise ValueError("a polygon needs at least 3 vertices")
        defect = polygon_defect(self.vertices)
        if defect is not None:
            raise ValueError(f"polygon is not simple: {describe_defect(self.vertices, defect)}")
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


def describe_defect(vertices: Sequence[Sequence[float]], defect: tuple[int, int]) -> str:
    """A :func:`~dfcoa_opt.core.polygons.polygon_defect` in words, with the vertices' numbers.

    Args:
        vertices: ``(V, 2)`` polygon vertices in m.
        defect: ``(i, j)`` edge indices from :func:`~dfcoa_opt.core.polygons.polygon_defect`.
    """
    v = [tuple(float(c) for c in p) for p in vertices]
    n = len(v)

    def pt(k: int) -> str:
        return f"({v[k % n][0]:.6g}, {v[k % n][1]:.6g})"

    def edge(k: int) -> str:
        return f"edge {k} {pt(k)}-{pt(k + 1)}"

    i, j = defect
    if i == j:
        hint = "; the first vertex is not repeated at the end" if i == n - 1 else ""
        return (f"vertices {i} and {(i + 1) % n} are the same point {pt(i)} (a zero-length "
                f"edge{hint})")
    if (j - i) % n in (1, n - 1):
        return f"{edge(i)} and {edge(j)} fold back onto each other"
    for k in (i, i + 1):
        if v[k % n] in (v[j], v[(j + 1) % n]):
            at = j if v[k % n] == v[j] else (j + 1) % n
            return (f"vertices {k % n} and {at} are the same point {pt(k)}, where {edge(i)} and "
                    f"{edge(j)} meet; edges may meet only at the vertex they share")
    p, r = np.array(v[i]), np.array(v[(i + 1) % n]) - np.array(v[i])
    q, t = np.array(v[j]), np.array(v[(j + 1) % n]) - np.array(v[j])
    denom = r[0] * t[1] - r[1] * t[0]
    if denom != 0.0:
        x, y = p + r * (((q - p)[0] * t[1] - (q - p)[1] * t[0]) / denom)
        if not any(np.array_equal(c, (x, y)) for c in (v[i], v[(i + 1) % n], v[j],
                                                          v[(j + 1) % n])):
            return (f"{edge(i)} and {edge(j)} cross at ({x:.6g}, {y:.6g}); edges may meet "
                    f"only at the vertex they share")
    return (f"{edge(i)} and {edge(j)} touch (a vertex on the other edge, or an overlap); edges "
            f"may meet only at the vertex they share")


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
