"""The runtime scenario: the validated spec plus the built world and team."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dfcoa_opt.core.geometry import point_segment_distance, points_in_polygon, wrap_angle
from dfcoa_opt.scenario.schema import ScenarioSpec
from dfcoa_opt.world.dynamic import DynamicObstacles
from dfcoa_opt.world.grid import OccupancyGrid
from dfcoa_opt.world.shape_clearance import shape_clearance
from dfcoa_opt.world.shapes import Circle, Shape


@dataclass(frozen=True, eq=False)
class World:
    """Static grid, exact obstacle geometry and moving obstacles.

    The static obstacles *are* the exact shapes plus the cells of the map file
    (``raster``); ``grid`` rasterises the shapes too (a cell touched by a shape
    is occupied) for the LiDAR and the planners. Contacts and clearances are
    measured by :meth:`clearance` against the exact shapes and the map cells,
    not against the rasterised shapes, which are up to a cell diagonal fatter.

    Attributes:
        grid: Occupancy grid (map plus rasterised shapes).
        shapes: Exact static shapes (polygons, rectangles, circles), in file order.
        dynamic: Moving discs.
        raster: Grid of the map file alone (``map_ascii``, ``map_image`` or ``map_yaml``);
            None without one.
        facts: The realised statistics of a generated world (``[world.generate]``,
            :class:`~dfcoa_opt.world.generate.Generated`); None otherwise.
    """

    grid: OccupancyGrid
    shapes: tuple[Shape, ...]
    dynamic: DynamicObstacles
    raster: OccupancyGrid | None = None
    facts: Mapping[str, Any] | None = None

    @cached_property
    def _edges(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Polygon edges ``(E, 2)`` starts and ends, m."""
        polys = self.polygons
        if not polys:
            return np.zeros((0, 2)), np.zeros((0, 2))
        return (np.concatenate(polys), np.concatenate([np.roll(v, -1, axis=0) for v in polys]))

    @cached_property
    def _boxes(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Bounding boxes ``(Q, 2)`` lower and upper corners of the polygons, m."""
        return (np.array([v.min(axis=0) for v in self.polygons]).reshape(-1, 2),
                np.array([v.max(axis=0) for v in self.polygons]).reshape(-1, 2))

    @cached_property
    def _kernel_args(self) -> tuple[NDArray, ...]:
        """Flat polygon edges, their offsets, boxes and circles for :func:`shape_clearance`."""
        a, b = self._edges
        sizes = [len(v) for v in self.polygons]
        start = np.concatenate(([0], np.cumsum(sizes))).astype(np.int64)
        lo, hi = self._boxes
        circles = self.circles
        centres = np.array([c.center for c in circles], dtype=float).reshape(-1, 2)
        radii = np.array([c.radius for c in circles], dtype=float)
        return (np.ascontiguousarray(a), np.ascontiguousarray(b), start,
                np.ascontiguousarray(lo), np.ascontiguousarray(hi), centres, radii)

    def clearance(self, points: ArrayLike, cap: float = 10.0) -> NDArray[np.float64]:
        """Distance (m) from points to the nearest static obstacle; 0 inside one.

        Exact for the shapes (polygon edges, circles) and for the map cells. The
        shapes go through the numba kernel :func:`shape_clearance`, bit-identical
        to the numpy formulas of :meth:`clearance_reference`.

        Args:
            points: ``(P, 2)`` world points, m.
            cap: Larger distances are reported as ``cap``, m.
        """
        p = np.ascontiguousarray(np.asarray(points, dtype=float).reshape(-1, 2))
        out = shape_clearance(p, *self._kernel_args, float(cap))
        if self.raster is not None:
            out = np.minimum(out, self.raster.clearance(p, cap))
        return out

    @staticmethod
    def stacked_shapes(worlds: Sequence[World]) -> tuple[NDArray, ...] | None:
        """The shapes of several worlds, stacked for one clearance call over all of them.

        Returns:
            The arguments of :func:`~dfcoa_opt.world.shape_clearance.shape_clearance_worlds`
            after ``points`` and ``world`` (edges, polygon and circle offsets per world);
            None when a world has a map raster (then each world measures alone).
        """
        if any(w.raster is not None for w in worlds):
            return None
        parts = [w._kernel_args for w in worlds]
        a, b, _, lo, hi, centres, radii = (np.concatenate([part[f] for part in parts])
                                           for f in range(7))
        sizes = [len(v) for w in worlds for v in w.polygons]
        start = np.concatenate(([0], np.cumsum(sizes))).astype(np.int64)
        poly_ptr = np.cumsum([0, *(len(w.polygons) for w in worlds)]).astype(np.int64)
        circle_ptr = np.cumsum([0, *(len(part[6]) for part in parts)]).astype(np.int64)
        return (a.reshape(-1, 2), b.reshape(-1, 2), start, poly_ptr, lo.reshape(-1, 2),
                hi.reshape(-1, 2), centres.reshape(-1, 2), radii, circle_ptr)

    def clearance_reference(self, points: ArrayLike, cap: float = 10.0) -> NDArray[np.float64]:
        """:meth:`clearance` with vectorised numpy (the reference of the kernel's tests).

        Args:
            points: ``(P, 2)`` world points, m.
            cap: Larger distances are reported as ``cap``, m.
        """
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        out = np.full(len(p), float(cap))
        a, b = self._edges
        if len(a):
            out = np.minimum(out, point_segment_distance(p[:, None, :], a, b).min(axis=1))
            lo, hi = self._boxes
            in_box = np.all((p[:, None, :] >= lo) & (p[:, None, :] <= hi), axis=2)
            for k in np.flatnonzero(in_box.any(axis=0)):
                rows = np.flatnonzero(in_box[:, k])
                out[rows[points_in_polygon(p[rows], self.polygons[k])]] = 0.0
        circles = self.circles
        if circles:
            c = np.array([ci.center for ci in circles])
            r = np.array([ci.radius for ci in circles])
            gap = np.linalg.norm(p[:, None, :] - c[None], axis=-1) - r[None]
            out = np.minimum(out, np.maximum(gap.min(axis=1), 0.0))
        if self.raster is not None:
            out = np.minimum(out, self.raster.clearance(p, cap))
        return out

    @cached_property
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
        data: The file's contents with the overrides applied, from which
            :func:`dfcoa_opt.scenario.loader.reseed` draws the world again (None: built
            another way).
        base_dir: Folder against which ``world.map_image`` and ``map_yaml`` are resolved.
    """

    spec: ScenarioSpec
    source: str
    world: World
    offsets: NDArray[np.float64]
    initial_pose: NDArray[np.float64]
    leader_heading: float
    leader_path: NDArray[np.float64]
    data: Mapping[str, Any] | None = field(default=None, repr=False)
    base_dir: Path = field(default=Path("."), repr=False)

    def start_pose(self, rng: np.random.Generator) -> NDArray[np.float64]:
        """``(N, 3)`` a run's initial poses: :attr:`initial_pose` plus ``team.start_noise``.

        Positions get ``N(0, start_noise)`` and headings ``N(0, heading_noise)``
        from ``rng`` (no draw when both are 0). A perturbed position that lands
        on an occupied cell falls back to the nominal one, so the run starts as
        collision-free as the file.
        """
        team = self.spec.team
        pose = self.initial_pose.copy()
        if team.start_noise == 0.0 and team.heading_noise == 0.0:
            return pose
        noise = rng.normal(size=(self.n, 3)) * (team.start_noise, team.start_noise,
                                                team.heading_noise)
        grid = self.world.grid
        moved = pose[:, :2] + noise[:, :2]
        free = grid.in_bounds(*grid.world_to_cell(moved)) & ~grid.is_occupied_at(moved)
        noise[~free, :2] = 0.0
        pose += noise
        pose[:, 2] = wrap_angle(pose[:, 2])
        return pose

    @property
    def seed_dependent(self) -> bool:
        """Whether the world is drawn from the scenario's ``seed``.

        True for a ``[world.clutter]`` field or a ``[world.generate]`` world
        without a seed of its own: each seed draws another world (and the
        leader's path through it).
        """
        clutter, generate = self.spec.world.clutter, self.spec.world.generate
        return ((clutter.density > 0.0 and clutter.seed is None)
                or (bool(generate.family) and generate.seed is None))

    @property
    def name(self) -> str:
        """Scenario name."""
        return self.spec.name

    @property
    def n(self) -> int:
        """Number of robots."""
        return self.spec.team.n
