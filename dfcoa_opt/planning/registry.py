"""Registry of global planners for the virtual leader.

A planner is a callable ``planner(grid, start, goal, spec) -> (P, 2) path`` in
metres, from ``start`` to ``goal``. The built-in ``straight`` planner joins the
start, the scenario's ``leader.waypoints`` and the goal with straight lines.
Other modules add planners with ``@register_planner("name")``.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.errors import UnknownNameError, did_you_mean
from dfcoa_opt.sim.schema import LeaderSpec
from dfcoa_opt.world.grid import OccupancyGrid

Planner = Callable[[OccupancyGrid, NDArray[np.float64], NDArray[np.float64], LeaderSpec],
                   NDArray[np.float64]]
_PLANNERS: dict[str, Planner] = {}


def register_planner(name: str) -> Callable[[Planner], Planner]:
    """Decorator registering a leader planner under ``name``."""

    def deco(fn: Planner) -> Planner:
        _PLANNERS[name] = fn
        return fn

    return deco


def planner_names() -> list[str]:
    """Sorted names of the registered planners."""
    return sorted(_PLANNERS)


def get_planner(name: str) -> Planner:
    """The planner registered as ``name``.

    Raises:
        UnknownNameError: With a "did you mean" hint.
    """
    try:
        return _PLANNERS[name]
    except KeyError:
        raise UnknownNameError(f"unknown planner '{name}'{did_you_mean(name, _PLANNERS)}; "
                               f"available: {', '.join(sorted(_PLANNERS))}") from None


@register_planner("straight")
def straight(grid: OccupancyGrid, start: NDArray[np.float64], goal: NDArray[np.float64],
             spec: LeaderSpec) -> NDArray[np.float64]:
    """Polyline start -> waypoints -> goal (ignores the map)."""
    return np.vstack((start, np.asarray(spec.waypoints, dtype=float).reshape(-1, 2), goal))
