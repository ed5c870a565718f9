"""The enclosing ellipse of an obstacle segment (paper 001 eq 8) and its support function.

:func:`segment_ellipse` builds ``O'`` around a segment with a clearance ``m``
(the reading of eq 8 is in :mod:`comparisons.orca.ivo.polygons`); :func:`ellipse_support`
is the exact support function of ``O' (+) D(0, r)`` used for the velocity
obstacle of eq 9; :func:`polygon_segments` cuts polygons into the segments the
ellipses enclose.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Ellipse:
    """An ellipse ``O'`` (eq 8).

    Attributes:
        centre: ``(2,)`` centre, m.
        axis: ``(2,)`` unit direction of the major (``a``) axis.
        a: Semi-axis along ``axis``, m.
        b: Semi-axis across ``axis``, m.
    """

    centre: FloatArray
    axis: FloatArray
    a: float
    b: float

    def contains(self, points: ArrayLike) -> NDArray[np.bool_]:
        """Whether points lie in the closed ellipse.

        Args:
            points: ``(..., 2)`` points, m.

        Returns:
            ``(...)`` booleans.
        """
        d = np.asarray(points, dtype=float) - self.centre
        x = d @ self.axis
        y = d @ np.array([-self.axis[1], self.axis[0]])
        with np.errstate(divide="ignore", invalid="ignore"):
            if self.b > 0.0:
                return (x / self.a) ** 2 + (y / self.b) ** 2 <= 1.0
            return (np.abs(x) <= self.a) & (y == 0.0)


@numba.njit(cache=True)
def ellipse_axes(half, m, stretch):  # pragma: no cover - numba
    """Semi-axes ``(a, b)`` of eq 8 for a segment of half-length ``half``, clearance ``m``."""
    a = stretch * (half + m)
    if m <= 0.0:
        return a, 0.0
    s = (a - m) * (a - m) - half * half
    t = (a + m) * (a + m) - half * half
    root = math.sqrt(max(s, 0.0) * t)
    b2 = 2.0 * m * m * a * a / (a * a - half * half + m * m + root)  # smaller root, stable
    return a, math.sqrt(b2)


def segment_ellipse(a_pt: ArrayLike, b_pt: ArrayLike, r_robot: float,
                    clearance: float | None = None, stretch: float = 1.0) -> Ellipse:
    """The ellipse ``O'`` enclosing segment ``I = [a_pt, b_pt]`` (eq 8).

    Centred at the midpoint, major axis along the segment, ``a = stretch (c + m)``
    (``c`` the half-length) and ``b`` the smallest semi-minor axis such that
    ``min_{q in I} dist(q, boundary of O') >= m`` ("the shortest distance
    between the expanded convex packet and the original line segment should be
    greater than r_A"; see the module docstring for the reading).

    Args:
        a_pt: ``(2,)`` first end point of the segment, m.
        b_pt: ``(2,)`` second end point, m.
        r_robot: Robot radius ``r_A``, m (the default clearance).
        clearance: Clearance ``m >= 0`` between the segment and the ellipse's
            boundary, m; ``None`` uses ``r_robot``; 0 gives the segment itself.
        stretch: ``a / (c + m) >= 1``; 1 puts the tips ``m`` past the end points.

    Returns:
        The ellipse.

    Raises:
        ValueError: If ``stretch < 1`` or the clearance is negative.
    """
    p0 = np.asarray(a_pt, dtype=float)
    p1 = np.asarray(b_pt, dtype=float)
    m = float(r_robot if clearance is None else clearance)
    if stretch < 1.0 or m < 0.0:
        raise ValueError("need stretch >= 1 and clearance >= 0")
    d = p1 - p0
    length = float(np.hypot(d[0], d[1]))
    axis = d / length if length > 0.0 else np.array([1.0, 0.0])
    a, b = ellipse_axes(0.5 * length, m, float(stretch))
    return Ellipse(0.5 * (p0 + p1), axis, float(a), float(b))


def ellipse_support(ellipse: Ellipse, normals: ArrayLike, r_robot: float = 0.0) -> FloatArray:
    """Support function of ``O' (+) D(0, r_A)`` (the set of eq 9), exact.

    ``h(n) = n . centre + sqrt(a^2 (n . e1)^2 + b^2 (n . e2)^2) + r_A``: the
    support of an ellipse plus that of a disc (supports add under Minkowski sums).

    Args:
        ellipse: The ellipse ``O'``.
        normals: ``(..., 2)`` unit directions.
        r_robot: Radius ``r_A`` of the disc added, m.

    Returns:
        ``(...)`` support values, m.
    """
    n = np.asarray(normals, dtype=float)
    e1 = ellipse.axis
    e2 = np.array([-e1[1], e1[0]])
    return (n @ ellipse.centre + np.sqrt((ellipse.a * (n @ e1)) ** 2 + (ellipse.b * (n @ e2)) ** 2)
            + r_robot)


def polygon_segments(polygons: list[ArrayLike], max_segment: float | None = None) -> FloatArray:
    """The set of line segments approximating the polygon obstacles (Fig. 2).

    Args:
        polygons: Vertex arrays ``(M, 2)``, m: ``M >= 3`` a closed polygon (a
            repeated first vertex is dropped), ``M == 2`` a single segment (wall).
        max_segment: Longest piece, m: longer edges are split into equal pieces
            (thinner ellipses); ``None`` keeps whole edges.

    Returns:
        ``(S, 4)`` segments ``(x0, y0, x1, y1)``, m; zero-length edges dropped.
    """
    starts, ends = [], []
    for poly in polygons:
        v = np.asarray(poly, dtype=float).reshape(-1, 2)
        if len(v) > 2 and np.array_equal(v[0], v[-1]):
            v = v[:-1]
        if len(v) < 2:
            continue
        ends.append(v[1:2] if len(v) == 2 else np.roll(v, -1, axis=0))
        starts.append(v[:1] if len(v) == 2 else v)
    if not starts:
        return np.zeros((0, 4))
    p0, p1 = np.concatenate(starts), np.concatenate(ends)
    length = np.hypot(p1[:, 0] - p0[:, 0], p1[:, 1] - p0[:, 1])
    keep = length > 0.0  # zero-length edges dropped
    p0, p1, length = p0[keep], p1[keep], length[keep]
    pieces = (np.ones(len(p0), np.int64) if max_segment is None else
              np.maximum(1, np.ceil(length / max_segment)).astype(np.int64))
    # piece q of an edge of k pieces runs from t = linspace(0, 1, k + 1)[q] to [q + 1]
    edge = np.repeat(np.arange(len(p0)), pieces)
    q = np.arange(len(edge)) - np.repeat(np.cumsum(pieces) - pieces, pieces)
    k = pieces[edge]
    t_lo, t_hi = np.empty(len(edge)), np.empty(len(edge))
    for kk in np.unique(k).tolist():
        t = np.linspace(0.0, 1.0, kk + 1)
        rows = k == kk
        t_lo[rows], t_hi[rows] = t[q[rows]], t[q[rows] + 1]
    a, d = p0[edge], (p1 - p0)[edge]
    return np.hstack([a + t_lo[:, None] * d, a + t_hi[:, None] * d])
