"""Exact clearance from points to polygons and circles (the fast path of ``World.clearance``).

:func:`shape_clearance` computes, for every point, the distance to the nearest
polygon edge or circle, zero inside a polygon (even-odd rule) or a circle, and
``cap`` beyond ``cap``. It is one numba loop over points, edges and circles,
written with the same floating-point operations, in the same order, as the
vectorised numpy formulas it replaces (:func:`dfcoa_opt.core.geometry.point_segment_distance`,
:func:`dfcoa_opt.core.geometry.points_in_polygons`), so both give bit-identical
results; ``tests/test_shape_clearance.py`` checks that, and shapely checks the
geometry (``tests/test_simulator.py``). The simulator calls it every step to
count contacts, where the numpy version cost ~150 us for 4 robots in paper
000's Scenario 1 and this one costs a few.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@numba.njit(cache=True)
def shape_clearance(points: FloatArray, a: FloatArray, b: FloatArray, start: IntArray,
                    lo: FloatArray, hi: FloatArray, centres: FloatArray, radii: FloatArray,
                    cap: float) -> FloatArray:  # pragma: no cover - numba
    """Distance (m) from points to polygons and circles, 0 inside; ``cap`` at most.

    Args:
        points: ``(P, 2)`` query points, m.
        a: ``(E, 2)`` edge starts of all polygons, polygon after polygon, m.
        b: ``(E, 2)`` edge ends, m (edge ``k`` of a polygon runs to its next vertex).
        start: ``(Q + 1,)`` first edge of each polygon, then ``E``.
        lo: ``(Q, 2)`` lower corners of the polygons' bounding boxes, m.
        hi: ``(Q, 2)`` upper corners, m.
        centres: ``(C, 2)`` circle centres, m.
        radii: ``(C,)`` circle radii, m.
        cap: Larger distances are reported as ``cap``, m.

    Returns:
        ``(P,)`` clearances, m.
    """
    one = np.zeros(0, np.int64)
    return shape_clearance_worlds(points, one, a, b, start, np.array([0, start.shape[0] - 1]),
                                  lo, hi, centres, radii, np.array([0, radii.shape[0]]), cap)


@numba.njit(cache=True)
def shape_clearance_worlds(points: FloatArray, world: IntArray, a: FloatArray, b: FloatArray,
                           start: IntArray, poly_ptr: IntArray, lo: FloatArray, hi: FloatArray,
                           centres: FloatArray, radii: FloatArray, circle_ptr: IntArray,
                           cap: float) -> FloatArray:  # pragma: no cover - numba
    """:func:`shape_clearance` of each point against its own world's shapes.

    The shapes of every world are stacked, world after world: world ``w`` has
    polygons ``poly_ptr[w] .. poly_ptr[w + 1] - 1`` (their edges from
    ``start``) and circles ``circle_ptr[w] .. circle_ptr[w + 1] - 1``. Point
    ``i`` is measured in world ``world[i]`` (``world`` empty: world 0 for every
    point), with the operations of a call on that world alone.

    Args:
        points: ``(P, 2)`` query points, m.
        world: ``(P,)`` each point's world, or ``(0,)``.
        a: ``(E, 2)`` edge starts of all polygons, m.
        b: ``(E, 2)`` edge ends, m.
        start: ``(Q + 1,)`` first edge of each polygon, then ``E``.
        poly_ptr: ``(W + 1,)`` first polygon of each world, then ``Q``.
        lo: ``(Q, 2)`` lower corners of the polygons' bounding boxes, m.
        hi: ``(Q, 2)`` upper corners, m.
        centres: ``(C, 2)`` circle centres, m.
        radii: ``(C,)`` circle radii, m.
        circle_ptr: ``(W + 1,)`` first circle of each world, then ``C``.
        cap: Larger distances are reported as ``cap``, m.

    Returns:
        ``(P,)`` clearances, m.
    """
    out = np.empty(points.shape[0])
    for i in range(points.shape[0]):
        w = world[i] if world.shape[0] > 0 else 0
        q0, q1 = poly_ptr[w], poly_ptr[w + 1]
        e0, e1 = start[q0], start[q1]
        px, py = points[i, 0], points[i, 1]
        best = cap
        if e1 > e0:
            d_min = np.inf
            for k in range(e0, e1):
                ax, ay = a[k, 0], a[k, 1]
                abx, aby = b[k, 0] - ax, b[k, 1] - ay
                denom = abx * abx + aby * aby
                t = ((px - ax) * abx + (py - ay) * aby) / (denom if denom > 0.0 else 1.0)
                t = min(max(t, 0.0), 1.0)
                dx, dy = px - (ax + t * abx), py - (ay + t * aby)
                d = math.sqrt(dx * dx + dy * dy)
                if d < d_min:
                    d_min = d
            best = min(best, d_min)
            for q in range(q0, q1):
                if not (lo[q, 0] <= px <= hi[q, 0] and lo[q, 1] <= py <= hi[q, 1]):
                    continue
                inside = False
                for k in range(start[q], start[q + 1]):
                    y1, y2 = a[k, 1], b[k, 1]
                    if y1 == y2 or (y1 <= py) == (y2 <= py):
                        continue
                    x1, x2 = a[k, 0], b[k, 0]
                    if px < x1 + (py - y1) * (x2 - x1) / (y2 - y1):
                        inside = not inside
                if inside:
                    best = 0.0
        c0, c1 = circle_ptr[w], circle_ptr[w + 1]
        if c1 > c0:
            gap = np.inf
            for c in range(c0, c1):
                dx, dy = px - centres[c, 0], py - centres[c, 1]
                g = math.sqrt(dx * dx + dy * dy) - radii[c]
                if g < gap:
                    gap = g
            best = min(best, max(gap, 0.0))
        out[i] = best
    return out
