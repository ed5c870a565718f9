"""Registry of global planners for the virtual leader.

A planner is a callable ``planner(grid, start, goal, spec, options) -> (P, 2)
path`` in metres, from ``start`` to ``goal`` (empty when the goal is
unreachable). ``options`` is an instance of the planner's ``Params`` dataclass
built from the scenario's ``[leader.planner_options]`` (None when the planner
has no Params). The built-in ``straight`` planner joins the start, the
scenario's ``leader.waypoints`` and the goal with straight lines. Other
modules add planners with ``@register_planner("name", params=MyParams)`` and
are listed in :data:`PLANNER_MODULES`.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.core.errors import UnknownNameError, did_you_mean
from dfcoa_opt.core.params import build_options
from dfcoa_opt.scenario.schema import LeaderSpec
from dfcoa_opt.world.grid import OccupancyGrid

Planner = Callable[[OccupancyGrid, NDArray[np.float64], NDArray[np.float64], LeaderSpec, Any],
                   NDArray[np.float64]]
#: Modules of this distribution that register planners when imported.
PLANNER_MODULES: tuple[str, ...] = ("dfcoa_opt.planning.astar", "dfcoa_opt.planning.clearance",
                                     "dfcoa_opt.planning.improved_astar")
_PLANNERS: dict[str, Planner] = {}
_PARAMS: dict[str, type | None] = {}


def register_planner(name: str, params: type | None = None) -> Callable[[Planner], Planner]:
    """Decorator registering a leader planner under ``name`` with its options dataclass."""

    def deco(fn: Planner) -> Planner:
        _PLANNERS[name] = fn
        _PARAMS[name] = params
        return fn

    return deco


def _load() -> None:
    for mod in PLANNER_MODULES:
        importlib.import_module(mod)


def planner_names() -> list[str]:
    """Sorted names of the registered planners."""
    _load()
    return sorted(_PLANNERS)


def planner_options(name: str, options: Mapping[str, Any], source: str) -> Any:
    """Validate ``[leader.planner_options]`` for planner ``name``.

    Raises:
        ScenarioError: Unknown or bad key (names ``leader.planner_options.<key>``).
    """
    _load()
    return build_options(_PARAMS.get(name), options, source, "leader.planner_options",
                         f"planner '{name}'")


def get_planner(name: str) -> Planner:
    """The planner registered as ``name``.

    Raises:
        UnknownNameError: With a "did you mean" hint.
    """
    _load()
    try:
        return _PLANNERS[name]
    except KeyError:
        raise UnknownNameError(f"unknown planner '{name}'{did_you_mean(name, _PLANNERS)}; "
                               f"available: {', '.join(sorted(_PLANNERS))}") from None


@register_planner("straight")
def straight(grid: OccupancyGrid, start: NDArray[np.float64], goal: NDArray[np.float64],
             spec: LeaderSpec, options: Any = None) -> NDArray[np.float64]:
    """Polyline start -> waypoints -> goal (ignores the map)."""
    return np.vstack((start, np.asarray(spec.waypoints, dtype=float).reshape(-1, 2), goal))
