"""Worlds drawn from a seed: registered families of generated maps (``[world.generate]``).

A *family* is a function ``family(params, rng, layout) -> Generated`` with a
``Params`` dataclass (typed keys with units and ranges, :func:`dfcoa_opt.core.params.param`)
registered with :func:`register_family` and named in the entry-point group
``dfcoa_opt.world_families`` (:data:`FAMILIES`). Given the run's world generator and
the :class:`Layout` (map, mission, team), it returns exact static shapes,
moving discs and the realised statistics of the draw (``facts``: what a test
compares with the parameters). Families:

- ``cellular`` (:mod:`~dfcoa_opt.world.generate.cellular`): BARN-like
  cellular-automaton obstacles;
- ``rooms`` (:mod:`~dfcoa_opt.world.generate.rooms`): rooms joined by doorways;
- ``corridors`` (:mod:`~dfcoa_opt.world.generate.corridors`): one winding corridor;
- ``crowd`` (:mod:`~dfcoa_opt.world.generate.crowd`): an open field crossed by
  moving discs.

The scenario loader (:mod:`dfcoa_opt.scenario.loader`) draws the world, checks that a
passage one robot wide joins the leader's start and goal (:func:`passage_exists`)
and that the leader's planner finds its path, and otherwise draws again with the
same generator, up to ``world.generate.tries`` times. Every draw is a pure
function of the seed (:func:`world_rng`), so the same seed gives the same world
on every machine, in a batch or alone.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.core.errors import ScenarioError
from dfcoa_opt.core.registry import Registry
from dfcoa_opt.world.dynamic import MovingDisc
from dfcoa_opt.world.grid import OccupancyGrid
from dfcoa_opt.world.shapes import Shape

#: Second word of the world generator's seed sequence: the world's draws never share a
#: stream with the run's generator (``np.random.default_rng(seed)``).
WORLD_STREAM = 0x776F726C64  # "world"


@dataclass(frozen=True)
class Layout:
    """What a generated world must leave free: the map, the mission and the team.

    Attributes:
        extent: ``(xmin, xmax, ymin, ymax)`` of the map inside its enclosing walls, m.
        start: The leader's start, m.
        goal: The leader's goal, m.
        start_clear: Radius kept free around the start (the formation's reach plus
            ``world.generate.keep_clear``), m.
        goal_clear: Radius kept free around the goal, m.
    """

    extent: tuple[float, float, float, float]
    start: tuple[float, float]
    goal: tuple[float, float]
    start_clear: float
    goal_clear: float

    @property
    def size(self) -> tuple[float, float]:
        """``(width, height)`` of the map, m."""
        x0, x1, y0, y1 = self.extent
        return x1 - x0, y1 - y0

    def span(self) -> tuple[float, float]:
        """The x interval between the start's and the goal's free discs, m (start to goal).

        The families put their walls and doorways there, so that neither the
        start nor the goal area is touched.
        """
        lo = min(self.start[0] + self.start_clear, self.goal[0] - self.goal_clear)
        hi = max(self.start[0] + self.start_clear, self.goal[0] - self.goal_clear)
        return lo, hi

    def keep_points(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``(points (2, 2), radii (2,))``: the start and goal discs kept free, m."""
        return (np.array([self.start, self.goal], dtype=float),
                np.array([self.start_clear, self.goal_clear]))


@dataclass(frozen=True)
class Generated:
    """One drawn world.

    Attributes:
        shapes: Static obstacles (exact geometry), in a fixed order.
        discs: Moving discs.
        facts: The draw's realised statistics (e.g. ``door_widths``), numbers or
            lists of numbers, for tests and the world's description.
    """

    shapes: tuple[Shape, ...] = ()
    discs: tuple[MovingDisc, ...] = ()
    facts: Mapping[str, Any] = field(default_factory=dict)


Family = Callable[[Any, np.random.Generator, Layout], Generated]
#: The world families (entry-point group ``dfcoa_opt.world_families``).
FAMILIES: Registry[Family] = Registry("world family", "dfcoa_opt.world_families")


def register_family(name: str, params: type) -> Callable[[Family], Family]:
    """Decorator registering a world family under ``name`` with its ``Params`` dataclass.

    The dataclass is kept as the family's ``Params`` attribute.
    """

    def deco(fn: Family) -> Family:
        fn.Params = params  # type: ignore[attr-defined]
        return FAMILIES.register(name)(fn)

    return deco


def family_names() -> list[str]:
    """Sorted names of the registered families."""
    return FAMILIES.names()


def family_params(name: str) -> type:
    """The ``Params`` dataclass of family ``name``.

    Raises:
        UnknownNameError: With a "did you mean" hint.
    """
    return FAMILIES.get(name).Params  # type: ignore[attr-defined, no-any-return]


def family_options(name: str, options: Mapping[str, Any], source: str) -> Any:
    """``[world.generate.options]`` built against family ``name``'s ``Params``.

    Raises:
        ScenarioError: Unknown family (key ``world.generate.family``) or a bad option.
    """
    FAMILIES.check_name(name, source, "world.generate.family")
    return FAMILIES.options(name, options, source, "world.generate.options")


def world_rng(seed: int) -> np.random.Generator:
    """The generator a world of seed ``seed`` is drawn from (PCG64, the same on every machine)."""
    return np.random.default_rng([int(seed), WORLD_STREAM])


def generate(name: str, params: Any, rng: np.random.Generator, layout: Layout) -> Generated:
    """One draw of family ``name`` (the loader redraws when it closes the way)."""
    return FAMILIES.get(name)(params, rng, layout)


def check_range(value: tuple[float, float], src: str, key: str) -> None:
    """A ``(low, high)`` parameter range needs ``low <= high``."""
    if value[0] > value[1]:
        raise ScenarioError(src, key, f"[{value[0]:g}, {value[1]:g}]: the low end must not "
                                      "exceed the high end")


def passage_exists(grid: OccupancyGrid, start: Any, goal: Any, clearance: float) -> bool:
    """Whether a path of free cells keeping ``clearance`` from obstacles joins start and goal.

    A cell counts when the exact clearance of its centre is at least
    ``clearance``, bounded from below by the centre distance field minus half a
    cell diagonal (an occupied cell reaches that far from its centre); cells are
    joined 8-connected. Conservative up to one cell: a passage that this accepts
    lets a disc of radius ``clearance`` travel from the start's cell to the
    goal's cell.

    Args:
        grid: The world's occupancy grid.
        start: ``(2,)`` m.
        goal: ``(2,)`` m.
        clearance: Distance to keep from every occupied cell, m (the robot
            radius plus a margin).
    """
    from scipy import ndimage

    wide = grid.distance_field - grid.cell_size * math.sqrt(0.5) >= clearance
    (rs, cs), (rg, cg) = (grid.world_to_cell(np.asarray(p, dtype=float)) for p in (start, goal))
    if not (grid.in_bounds(rs, cs) and grid.in_bounds(rg, cg) and wide[rs, cs] and wide[rg, cg]):
        return False
    labels, _ = ndimage.label(wide, structure=np.ones((3, 3), dtype=int))
    return bool(labels[rs, cs] == labels[rg, cg])


__all__ = ["FAMILIES", "Generated", "Layout", "check_range", "family_names",
           "family_options", "family_params", "generate", "passage_exists", "register_family",
           "world_rng"]
