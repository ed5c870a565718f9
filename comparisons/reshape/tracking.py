"""The tracking layer of ``reshape``: paths around static obstacles, and stuck robots.

Each robot drives to its target through the ``cbf`` filter (in
:mod:`~comparisons.reshape.controller`). Two things help it get there:

- :class:`Guidance`: when the straight line to the target passes too near a
  static obstacle, the robot heads instead for a waypoint on an A* path on the
  map inflated by its radius and margin;
- :class:`StuckMonitor`: a robot that stays still away from its target (two
  robots blocking each other in a gap, or a local minimum of the filtered
  field) has its command turned.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from comparisons.reshape.routes import cell_of
from dfcoa_opt.core.geometry import clip_segments_to_box, point_segment_distance, rotate
from dfcoa_opt.planning.astar import search
from dfcoa_opt.world.grid import OccupancyGrid

FloatArray = NDArray[np.float64]
#: Step of the free-segment test along a line, m.
PROBE = 0.1
#: Farthest a robot's guidance waypoint lies along its A* path, m.
GUIDANCE_REACH = 1.5
#: How far along its path around the other robots a stuck robot heads, m.
DETOUR_STEP = 0.6
#: A robot that stays within this of one point is still; one this near its target is not stuck, m.
STILL_RADIUS = 0.1
#: A robot freed from being stuck keeps its path around the others this long while
#: its straight line to the target still passes another robot, s.
FREED_MEMORY = 15.0


class Guidance:
    """Free-segment tests and A* paths on the static map.

    Args:
        grid: The static occupancy grid (its exact clearance is used).
        clearance: The inflation of the A* map and the clearance a robot's line
            must keep (``reshape``: robot radius plus margin), m.
        goal_reach: When a path's goal lies in a blocked cell of the inflated
            map (a slot nearer a wall than ``clearance``), the path ends at the
            nearest free cell within this distance instead; 0: no path, m.
        exact: The exact distance (m) of points ``(P, 2)`` to the static
            obstacles (:meth:`~dfcoa_opt.scenario.scenario.World.clearance`, the
            shapes the safety filter keeps off). When given, a cell is blocked
            when its centre's distance to them plus half a cell is short of
            ``clearance`` (along walls on cell edges, the grid's own measure).
            When None, the map is the grid inflated from its cell centres, which
            lets a path through gaps up to about a cell narrower (a disc's edge
            lies up to a cell beyond its outermost occupied centre).
    """

    def __init__(self, grid: OccupancyGrid, clearance: float, goal_reach: float = 0.0,
                 exact: Callable[[FloatArray], FloatArray] | None = None) -> None:
        self.grid = grid
        self.clearance = clearance
        self.goal_reach = goal_reach
        if exact is None:
            self.inflated = grid.inflate(clearance)
        else:
            face = exact(grid.cell_centers().reshape(-1, 2)).reshape(grid.shape)
            near = face + 0.5 * grid.cell_size < clearance
            self.inflated = OccupancyGrid(grid.occupied | near, grid.resolution, grid.origin)

    def free(self, a: FloatArray, b: FloatArray, clearance: float) -> bool:
        """Whether the segment ``[a, b]`` keeps ``clearance`` (m) from every static obstacle.

        The distances are capped at ``clearance`` itself: the answer is the same,
        and the exact search stops within ``clearance`` of each probe (with the
        default 10 m cap it scanned up to 10 m around each one on open maps).
        """
        return bool(self.free_many(a[None], b[None], clearance)[0])

    def free_many(self, a: FloatArray, b: FloatArray, clearance: float) -> NDArray[np.bool_]:
        """:meth:`free` of every segment ``[a_k, b_k]`` (``(K, 2)`` each, m): one distance call.

        Each segment is probed every ``PROBE`` m, ends included, as :meth:`free`
        does; the probes of all segments go to the clearance kernel at once.
        """
        if len(a) == 0:
            return np.zeros(0, dtype=bool)
        # every occupied cell lies in the map: beyond it by more than ``clearance`` a probe
        # is free, so only the part of a segment inside that margin is probed (an
        # estimate far off the map would otherwise take a probe every PROBE m of the way)
        x0, x1, y0, y1 = self.grid.extent
        a, b, meets = clip_segments_to_box(a, b, (x0 - clearance, y0 - clearance,
                                                  x1 + clearance, y1 + clearance))
        if not meets.all():
            out = np.ones(len(a), dtype=bool)
            out[meets] = self.free_many(a[meets], b[meets], clearance)
            return out
        d = b - a
        counts = [max(2, int(math.ceil(math.hypot(dx, dy) / PROBE)) + 1)
                  for dx, dy in d.tolist()]
        frac = np.concatenate([_unit(c) for c in counts])
        pts = np.repeat(a, counts, axis=0) + frac[:, None] * np.repeat(d, counts, axis=0)
        ok = self.grid.clearance(pts, cap=clearance) >= clearance
        return np.logical_and.reduceat(ok, np.cumsum([0, *counts[:-1]]))

    def path(self, a: FloatArray, b: FloatArray, blocked: NDArray[np.bool_] | None = None,
             reach: float = 0.0) -> FloatArray | None:
        """Cell centres (m) of an A* path from ``a`` to ``b`` on the inflated map, or None.

        Args:
            a: Start, m.
            b: Goal, m.
            blocked: The cells to avoid, when not the inflated map's.
            reach: When ``a``'s cell is blocked, the path starts from the nearest
                free cell within this distance (a robot already nearer another
                than the path keeps), m.
        """
        grid = self.inflated
        occ = grid.occupied if blocked is None else blocked
        ca, cb = cell_of(grid, a), cell_of(grid, b)
        if not (grid.in_bounds(*ca) and grid.in_bounds(*cb)):
            return None
        if occ[cb]:  # a goal near a wall: to the nearest free cell within goal_reach
            near = (_nearest_free(occ, cb, int(math.ceil(self.goal_reach / grid.cell_size)))
                    if self.goal_reach > 0.0 else None)
            if near is None:
                return None
            cb = near
        if occ[ca]:
            near = _nearest_free(occ, ca, int(math.ceil(reach / grid.cell_size)))
            if near is None:
                return None
            ca = near
        res = search(occ, ca, cb)
        if not res.found or len(res.cells) < 2:
            return None
        cells = np.asarray(res.cells)
        return np.column_stack([grid.origin[0] + (cells[:, 1] + 0.5) * grid.cell_size,
                                grid.origin[1] + (cells[:, 0] + 0.5) * grid.cell_size])

    def point_along(self, start: FloatArray, goal: FloatArray, reach: float) -> FloatArray:
        """The point ``reach`` m along an A* path to ``goal``; ``goal`` when there is none.

        The leader's path may cross obstacles (the ``straight`` planner through a
        clutter field): the formation then heads around them along this path.
        """
        pts = self.path(start, goal)
        if pts is None:
            return goal
        along = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
        return pts[min(int(np.searchsorted(along, reach)), len(pts) - 1)]

    def waypoints(self, pos: FloatArray, targets: FloatArray,
                  stuck: NDArray[np.intp] | None = None, keep: float = 0.0,
                  freed: NDArray[np.intp] | None = None) -> dict[int, FloatArray]:
        """A waypoint for each robot whose straight line to its target is blocked.

        The farthest point of its A* path within ``GUIDANCE_REACH`` that the
        robot sees with the clearance (pure pursuit on the path): a point at a
        fixed distance could sit behind a corner, where the safety filter stops
        a robot heading straight at it. A ``stuck`` robot plans around the
        other robots too (every point within ``keep`` of another robot's centre
        is an obstacle) and heads ``DETOUR_STEP`` along that path: a robot
        settled on its slot does not make way. A ``freed`` robot (stuck until
        lately) keeps that path while its straight line to the target passes
        within ``keep`` of another robot: otherwise, once moving, it would drive
        straight back into the pocket it left.

        Args:
            pos: ``(N, 2)`` robot positions, m.
            targets: ``(N, 2)`` their targets, m.
            stuck: Indices of stuck robots.
            keep: Distance a stuck robot's path keeps from the other robots'
                centres: at least the safety filter's pair distance, so that the
                path does not lead into a gap the filter will not let it through, m.
            freed: Indices of robots stuck until lately.

        Returns:
            Robot index -> ``(2,)`` waypoint, m (robots with a free line, or no
            path, are left out).
        """
        out: dict[int, FloatArray] = {}
        reach = int(round(GUIDANCE_REACH / self.inflated.cell_size))
        step = int(round(DETOUR_STEP / self.inflated.cell_size))
        around = set(() if stuck is None else stuck.tolist())
        for i in (() if freed is None else freed.tolist()):
            gap = point_segment_distance(pos, pos[i], targets[i])
            gap[i] = np.inf  # its own centre
            if np.any(gap < keep):
                around.add(i)
        for i in sorted(around):
            others = np.delete(pos, i, axis=0)
            pts = self.path(pos[i], targets[i], self._with_robots(others, keep), reach=keep)
            if pts is not None:
                out[int(i)] = pts[min(len(pts) - 1, step)]
        clear = self.free_many(pos, targets, self.clearance)
        for i in range(len(pos)):
            if i in out or clear[i]:
                continue
            pts = self.path(pos[i], targets[i])
            if pts is None:
                continue
            out[i] = pts[1]
            ahead = pts[reach:0:-1]  # the farthest first
            seen = self.free_many(np.broadcast_to(pos[i], ahead.shape), ahead, self.clearance)
            if seen.any():
                out[i] = ahead[int(np.argmax(seen))]
        return out


    def _with_robots(self, centres: FloatArray, radius: float) -> NDArray[np.bool_]:
        """The inflated map with every cell within ``radius`` of a centre blocked too."""
        g = self.inflated
        occ = g.occupied.copy()
        h = g.cell_size
        span = int(math.ceil(radius / h)) + 1
        for c in centres:
            row, col = cell_of(g, c)
            r0, r1 = max(row - span, 0), min(row + span + 1, occ.shape[0])
            c0, c1 = max(col - span, 0), min(col + span + 1, occ.shape[1])
            if r0 >= r1 or c0 >= c1:
                continue
            ys = g.origin[1] + (np.arange(r0, r1) + 0.5) * h
            xs = g.origin[0] + (np.arange(c0, c1) + 0.5) * h
            occ[r0:r1, c0:c1] |= np.hypot(xs[None] - c[0], ys[:, None] - c[1]) <= radius
        return occ


@functools.lru_cache(maxsize=256)
def _unit(steps: int) -> FloatArray:
    """``np.linspace(0, 1, steps)`` (read-only, cached: the probes' fractions)."""
    out = np.linspace(0.0, 1.0, steps)
    out.setflags(write=False)
    return out


def _nearest_free(blocked: NDArray[np.bool_], cell: tuple[int, int],
                  span: int) -> tuple[int, int] | None:
    """The free cell nearest ``cell`` within ``span`` cells (Euclidean), or None."""
    row, col = cell
    r0, r1 = max(row - span, 0), min(row + span + 1, blocked.shape[0])
    c0, c1 = max(col - span, 0), min(col + span + 1, blocked.shape[1])
    rows, cols = np.nonzero(~blocked[r0:r1, c0:c1])
    if rows.size == 0:
        return None
    k = int(np.argmin((rows + r0 - row) ** 2 + (cols + c0 - col) ** 2))
    return int(rows[k] + r0), int(cols[k] + c0)


class StuckMonitor:
    """Turns the command of robots stuck away from their targets.

    A robot is stuck when it has stayed within ``STILL_RADIUS`` of one point
    for ``after`` s while more than ``STILL_RADIUS`` from its target. Its
    command is turned by ``angle`` counter-clockwise, and by one ``angle`` more
    every further ``after`` s it stays still: the safety filter returns zero
    when the command points into the corner its rows make (a disc on one side,
    a robot on the other), and only a command far enough round leaves it.
    Turning every stuck robot the same way sends two that block each other
    around each other.

    One monitor serves every run of a batch: row ``env * N + i`` is robot
    ``i`` of run ``env``, and every row is updated from its own values alone.

    Args:
        start: ``(R, 2)`` initial positions of every row, m.
        after: Time still before a robot counts as stuck, s.
        angle: Turn of a stuck robot's command, rad (counter-clockwise).

    Attributes:
        turned: ``(K,)`` True for each row of the latest :meth:`turn` whose command was turned.
    """

    def __init__(self, start: FloatArray, after: float, angle: float) -> None:
        self.anchor = np.array(start, dtype=float)
        self.since = np.zeros(len(self.anchor))
        self.left = np.full(len(self.anchor), -np.inf)
        self.after = after
        self.angle = angle
        self.turned = np.zeros(0, dtype=bool)

    def stuck(self, t: float, rows: slice | None = None) -> NDArray[np.intp]:
        """Indices of the robots still for ``after`` s or more (their targets unchecked).

        Args:
            t: Time, s.
            rows: Only these rows (one run of a batch), indices relative to its start.
        """
        since = self.since if rows is None else self.since[rows]
        return np.flatnonzero(t - since >= self.after)

    def freed(self, t: float, rows: slice | None = None) -> NDArray[np.intp]:
        """Robots that got moving again from being stuck less than ``FREED_MEMORY`` s ago.

        Args:
            t: Time, s.
            rows: Only these rows (one run of a batch), indices relative to its start.
        """
        left = self.left if rows is None else self.left[rows]
        return np.flatnonzero(t - left < FREED_MEMORY)

    def restart(self, t: float, rows: NDArray[np.intp]) -> None:
        """Start the still clock of ``rows`` again at ``t`` (s): their targets changed.

        A robot given a new target is not stuck on it yet, so its command is not
        turned until it has stood ``after`` s on the new one.
        """
        self.since[rows] = t

    def turn(self, t: float, ids: NDArray[np.intp], pos: FloatArray, target: FloatArray,
             u: FloatArray) -> tuple[FloatArray, int]:
        """Commands with the stuck robots' turned, and how many were turned.

        Args:
            t: Time, s.
            ids: ``(K,)`` the monitor's row of each command (robot indices in one run).
            pos: ``(K, 2)`` positions, m.
            target: ``(K, 2)`` targets, m.
            u: ``(K, 2)`` velocity commands, m/s.
        """
        moved = np.hypot(*(pos - self.anchor[ids]).T) > STILL_RADIUS
        freed = moved & (t - self.since[ids] >= self.after)
        self.left[ids[freed]] = t
        self.anchor[ids[moved]] = pos[moved]
        self.since[ids[moved]] = t
        periods = np.floor((t - self.since[ids]) / self.after)
        stuck = (periods >= 1) & (np.hypot(*(target - pos).T) > STILL_RADIUS)
        self.turned = stuck
        if not stuck.any():
            return u, 0
        out = u.copy()
        out[stuck] = rotate(u[stuck], self.angle * periods[stuck])
        return out, int(stuck.sum())
