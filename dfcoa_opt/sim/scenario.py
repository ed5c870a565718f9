"""The runtime scenario: the validated spec plus the built world and team."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.sim.schema import ScenarioSpec
from dfcoa_opt.world.dynamic import DynamicObstacles
from dfcoa_opt.world.grid import OccupancyGrid
from dfcoa_opt.world.shapes import Circle, Shape


@dataclass(frozen=True, eq=False)
class World:
    """Static grid, exact obstacle geometry and moving obstacles.

    Attributes:
        grid: Occupancy grid (map plus rasterised shapes).
        shapes: Exact static shapes (polygons, rectangles, circles), in file order.
        dynamic: Moving discs.
    """

    grid: OccupancyGrid
    shapes: tuple[Shape, ...]
    dynamic: DynamicObstacles

    @property
    def polygons(self) -> list[NDArray[np.float64]]:
        """Polygons and rectangles as ``(V, 2)`` counter-clockwise vertex arrays, m."""
        return [s.to_polygon().as_array() for s in self.shapes if not isinstance(s, Circle)]

    @property
    def circles(self) -> list[Circle]:
        """Static circular obstacles."""
        return [s for s in self.shapes if isinstance(s, Circle)]


@dataclass(frozen=True, eq=False)
class Scenario:
    """A loaded scenario, ready to simulate.

    Attributes:
        spec: The validated file contents.
        source: Path of the file (or ``"<dict>"``), used in messages.
        world: The built world.
        offsets: ``(N, 2)`` formation slot offsets in the leader frame, m.
        initial_pose: ``(N, 3)`` initial robot poses (m, m, rad).
        leader_heading: Initial leader heading, rad.
        leader_path: ``(P, 2)`` the leader's planned path, m.
    """

    spec: ScenarioSpec
    source: str
    world: World
    offsets: NDArray[np.float64]
    initial_pose: NDArray[np.float64]
    leader_heading: float
    leader_path: NDArray[np.float64]

    @property
    def name(self) -> str:
        """Scenario name."""
        return self.spec.name

    @property
    def n(self) -> int:
        """Number of robots."""
        return self.spec.team.n
