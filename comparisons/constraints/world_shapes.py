"""The static shapes of a batch's maps (every run's own map), all rows in one call.

A batch's runs share one map, except with a seeded clutter field (one map per
run). :class:`WorldShapes` holds the maps' discs and polygons end to end, and
:meth:`WorldShapes.nearest` gives every row (one robot's ``H`` linearisation
points) the ``M`` nearest shapes of its own map in one compiled call.

Each row's points go through the shared builder,
:func:`comparisons.constraints.geometry_kernels.nearest_kernel` (what
:meth:`StaticObstacles.nearest <comparisons.constraints.distance.StaticObstacles.nearest>`
runs), with only the discs that can be among the ``M`` nearest of one of its
points: with ``B`` the bounding box of the row's points, a disc ``(c, r)`` has
``delta >= dist(c, B) - r`` (``lb``) and ``delta <= maxdist(c, B) - r`` (``ub``)
at every point of ``B``, so the ``M``-th nearest shape of every point is at most
``T`` = the ``M``-th smallest ``ub``, and a disc with ``lb > T`` is never among
the ``M`` nearest (nor ties with them). The kernel keeps the first ``M`` shapes in
(distance, order) order, and the kept discs keep their order: its output is
that of the whole map, bit for bit. Polygons are all kept.
"""

from __future__ import annotations

from collections.abc import Sequence

import numba
import numpy as np
from numpy.typing import NDArray

from comparisons.constraints.distance import Nearest, StaticObstacles
from comparisons.constraints.geometry_kernels import nearest_kernel

FloatArray = NDArray[np.float64]
#: Distances (m) are compared with this much room for rounding in the disc bounds.
_ROOM = 1e-6


class WorldShapes:
    """The static shapes of the maps of a batch.

    Args:
        maps: One :class:`~comparisons.constraints.distance.StaticObstacles` per map.

    Attributes:
        maps: The maps, as given.
        discs: ``(C, 3)`` every map's discs, map after map (x m, y m, radius m).
        disc_ptr: ``(W + 1,)`` map ``w``'s discs are ``discs[disc_ptr[w]:disc_ptr[w + 1]]``.
        edge_a: ``(Q, V, 2)`` every map's polygon edge starts, m (padded to the
            longest polygon with zero-length edges at the last vertex, as
            :func:`dfcoa_opt.core.geometry.polygon_edges` pads).
        edge_b: ``(Q, V, 2)`` the edge ends, m.
        poly_ptr: ``(W + 1,)`` map ``w``'s polygons are ``edge_a[poly_ptr[w]:poly_ptr[w + 1]]``.
    """

    def __init__(self, maps: Sequence[StaticObstacles]) -> None:
        self.maps = list(maps)
        self.discs = np.ascontiguousarray(np.concatenate([m.discs for m in self.maps]))
        self.disc_ptr = np.cumsum([0, *(len(m.discs) for m in self.maps)]).astype(np.intp)
        width = max((m.edge_a.shape[1] for m in self.maps), default=0)
        padded = [_pad(m.edge_a, m.edge_b, width) for m in self.maps]
        self.edge_a = np.ascontiguousarray(np.concatenate([a for a, _ in padded]))
        self.edge_b = np.ascontiguousarray(np.concatenate([b for _, b in padded]))
        self.poly_ptr = np.cumsum([0, *(len(m.edge_a) for m in self.maps)]).astype(np.intp)

    def nearest(self, lin: FloatArray, count: int, reach: float,
                world: NDArray[np.intp] | None = None) -> Nearest:
        """The ``count`` nearest shapes of each point of each row, in the row's own map.

        Args:
            lin: ``(R, H, 2)`` points, one row per robot, m.
            count: Slots per point ``M``.
            reach: Shapes farther than this (signed distance) are masked out, m.
            world: ``(R,)`` the map of each row (None: map 0).

        Returns:
            :class:`~comparisons.constraints.distance.Nearest` of the ``R H``
            points (row after row), point by point ``StaticObstacles.nearest``
            of the row's map.
        """
        r, h = lin.shape[:2]
        points = np.ascontiguousarray(lin, dtype=float).reshape(r * h, 2)
        world = np.zeros(r, dtype=np.intp) if world is None else np.asarray(world, np.intp)
        q, normal = np.empty((r * h, count, 2)), np.empty((r * h, count, 2))
        delta, mask = np.empty((r * h, count)), np.empty((r * h, count), dtype=bool)
        if count == 0:  # (nearest_kernel needs a slot: it reads the last one)
            return Nearest(q, delta, normal, mask)
        _rows_kernel(points, h, world, self.discs, self.disc_ptr, self.edge_a, self.edge_b,
                     self.poly_ptr, float(reach), q, delta, normal, mask)
        return Nearest(q, delta, normal, mask)


def _pad(a: FloatArray, b: FloatArray, width: int) -> tuple[FloatArray, FloatArray]:
    """Polygon edges ``(Q, V, 2)`` padded to ``width`` with zero-length edges at the last vertex.

    The last vertex is the start of each polygon's last edge (its closing edge,
    or a padding edge already); :func:`dfcoa_opt.core.geometry.polygon_edges` pads so.
    """
    v = a.shape[1]
    if v == width:
        return a, b
    if not len(a):
        return np.zeros((0, width, 2)), np.zeros((0, width, 2))
    out_a, out_b = np.empty((len(a), width, 2)), np.empty((len(b), width, 2))
    out_a[:, :v], out_b[:, :v] = a, b
    out_a[:, v:] = out_b[:, v:] = a[:, v - 1:v]
    return out_a, out_b


@numba.njit(cache=True)
def _rows_kernel(points, h, world, discs, disc_ptr, edge_a, edge_b, poly_ptr, reach,
                 q, delta, normal, mask):  # pragma: no cover - numba
    """:func:`nearest_kernel` of each row's ``h`` points with the discs that can matter.

    Fills ``q``, ``delta``, ``normal``, ``mask`` (module docstring for the disc bounds).
    """
    count = delta.shape[1]
    most = 0
    for w in range(len(disc_ptr) - 1):
        most = max(most, disc_ptr[w + 1] - disc_ptr[w])
    kept = np.empty((most, 3))
    best = np.empty(count)  # the count smallest ub, ascending
    for row in range(points.shape[0] // h):
        w = world[row]
        lo, hi = row * h, (row + 1) * h
        d0, d1 = disc_ptr[w], disc_ptr[w + 1]
        use = discs[d0:d1]
        xmin, xmax = points[lo, 0], points[lo, 0]
        ymin, ymax = points[lo, 1], points[lo, 1]
        for i in range(lo + 1, hi):
            xmin, xmax = min(xmin, points[i, 0]), max(xmax, points[i, 0])
            ymin, ymax = min(ymin, points[i, 1]), max(ymax, points[i, 1])
        finite = np.isfinite(xmin) and np.isfinite(xmax) and np.isfinite(ymin) and \
            np.isfinite(ymax)
        if d1 - d0 > count and finite:
            found = 0
            for s in range(d0, d1):
                cx, cy, r = discs[s, 0], discs[s, 1], discs[s, 2]
                fx, fy = max(cx - xmin, xmax - cx), max(cy - ymin, ymax - cy)
                ub = np.sqrt(fx * fx + fy * fy) - r
                j = found
                if found < count:
                    found += 1
                elif ub >= best[count - 1]:
                    continue
                else:
                    j = count - 1
                while j > 0 and ub < best[j - 1]:
                    best[j] = best[j - 1]
                    j -= 1
                best[j] = ub
            top = best[count - 1] + _ROOM
            m = 0
            for s in range(d0, d1):
                cx, cy, r = discs[s, 0], discs[s, 1], discs[s, 2]
                dx = max(xmin - cx, 0.0, cx - xmax)
                dy = max(ymin - cy, 0.0, cy - ymax)
                if np.sqrt(dx * dx + dy * dy) - r <= top:
                    kept[m, 0], kept[m, 1], kept[m, 2] = cx, cy, r
                    m += 1
            use = kept[:m]
        nearest_kernel(points[lo:hi], use, edge_a[poly_ptr[w]:poly_ptr[w + 1]],
                       edge_b[poly_ptr[w]:poly_ptr[w + 1]], reach, q[lo:hi], delta[lo:hi],
                       normal[lo:hi], mask[lo:hi])
