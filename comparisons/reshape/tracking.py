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

import math

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.geometry import rotate
from dfcoa_opt.planning.astar import search
from dfcoa_opt.world.grid import OccupancyGrid

FloatArray = NDArray[np.float64]
#: Step of the free-segment test along a line, m.
PROBE = 0.1
#: Farthest a robot's guidance waypoint lies along its A* path, m.
GUIDANCE_REACH = 1.5
#: A robot that stays within this of one point is still; one this near its target is not stuck, m.
STILL_RADIUS = 0.1


class Guidance:
    """Free-segment tests and A* paths on the static map.

    Args:
        grid: The static occupancy grid (its exact clearance is used).
        clearance: Robot radius plus margin: the inflation of the A* map and the
            clearance a robot's line must keep, m.
    """

    def __init__(self, grid: OccupancyGrid, clearance: float) -> None:
        self.grid = grid
        self.clearance = clearance
        self.inflated = grid.inflate(clearance)

    def free(self, a: FloatArray, b: FloatArray, clearance: float) -> bool:
        """Whether the segment ``[a, b]`` keeps ``clearance`` (m) from every static obstacle."""
        steps = max(2, int(math.ceil(math.hypot(*(b - a)) / PROBE)) + 1)
        pts = a + np.linspace(0.0, 1.0, steps)[:, None] * (b - a)
        return bool(np.all(self.grid.clearance(pts) >= clearance))

    def path(self, a: FloatArray, b: FloatArray) -> FloatArray | None:
        """Cell centres (m) of an A* path from ``a`` to ``b`` on the inflated map, or None."""
        grid = self.inflated
        ca = tuple(int(v) for v in grid.world_to_cell(a))
        cb = tuple(int(v) for v in grid.world_to_cell(b))
        if not (grid.in_bounds(*ca) and grid.in_bounds(*cb)) or grid.occupied[ca] \
                or grid.occupied[cb]:
            return None
        res = search(grid.occupied, ca, cb)
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

    def waypoints(self, pos: FloatArray, targets: FloatArray) -> dict[int, FloatArray]:
        """A waypoint for each robot whose straight line to its target is blocked.

        The farthest point of its A* path within ``GUIDANCE_REACH`` that the
        robot sees with the clearance (pure pursuit on the path): a point at a
        fixed distance could sit behind a corner, where the safety filter stops
        a robot heading straight at it.

        Args:
            pos: ``(N, 2)`` robot positions, m.
            targets: ``(N, 2)`` their targets, m.

        Returns:
            Robot index -> ``(2,)`` waypoint, m (robots with a free line, or no
            path, are left out).
        """
        out: dict[int, FloatArray] = {}
        reach = int(round(GUIDANCE_REACH / self.inflated.cell_size))
        for i in range(len(pos)):
            if self.free(pos[i], targets[i], self.clearance):
                continue
            pts = self.path(pos[i], targets[i])
            if pts is None:
                continue
            out[i] = pts[1]
            for p in pts[reach:0:-1]:
                if self.free(pos[i], p, self.clearance):
                    out[i] = p
                    break
        return out


class StuckMonitor:
    """Turns the command of robots stuck away from their targets.

    A robot is stuck when it has stayed within ``STILL_RADIUS`` of one point
    for ``after`` s while more than ``STILL_RADIUS`` from its target. Turning
    every stuck robot the same way (counter-clockwise) sends two that block
    each other around each other.

    Args:
        start: ``(N, 2)`` initial positions, m.
        after: Time still before a robot counts as stuck, s.
        angle: Turn of a stuck robot's command, rad (counter-clockwise).
    """

    def __init__(self, start: FloatArray, after: float, angle: float) -> None:
        self.anchor = np.array(start, dtype=float)
        self.since = np.zeros(len(self.anchor))
        self.after = after
        self.angle = angle

    def turn(self, t: float, ids: NDArray[np.intp], pos: FloatArray, target: FloatArray,
             u: FloatArray) -> tuple[FloatArray, int]:
        """Commands with the stuck robots' turned, and how many were turned.

        Args:
            t: Time, s.
            ids: ``(N,)`` robot indices of the rows.
            pos: ``(N, 2)`` positions, m.
            target: ``(N, 2)`` targets, m.
            u: ``(N, 2)`` velocity commands, m/s.
        """
        moved = np.hypot(*(pos - self.anchor[ids]).T) > STILL_RADIUS
        self.anchor[ids[moved]] = pos[moved]
        self.since[ids[moved]] = t
        stuck = ((t - self.since[ids] >= self.after)
                 & (np.hypot(*(target - pos).T) > STILL_RADIUS))
        if not stuck.any():
            return u, 0
        out = u.copy()
        out[stuck] = rotate(u[stuck], self.angle)
        return out, int(stuck.sum())
