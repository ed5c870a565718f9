"""Checks of the names a scenario file gives: registered ids, and waypoints only where used.

The planner (``leader.planner``), the estimator (``localization.mode``) and
every ``[controllers.<id>]`` table are checked against their registries
(:mod:`dfcoa_opt.core.registry`, :mod:`dfcoa_opt.planning.registry`), which
ask only the entry point of the id they are given. Where things are (starts,
goal, obstacles) is checked by :mod:`dfcoa_opt.scenario.placement`, sizes by
:mod:`dfcoa_opt.scenario.budget`. Each raises
:class:`~dfcoa_opt.core.errors.ScenarioError` (one line: the file, the key,
the problem).
"""

from __future__ import annotations

from dfcoa_opt.core.errors import ScenarioError
from dfcoa_opt.core.registry import ESTIMATORS, check_tables
from dfcoa_opt.planning.registry import PLANNERS
from dfcoa_opt.scenario.schema import ScenarioSpec


def check_names(spec: ScenarioSpec, source: str) -> None:
    """Registered planner, localization mode and controller override tables.

    The catalogues are the registries of :mod:`dfcoa_opt.core.registry` and
    :mod:`dfcoa_opt.planning.registry`; each asks only the entry point of the
    id it is given.
    """
    PLANNERS.check_name(spec.leader.planner, source, "leader.planner")
    ESTIMATORS.check_name(spec.localization.mode, source, "localization.mode")
    ESTIMATORS.options(spec.localization.mode, spec.localization.options, source,
                       "localization.options")
    check_tables(spec.controllers, source, spec.team.n)


def check_waypoints(spec: ScenarioSpec, source: str) -> None:
    """``leader.waypoints`` only with the ``straight`` planner, the one that uses them.

    The searching planners plan their own path from ``leader.start`` to
    ``leader.goal`` and would silently ignore the via points.
    """
    if spec.leader.waypoints and spec.leader.planner != "straight":
        raise ScenarioError(source, "leader.waypoints", f"only the 'straight' planner uses them; "
                                                        f"planner '{spec.leader.planner}' plans "
                                                        f"its own path and would ignore them")
