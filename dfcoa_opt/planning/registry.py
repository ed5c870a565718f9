"""Registry of global planners for the virtual leader.

A planner is a callable ``planner(grid, start, goal, waypoints, options) -> (P, 2)
path`` in metres, from ``start`` to ``goal`` (empty when the goal is
unreachable); ``waypoints`` ``(W, 2)`` are the scenario's ``leader.waypoints``,
m. ``options`` is an instance of the planner's ``Params`` dataclass built from
the scenario's ``[leader.planner_options]`` (None when the planner has no
Params). The built-in ``straight`` planner joins the start, the waypoints and
the goal with straight lines. A planner is registered with
``@register_planner("name", params=MyParams)`` in its module, and the module is
named in the entry-point group ``dfcoa_opt.planners`` (:data:`PLANNERS`, a
:class:`~dfcoa_opt.core.registry.Registry`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.core.registry import Registry
from dfcoa_opt.world.grid import OccupancyGrid

Planner = Callable[[OccupancyGrid, NDArray[np.float64], NDArray[np.float64],
                    NDArray[np.float64], Any], NDArray[np.float64]]
#: The leader planners (entry-point group ``dfcoa_opt.planners``).
PLANNERS: Registry[Planner] = Registry("planner", "dfcoa_opt.planners")


def register_planner(name: str, params: type | None = None) -> Callable[[Planner], Planner]:
    """Decorator registering a leader planner under ``name`` with its options dataclass.

    The dataclass is kept as the planner's ``Params`` attribute (None: no options).
    """

    def deco(fn: Planner) -> Planner:
        fn.Params = params  # type: ignore[attr-defined]
        return PLANNERS.register(name)(fn)

    return deco


def planner_names() -> list[str]:
    """Sorted names of the registered planners."""
    return PLANNERS.names()


def planner_options(name: str, options: Mapping[str, Any], source: str) -> Any:
    """Validate ``[leader.planner_options]`` for planner ``name``.

    Raises:
        ScenarioError: Unknown or bad key (names ``leader.planner_options.<key>``).
    """
    return PLANNERS.options(name, options, source, "leader.planner_options")


def get_planner(name: str) -> Planner:
    """The planner registered as ``name``.

    Raises:
        UnknownNameError: With a "did you mean" hint.
    """
    return PLANNERS.get(name)


@register_planner("straight")
def straight(grid: OccupancyGrid, start: NDArray[np.float64], goal: NDArray[np.float64],
             waypoints: NDArray[np.float64], options: Any = None) -> NDArray[np.float64]:
    """Polyline start -> waypoints -> goal (ignores the map)."""
    return np.vstack((start, np.asarray(waypoints, dtype=float).reshape(-1, 2), goal))
