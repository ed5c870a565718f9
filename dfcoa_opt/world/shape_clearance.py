"""Exact clearance from points to polygons and circles (the fast path of ``World.clearance``).

:func:`shape_clearance` computes, for every point, the distance to the nearest
polygon edge or circle, zero inside a polygon (even-odd rule) or a circle, and
``cap`` beyond ``cap``. It is one numba loop over points, edges and circles,
written with the same floating-point operations, in the same order, as the
vectorised numpy formulas it replaces (:func:`dfcoa_opt.geometry.point_segment_distance`,
:func:`dfcoa_opt.geometry.points_in_polygons`), so both give bit-identical
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
    n_poly = start.shape[0] - 1
    out = np.empty(points.shape[0])
    for i in range(points.shape[0]):
        px, py = points[i, 0], points[i, 1]
        best = cap
        if a.shape[0]:
            d_min = np.inf
            for k in range(a.shape[0]):
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
            for q in range(n_poly):
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
        if centres.shape[0]:
            gap = np.inf
            for c in range(centres.shape[0]):
                dx, dy = px - centres[c, 0], py - centres[c, 1]
                g = math.sqrt(dx * dx + dy * dy) - radii[c]
                if g < gap:
                    gap = g
            best = min(best, max(gap, 0.0))
        out[i] = best
    return out
