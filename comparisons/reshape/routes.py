"""Routes for a whole formation through the static map: its configuration space per scale.

A formation of template offsets ``o_j`` (relative to its centre, m) at scale
``s`` and heading ``psi`` overlaps an obstacle when its centre ``c`` has some
slot ``c + s R(psi) o_j`` within ``rho`` (robot radius plus margin) of an
occupied cell. On the occupancy grid this set -- the formation's
configuration-space obstacle for translations -- is the union over slots of
the one-disc obstacle ``{distance field <= rho}`` shifted by each slot's offset
rounded to whole cells (so ``rho`` carries half a cell diagonal more). One
boolean OR per distinct offset: about 10 ms for N = 100 on a 400 x 600 grid,
computed once per (scale, heading bin) and cached, since the map is static.

A* (:func:`dfcoa_opt.planning.astar.search`) on that set gives a route for the
centre along which the whole formation, rigid, stays clear of every static
obstacle (moving ones are left to the tracking layer's safety filter). A
shortest route hugs the obstacles, and robots that lag behind their slots cut
its corners, so the route is searched first with ``clearance`` m more
(``rho + clearance``), and only when that finds none with ``rho``. A start
or goal inside the set is moved to the nearest free cell. A formation
with one slot at the origin is a single robot: the route of a column that
follows it in single file.

A* without corner cutting reaches exactly the 4-connected free component of its
start, so a goal in another component is known to be unreachable without a
search: the components of each set are labelled once, and such a search (the
costliest kind: it expands every cell it can reach) is skipped with the same
answer.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.planning.astar import search
from dfcoa_opt.world.grid import OccupancyGrid

FloatArray = NDArray[np.float64]
#: Headings are quantised to this many bins over a turn (22.5 deg each).
HEADING_BINS = 16


@dataclass(frozen=True)
class Route:
    """A route for the formation's centre.

    Attributes:
        points: ``(P, 2)`` cell centres along the route, m (P >= 1).
        arc: ``(P,)`` arc length at each point, m.
    """

    points: FloatArray
    arc: FloatArray

    @property
    def length(self) -> float:
        """Total length, m."""
        return float(self.arc[-1])

    def project(self, p: FloatArray) -> float:
        """Arc length (m) of the route point nearest ``p``."""
        return float(self.arc[int(np.argmin(np.sum((self.points - p) ** 2, axis=1)))])

    def distance(self, p: FloatArray) -> float:
        """Distance (m) from ``p`` to the nearest route point."""
        return float(np.sqrt(np.min(np.sum((self.points - p) ** 2, axis=1))))

    def front(self, points: FloatArray, within: float, default: float) -> float:
        """Arc length (m) of the farthest projection of ``points`` ``(N, 2)`` within ``within``.

        Only points within ``within`` (m) of the route count; ``default`` when
        none does. ``reshape_passage`` leads its column from its front robot:
        a column placed around its centroid stands still where the route bends
        back, since the centroid of its targets is the centroid it was placed
        from.
        """
        near = [self.project(p) for p in points if self.distance(p) <= within]
        return max(near) if near else default

    def along(self, arcs: FloatArray) -> FloatArray:
        """``(K, 2)`` points at arc lengths ``arcs`` (m); before the start, straight back.

        :meth:`point_at` of every arc length, in one interpolation per axis.
        """
        arcs = np.asarray(arcs, dtype=float)
        s = np.minimum(np.maximum(arcs, 0.0), self.length)
        pts = np.column_stack([np.interp(s, self.arc, self.points[:, 0]),
                               np.interp(s, self.arc, self.points[:, 1])])
        behind = arcs < 0.0
        if behind.any():
            d = self.points[min(1, len(self.points) - 1)] - self.points[0]
            n = float(np.hypot(*d))
            u = d / n if n > 0 else np.array([1.0, 0.0])
            pts[behind] = self.points[0] + arcs[behind, None] * u
        return pts

    def point_at(self, s: float) -> FloatArray:
        """The point at arc length ``s`` (m), linearly interpolated, clamped to the ends."""
        s = min(max(s, 0.0), self.length)
        return np.array([np.interp(s, self.arc, self.points[:, 0]),
                         np.interp(s, self.arc, self.points[:, 1])])


def heading_bin(psi: float) -> int:
    """Index of the heading bin nearest ``psi`` (rad)."""
    return int(round(psi / (2.0 * math.pi / HEADING_BINS))) % HEADING_BINS


def bin_heading(k: int) -> float:
    """Centre heading (rad) of bin ``k``."""
    return 2.0 * math.pi * k / HEADING_BINS


def cell_of(grid: OccupancyGrid, p: FloatArray) -> tuple[int, int]:
    """``grid.world_to_cell`` of one point ``(2,)`` (m), as ``(row, col)``.

    The same arithmetic on Python floats, without the array call's overhead
    (about 25 us a point); a non-finite point goes to ``world_to_cell``.
    """
    x, y = float(p[0]), float(p[1])
    if not (math.isfinite(x) and math.isfinite(y)):
        row, col = grid.world_to_cell(np.array([x, y]))
        return int(row), int(col)
    h, w = grid.shape
    col = math.floor((x - grid.origin[0]) * grid.resolution)
    row = math.floor((y - grid.origin[1]) * grid.resolution)
    return min(max(row, -1), h), min(max(col, -1), w)


def cells_of(grid: OccupancyGrid, points: FloatArray) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """``grid.world_to_cell`` of finite points ``(K, 2)`` (m): the same arithmetic, less overhead.

    Non-finite points go to ``world_to_cell`` (its NaN handling).
    """
    p = np.asarray(points, dtype=float)
    if not np.isfinite(p).all():
        return grid.world_to_cell(p)
    h, w = grid.shape
    col = np.floor((p[..., 0] - grid.origin[0]) * grid.resolution)
    row = np.floor((p[..., 1] - grid.origin[1]) * grid.resolution)
    return (np.minimum(np.maximum(row, -1.0), h).astype(np.intp),
            np.minimum(np.maximum(col, -1.0), w).astype(np.intp))


class ConfigurationSpace:
    """Cells where a formation's centre would put a slot on an obstacle (module docstring).

    Args:
        grid: The static occupancy grid.
        offsets: ``(N, 2)`` template offsets relative to the formation's centre, m.
        rho: Robot radius plus margin, m.
        clearance: Extra distance that routes keep where they can, m.
    """

    def __init__(self, grid: OccupancyGrid, offsets: FloatArray, rho: float,
                 clearance: float = 0.0) -> None:
        self.grid = grid
        self.offsets = np.asarray(offsets, float)
        half = 0.5 * math.sqrt(2.0) * grid.cell_size
        self._disc = {False: grid.distance_field <= rho + half,
                      True: grid.distance_field <= rho + clearance + half}
        self._blocked: dict[tuple[float, int, bool], NDArray[np.bool_]] = {}
        self._nearest: dict[tuple[float, int, bool], NDArray[np.intp]] = {}
        self._labels: dict[tuple[float, int, bool], tuple[NDArray[np.int32], int]] = {}

    def blocked(self, scale: float, k: int, wide: bool = False) -> NDArray[np.bool_]:
        """``(H, W)`` True where the centre cannot be, at ``scale`` and heading bin ``k``.

        ``wide``: with the extra ``clearance``.
        """
        key = (round(scale, 9), k, wide)
        if key not in self._blocked:
            psi = bin_heading(k)
            c, s = math.cos(psi), math.sin(psi)
            off = scale * self.offsets @ np.array([[c, s], [-s, c]])
            cells = np.unique(np.rint(off / self.grid.cell_size).astype(np.intp), axis=0)
            out = np.zeros(self.grid.shape, dtype=bool)
            for dc, dr in cells:
                _shift_or(out, self._disc[wide], int(dr), int(dc))
            out.setflags(write=False)
            self._blocked[key] = out
        return self._blocked[key]

    def free_at(self, points: FloatArray, scale: float, k: int) -> NDArray[np.bool_]:
        """Whether the formation fits with its centre at each of ``points`` ``(P, 2)``, m."""
        row, col = cells_of(self.grid, points)
        ok = self.grid.in_bounds(row, col)
        out = np.zeros(len(row), dtype=bool)
        out[ok] = ~self.blocked(scale, k)[row[ok], col[ok]]
        return out

    def route(self, start: FloatArray, goal: FloatArray, scale: float, k: int) -> Route | None:
        """A* route of the centre from ``start`` to ``goal`` (m), or None when there is none.

        With the extra clearance when it finds one, else without.
        """
        return (self._search(start, goal, scale, k, True)
                or self._search(start, goal, scale, k, False))

    def _search(self, start: FloatArray, goal: FloatArray, scale: float, k: int,
                wide: bool) -> Route | None:
        key = (round(scale, 9), k, wide)
        blocked = self.blocked(scale, k, wide)
        labels, count = self._components(key, blocked)
        if count == 0:  # every cell blocked
            return None
        a, b = self._snap(start, blocked, key), self._snap(goal, blocked, key)
        if a == b:
            pts = self._centres(np.array([a]))
            return Route(pts, np.zeros(1))
        if labels[a] != labels[b]:  # A* would expand all of a's component in vain
            return None
        res = search(blocked, a, b)
        if not res.found:
            return None
        pts = self._centres(np.asarray(res.cells))
        arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
        return Route(pts, arc)

    def _snap(self, p: FloatArray, blocked: NDArray[np.bool_],
              key: tuple[float, int, bool]) -> tuple[int, int]:
        """The cell of ``p``, or the nearest cell not ``blocked`` (cached by ``key``)."""
        row, col = cell_of(self.grid, p)
        h, w = self.grid.shape
        row, col = min(max(row, 0), h - 1), min(max(col, 0), w - 1)
        if not blocked[row, col]:
            return row, col
        if key not in self._nearest:
            from scipy import ndimage  # here: ~0.2 s to import, only for replanning

            self._nearest[key] = ndimage.distance_transform_edt(
                blocked, return_distances=False, return_indices=True)
        near = self._nearest[key]
        return int(near[0, row, col]), int(near[1, row, col])

    def _components(self, key: tuple[float, int, bool],
                    blocked: NDArray[np.bool_]) -> tuple[NDArray[np.int32], int]:
        """The 4-connected components of the cells not ``blocked``, and how many (cached)."""
        if key not in self._labels:
            from scipy import ndimage

            labels, count = ndimage.label(~blocked)  # the default structure: 4-connected
            self._labels[key] = labels, int(count)
        return self._labels[key]

    def _centres(self, cells: NDArray[np.intp]) -> FloatArray:
        g = self.grid
        return np.column_stack([g.origin[0] + (cells[:, 1] + 0.5) * g.cell_size,
                                g.origin[1] + (cells[:, 0] + 0.5) * g.cell_size])


def _shift_or(out: NDArray[np.bool_], disc: NDArray[np.bool_], dr: int, dc: int) -> None:
    """``out[r, c] |= disc[r + dr, c + dc]``, with cells beyond the grid blocked."""
    h, w = disc.shape
    r0, r1 = max(0, -dr), min(h, h - dr)
    c0, c1 = max(0, -dc), min(w, w - dc)
    if r0 >= r1 or c0 >= c1:
        out[:] = True
        return
    out[r0:r1, c0:c1] |= disc[r0 + dr:r1 + dr, c0 + dc:c1 + dc]
    out[:r0] = True
    out[r1:] = True
    out[:, :c0] = True
    out[:, c1:] = True


class RoutePlanner:
    """The formation's route when the leader's path is blocked at every scale.

    Args:
        cspace: Configuration space of the scenario's formation.
        single: That of one robot (single file), or None when single file is
            not a template.
        scales: Scales tried, largest first.
        column_length: Length of the single-file column, m.
        goal: ``(2,)`` the formation's centre at the goal, m.
        detour: A larger scale's route may be this fraction longer than the
            quickest passage.
        period: Time between two searches while the formation stays on its
            route, s.
        leave: Distance from the route beyond which it is searched again, m.
    """

    def __init__(self, cspace: ConfigurationSpace, single: ConfigurationSpace | None,
                 scales: FloatArray, column_length: float, goal: FloatArray, detour: float,
                 period: float, leave: float) -> None:
        self.cspace, self.single = cspace, single
        self.scales = [float(s) for s in scales]
        self.column_length, self.goal = column_length, goal
        self.detour, self.period, self.leave = detour, period, leave
        self.way: Route | None = None
        self.scale: float | None = None  # None: single file
        self._bin, self._time = -1, -math.inf

    def clear(self) -> None:
        """Forget the route (the leader's path is open again)."""
        self.way = None

    def update(self, t: float, centroid: FloatArray, k: int) -> tuple[Route | None, float | None]:
        """The route and its scale, searched again when due, left or turned (bin ``k``)."""
        if (self.way is None or k != self._bin or t >= self._time + self.period - 1e-9
                or self.way.distance(centroid) > self.leave):
            self.way, self.scale = self.best(centroid, k)
            self._bin, self._time = k, t
        return self.way, self.scale

    def best(self, centroid: FloatArray, k: int) -> tuple[Route | None, float | None]:
        """The route of the largest scale within ``detour`` of the quickest passage.

        The quickest passage is the shortest route of any scale, or single file,
        whose length counts the column's too (the last robot must pass). The
        current scale is kept while its route is within ``detour`` of that limit
        again (hysteresis: a change of scale moves every robot).

        Returns:
            ``(route, scale)``; the single-file route with scale None when it is
            quicker than every scale; ``(None, None)`` when nothing gets through.
        """
        single = (self.single.route(centroid, self.goal, 1.0, k)
                  if self.single is not None else None)
        ways = [(sc, w) for sc in self.scales
                if (w := self.cspace.route(centroid, self.goal, sc, k)) is not None]
        column = math.inf if single is None else single.length + self.column_length
        limit = (1.0 + self.detour) * min([w.length for _, w in ways] + [column])
        for scale, way in ways:  # the current scale while it qualifies, else the largest
            if scale == self.scale and way.length <= (1.0 + self.detour) * limit:
                return way, scale
        for scale, way in ways:
            if way.length <= limit + 1e-9:
                return way, scale
        return single, None
