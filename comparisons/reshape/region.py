"""Convex obstacle-free regions around a seed segment, IRIS style (Deits & Tedrake 2015).

The region is a convex polygon ``{x : A x <= b}`` (rows of ``A`` unit normals)
grown around a seed segment (the leader's look-ahead): alternately

1. **separating half-planes**: in the frame where the current ellipse
   ``E = {C u + d : |u| <= 1}`` is the unit disc, the obstacle nearest to the
   centre gives the half-plane tangent to the scaled ellipse at its nearest
   point; every obstacle already on the far side of it is dropped, and the next
   nearest gives the next half-plane, until none is left;
2. **the largest inscribed ellipse** of that polygon (``max log det C`` subject
   to ``|C a_k| + a_k . d <= b_k``), which seeds the next round.

The first round starts from the disc whose diameter is the seed segment.

Obstacles are segments (a polygon's edges; a disc as the edges of its
circumscribed regular polygon, so it is covered, never cut; a moving disc as
the circumscribed polygon of its sweep over the horizon). A convex region that
holds a point outside a polygon and meets the polygon must cross an edge, so
excluding every edge excludes the polygons. The seed segment always stays in
the region: a tangent half-plane that would cut it is replaced by the line
separating the obstacle segment from the seed segment at their closest points.
The map's bounds are four more half-planes.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.core.geometry import closest_point_on_segment
from dfcoa_opt.world.shapes import Circle, Shape

FloatArray = NDArray[np.float64]

#: Edges of the regular polygon that circumscribes a disc obstacle.
DISC_EDGES = 16
#: Smallest radius of the initial disc (a seed segment of one point), m.
SEED_WIDTH = 1e-3
#: Half-plane offsets keep this much off an obstacle (numerical margin), m.
EPS = 1e-9


@dataclass(frozen=True)
class Region:
    """A convex polygon ``{x : A x <= b}`` and the ellipse it was grown from.

    Attributes:
        A: ``(K, 2)`` unit outward normals.
        b: ``(K,)`` offsets, m.
        C: ``(2, 2)`` symmetric positive-definite shape of the ellipse, m.
        d: ``(2,)`` centre of the ellipse, m.
    """

    A: FloatArray
    b: FloatArray
    C: FloatArray
    d: FloatArray

    def contains(self, points: FloatArray, margin: float = 0.0) -> NDArray[np.bool_]:
        """Whether each point lies in the region shrunk by ``margin`` (m)."""
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        return np.all(p @ self.A.T <= self.b + 1e-9 - margin, axis=1)

    def vertices(self) -> FloatArray:
        """``(V, 2)`` the polygon's corners, counter-clockwise (for plots and tests)."""
        from scipy.spatial import HalfspaceIntersection

        hs = HalfspaceIntersection(np.column_stack([self.A, -self.b]), self.d)
        pts = hs.intersections
        centre = pts.mean(axis=0)
        order = np.argsort(np.arctan2(pts[:, 1] - centre[1], pts[:, 0] - centre[0]))
        return pts[order]


def disc_segments(centres: FloatArray, radii: FloatArray) -> FloatArray:
    """``(C * DISC_EDGES, 2, 2)`` edges of the regular polygons circumscribing discs."""
    c = np.asarray(centres, dtype=float).reshape(-1, 2)
    r = np.asarray(radii, dtype=float).reshape(-1)
    ang = 2.0 * math.pi * np.arange(DISC_EDGES + 1) / DISC_EDGES
    corner = (r / math.cos(math.pi / DISC_EDGES))[:, None, None] * np.stack(
        [np.cos(ang), np.sin(ang)], axis=-1)[None]
    pts = c[:, None, :] + corner
    return np.stack([pts[:, :-1], pts[:, 1:]], axis=2).reshape(-1, 2, 2)


def swept_disc_segments(positions: FloatArray, velocities: FloatArray, radii: FloatArray,
                        horizon: float) -> FloatArray:
    """Edges covering moving discs over ``[0, horizon]`` s at constant velocity.

    Each disc's sweep (a capsule) is covered by its two end discs' circumscribed
    polygons and the two sides between them.
    """
    p0 = np.asarray(positions, dtype=float).reshape(-1, 2)
    p1 = p0 + horizon * np.asarray(velocities, dtype=float).reshape(-1, 2)
    r = np.asarray(radii, dtype=float).reshape(-1)
    out = [disc_segments(p0, r), disc_segments(p1, r)]
    move = p1 - p0
    length = np.hypot(move[:, 0], move[:, 1])
    keep = length > 1e-9
    if keep.any():
        side = np.stack([-move[keep, 1], move[keep, 0]], axis=-1) / length[keep, None]
        off = (r[keep] / math.cos(math.pi / DISC_EDGES))[:, None] * side
        for sign in (1.0, -1.0):
            out.append(np.stack([p0[keep] + sign * off, p1[keep] + sign * off], axis=1))
    return np.concatenate(out, axis=0)


def shape_segments(shapes: Sequence[Shape]) -> FloatArray:
    """``(S, 2, 2)`` obstacle segments of static shapes: discs as polygons, polygons' edges."""
    circles = [s for s in shapes if isinstance(s, Circle)]
    parts = [disc_segments(np.array([c.center for c in circles]).reshape(-1, 2),
                           np.array([c.radius for c in circles]))]
    for s in shapes:
        if isinstance(s, Circle):
            continue
        v = s.to_polygon().as_array()
        parts.append(np.stack([v, np.roll(v, -1, axis=0)], axis=1))
    return np.concatenate(parts, axis=0) if parts else np.zeros((0, 2, 2))


def _closest_between_segments(a0: FloatArray, a1: FloatArray, b0: FloatArray, b1: FloatArray
                              ) -> tuple[FloatArray, FloatArray]:
    """Closest points ``(p on [a0, a1], q on [b0, b1])`` of two segments that do not cross."""
    cands = [(a0, closest_point_on_segment(a0, b0, b1)), (a1, closest_point_on_segment(a1, b0, b1)),
             (closest_point_on_segment(b0, a0, a1), b0), (closest_point_on_segment(b1, a0, a1), b1)]
    return min(cands, key=lambda pq: float(np.hypot(*(pq[0] - pq[1]))))


def separating_halfplanes(C: FloatArray, d: FloatArray, segments: FloatArray,
                          seed: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Half-planes that exclude every segment, nearest first in the ellipse's metric.

    Args:
        C: ``(2, 2)`` ellipse shape.
        d: ``(2,)`` ellipse centre, m.
        segments: ``(S, 2, 2)`` obstacle segments, m.
        seed: ``(2, 2)`` the seed segment, kept inside every half-plane, m.

    Returns:
        ``(A (K, 2) unit normals, b (K,))``.
    """
    if len(segments) == 0:
        return np.zeros((0, 2)), np.zeros(0)
    c_inv = np.linalg.inv(C)
    local = (segments - d) @ c_inv.T  # the ellipse becomes the unit disc
    q = closest_point_on_segment(np.zeros(2), local[:, 0], local[:, 1])
    dist = np.hypot(q[:, 0], q[:, 1])
    remaining = np.ones(len(segments), dtype=bool)
    rows_a, rows_b = [], []
    while remaining.any():
        i = int(np.flatnonzero(remaining)[np.argmin(dist[remaining])])
        # n' . C^-1 (x - d) <= |q'| in the world: (C^-T n') . x <= |q'| + (C^-T n') . d
        raw = c_inv.T @ (q[i] / max(dist[i], 1e-300))
        norm = math.hypot(*raw)
        a, b = raw / norm, float(dist[i] + raw @ d) / norm
        if np.any(seed @ a > b - EPS):  # it would cut the seed: separate at the closest points
            p, o = _closest_between_segments(seed[0], seed[1], segments[i, 0], segments[i, 1])
            gap = o - p
            a = gap / max(math.hypot(*gap), 1e-300)
            b = float(a @ o)
        b -= EPS
        rows_a.append(a)
        rows_b.append(b)
        remaining[i] = False
        outside = np.all(segments @ a >= b, axis=1)
        remaining &= ~outside
    return np.array(rows_a), np.array(rows_b)


def inscribed_ellipse(A: FloatArray, b: FloatArray, C0: FloatArray, d0: FloatArray
                      ) -> tuple[FloatArray, FloatArray]:
    """The largest ellipse in ``{x : A x <= b}`` (``max log det C``), from ``(C0, d0)``.

    Solved over ``C = [[c1, c2], [c2, c3]]`` and ``d`` with SLSQP; the start is
    shrunk until it is feasible. Returns the start itself if the solver fails.
    """
    def unpack(z: FloatArray) -> tuple[FloatArray, FloatArray]:
        return np.array([[z[0], z[1]], [z[1], z[2]]]), z[3:]

    def slack(z: FloatArray) -> FloatArray:
        c, d = unpack(z)
        return b - A @ d - np.hypot(*(A @ c).T)

    def slack_jac(z: FloatArray) -> FloatArray:
        c, _ = unpack(z)
        ca = A @ c  # (K, 2): rows C a_k (C symmetric)
        n = ca / np.maximum(np.hypot(ca[:, 0], ca[:, 1]), 1e-300)[:, None]
        # d|C a|/dc1 = n_x a_x, dc2 = n_x a_y + n_y a_x, dc3 = n_y a_y
        dc = np.column_stack([n[:, 0] * A[:, 0], n[:, 0] * A[:, 1] + n[:, 1] * A[:, 0],
                              n[:, 1] * A[:, 1]])
        return -np.column_stack([dc, A])

    def det(z: FloatArray) -> float:
        # SLSQP's line search may try huge steps: an overflowing or non-positive
        # determinant counts as the smallest one (the largest cost), not as nan
        with np.errstate(over="ignore", invalid="ignore"):
            v = float(z[0] * z[2] - z[1] * z[1])
        return v if math.isfinite(v) and v > 1e-300 else 1e-300

    def cost(z: FloatArray) -> float:
        return -math.log(det(z))

    def cost_grad(z: FloatArray) -> FloatArray:
        with np.errstate(over="ignore", invalid="ignore"):
            return np.array([-z[2], 2.0 * z[1], -z[0], 0.0, 0.0]) / det(z)

    start = np.array([C0[0, 0], C0[0, 1], C0[1, 1], *d0])
    for _ in range(60):
        if np.all(slack(start) >= 0.0):
            break
        start[:3] *= 0.7
    from scipy.optimize import minimize  # here: scipy.optimize takes ~0.15 s to import

    res = minimize(cost, start, jac=cost_grad, method="SLSQP",
                   constraints=[{"type": "ineq", "fun": slack, "jac": slack_jac}],
                   options={"maxiter": 60, "ftol": 1e-6})
    c, d = unpack(res.x if res.success and np.all(slack(res.x) >= -1e-7) else start)
    eig = np.linalg.eigvalsh(c)
    if eig.min() <= 0.0:
        return C0, d0
    return c, d


def grow_region(seed: FloatArray, segments: FloatArray, bounds: tuple[float, float, float, float],
                iterations: int = 2) -> Region:
    """An obstacle-free convex polygon around a seed segment (module docstring).

    Args:
        seed: ``(2, 2)`` the seed segment's ends, m; it must not cross an obstacle.
        segments: ``(S, 2, 2)`` obstacle segments, m.
        bounds: ``(xmin, xmax, ymin, ymax)`` of the map, m.
        iterations: Rounds of half-planes and ellipse.

    Returns:
        The :class:`Region` (its half-planes include the map's bounds).
    """
    seed = np.asarray(seed, dtype=float).reshape(2, 2)
    # the first round measures distances from the disc through the seed's ends: a thin
    # ellipse along the seed would see every obstacle as far across and cut the region
    # down to a band along the seed
    C = max(0.5 * math.hypot(*(seed[1] - seed[0])), SEED_WIDTH) * np.eye(2)
    d = seed.mean(axis=0)
    xmin, xmax, ymin, ymax = bounds
    box_a = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
    box_b = np.array([xmax, -xmin, ymax, -ymin])
    A, b = box_a, box_b
    for _ in range(max(1, iterations)):
        sa, sb = separating_halfplanes(C, d, segments, seed)
        A, b = np.vstack([sa, box_a]), np.concatenate([sb, box_b])
        C, d = inscribed_ellipse(A, b, C, d)
    return Region(A, b, C, d)
