"""Who touched what at a logged instant: the contacts figures mark.

A :class:`~dfcoa_opt.sim.log.RunLog` counts the contacts of each instant
(``robot_contacts``, ``obstacle_contacts``, ``dynamic_contacts``); when a run
has one is :func:`dfcoa_opt.metrics.outcome.first_contact_time`. This module finds
*which* robots and obstacles touched, from the logged positions and
clearances, with the simulator's contact rules: two robots whose centres are
closer than two radii, a robot whose clearance to the static map is below its
radius, a robot overlapping a moving disc. A count of the log that the
geometry does not explain (a log of rounded positions) is given to the
nearest candidate of its kind, so every counted kind gets a contact.

Coordinates are world metres, times seconds. Nothing here changes a metric:
figures only.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from dfcoa_opt.metrics.outcome import contact_steps

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from dfcoa_opt.sim.log import RunLog
    from dfcoa_opt.world.grid import OccupancyGrid

#: Robot radius assumed for logs that do not record it (``RobotSpec`` default), m.
DEFAULT_RADIUS = 0.2
#: Contact kinds: another robot, the static map, a moving disc.
KINDS = ("robot", "obstacle", "moving")
#: Most contacts named in a description; the rest are counted.
MAX_NAMED = 2


@dataclass(frozen=True)
class Contact:
    """One contact at one instant.

    Attributes:
        kind: One of :data:`KINDS`.
        robot: The robot's index.
        other: The other robot's index (``robot``), the moving disc's (``moving``), -1 (static).
        point: Where they touch, ``(x, y)`` in m: the middle of the overlap (robots,
            moving discs), the nearest point of the nearest occupied cell when the
            map is known, else the robot's centre (static).
    """

    kind: str
    robot: int
    other: int
    point: tuple[float, float]

    def describe(self) -> str:
        """In words: ``"robot 0 and robot 2"``, ``"robot 3 and a static obstacle"``, ...

        A moving disc is ``"moving obstacle j"``.
        """
        what = {"robot": f"robot {self.other}", "obstacle": "a static obstacle",
                "moving": f"moving obstacle {self.other}"}[self.kind]
        return f"robot {self.robot} and {what}"


def robot_radius(log: RunLog) -> float:
    """The log's ``meta["robot_radius"]`` in m, :data:`DEFAULT_RADIUS` when it is missing."""
    return float(log.meta.get("robot_radius", DEFAULT_RADIUS))


def first_contact_step(log: RunLog) -> int | None:
    """Index of the first instant with a counted contact (None without contact)."""
    hit = np.flatnonzero(contact_steps(log))
    return int(hit[0]) if hit.size else None


def contacts_at(log: RunLog, k: int, grid: OccupancyGrid | None = None) -> list[Contact]:
    """The contacts of instant ``k``: the geometry's, then one per unexplained counted kind.

    Args:
        log: The run.
        k: The instant.
        grid: The run's map, to place static contacts on the obstacle (else at the robot).

    Returns:
        The contacts, robot-robot first, then static, then moving; within a kind by robot.
    """
    found = _geometric(log, k, grid)
    counts = {"robot": log.robot_contacts[k], "obstacle": log.obstacle_contacts[k],
              "moving": log.dynamic_contacts[k]}
    for kind in KINDS:
        if counts[kind] > 0 and not any(c.kind == kind for c in found):
            nearest = _nearest(log, k, kind, grid)
            found += [nearest] if nearest is not None else []
    return sorted(found, key=lambda c: (KINDS.index(c.kind), c.robot, c.other))


def describe(contacts: list[Contact]) -> str:
    """``"robot 0 and robot 2"``; past :data:`MAX_NAMED` contacts, ``"..., +3 more"``."""
    named = ", ".join(c.describe() for c in contacts[:MAX_NAMED])
    rest = len(contacts) - MAX_NAMED
    return f"{named}, +{rest} more" if rest > 0 else named


# ------------------------------------------------------------------ internals
def _geometric(log: RunLog, k: int, grid: OccupancyGrid | None) -> list[Contact]:
    """Every contact the positions and clearances of instant ``k`` show."""
    r = robot_radius(log)
    pos = np.asarray(log.pose[k, :, :2], dtype=float)
    out: list[Contact] = []
    if len(pos) > 1:
        d = np.linalg.norm(pos[:, None] - pos[None], axis=-1)
        for i, j in zip(*np.nonzero(np.triu(d < 2.0 * r, 1)), strict=True):
            out.append(_pair(pos, int(i), int(j)))
    for i in np.flatnonzero(np.asarray(log.clearance[k]) < r):
        out.append(_static(pos, int(i), r, grid))
    if len(log.dyn_radius):
        dyn, dyn_r = np.asarray(log.dyn_pos[k], dtype=float), np.asarray(log.dyn_radius)
        dd = np.linalg.norm(pos[:, None] - dyn[None], axis=-1)
        for i, j in zip(*np.nonzero(dd < r + dyn_r[None]), strict=True):
            out.append(_moving(pos, dyn, int(i), int(j), r, float(dyn_r[j])))
    return out


def _nearest(log: RunLog, k: int, kind: str, grid: OccupancyGrid | None) -> Contact | None:
    """The closest candidate of ``kind`` at instant ``k`` (a count the geometry missed)."""
    r = robot_radius(log)
    pos = np.asarray(log.pose[k, :, :2], dtype=float)
    if kind == "robot" and len(pos) > 1:
        d = np.linalg.norm(pos[:, None] - pos[None], axis=-1)
        np.fill_diagonal(d, np.inf)
        i, j = np.unravel_index(int(np.argmin(d)), d.shape)
        return _pair(pos, int(min(i, j)), int(max(i, j)))
    if kind == "obstacle" and len(pos):
        return _static(pos, int(np.argmin(log.clearance[k])), r, grid)
    if kind == "moving" and len(pos) and len(log.dyn_radius):
        dyn, dyn_r = np.asarray(log.dyn_pos[k], dtype=float), np.asarray(log.dyn_radius)
        gap = np.linalg.norm(pos[:, None] - dyn[None], axis=-1) - dyn_r[None]
        i, j = np.unravel_index(int(np.argmin(gap)), gap.shape)
        return _moving(pos, dyn, int(i), int(j), r, float(dyn_r[j]))
    return None


def _pair(pos: NDArray[np.float64], i: int, j: int) -> Contact:
    mid = 0.5 * (pos[i] + pos[j])
    return Contact("robot", i, j, (float(mid[0]), float(mid[1])))


def _moving(pos: NDArray[np.float64], dyn: NDArray[np.float64], i: int, j: int, r: float,
            dyn_r: float) -> Contact:
    """Robot ``i`` and disc ``j``: the point between the centres at ``r / (r + R)``."""
    p = pos[i] + (dyn[j] - pos[i]) * (r / (r + dyn_r))
    return Contact("moving", i, j, (float(p[0]), float(p[1])))


def _static(pos: NDArray[np.float64], i: int, r: float, grid: OccupancyGrid | None) -> Contact:
    """Robot ``i`` against the map: the nearest point of an occupied cell within ``2 r``."""
    p = pos[i]
    point = p
    if grid is not None:
        h = grid.cell_size
        reach = 2.0 * r + h
        (r0, r1), (c0, c1) = grid.world_to_cell(np.array([p - reach, p + reach]))
        r0, c0 = max(int(r0), 0), max(int(c0), 0)
        rows, cols = np.nonzero(grid.occupied[r0:int(r1) + 1, c0:int(c1) + 1])
        if rows.size:
            lo = np.column_stack((grid.origin[0] + (cols + c0) * h,
                                  grid.origin[1] + (rows + r0) * h))
            near = np.clip(p, lo, lo + h)  # nearest point of each cell square
            point = near[int(np.argmin(np.linalg.norm(near - p, axis=1)))]
    return Contact("obstacle", i, -1, (float(point[0]), float(point[1])))
