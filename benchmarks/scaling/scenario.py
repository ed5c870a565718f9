"""Scenario of the scaling study (:mod:`benchmarks.scaling`): one per N and robot model.

Built with :func:`dfcoa_opt.scenario.loader.scenario_from_dict`: an open field without
obstacles whose area grows with N (:data:`AREA_PER_ROBOT` m^2 per robot, square), a
grid formation (1 m spacing, ``ceil(sqrt(N))`` columns) around a virtual leader on a
straight line along +x at 0.35 m/s, 8 nearest neighbours within 5 m, and a small
LiDAR (36 beams, 4 m). The LiDAR stays on for every controller because ``dfcoa``
needs it.
"""

from __future__ import annotations

import math
from typing import Any

from dfcoa_opt.scenario.loader import scenario_from_dict
from dfcoa_opt.scenario.scenario import Scenario

#: Field area per robot, m^2 (constant density: the square field's side is sqrt(area * N)).
AREA_PER_ROBOT = 16.0
DT = 0.1  # s
SPACING = 1.0  # m, grid formation
LEADER_SPEED = 0.35  # m/s
#: Robot model per controller (the model each controller's module documents); default unicycle.
MODELS: dict[str, dict[str, Any]] = {
    "consensus": {"model": "double_integrator", "a_max": 1000.0},  # paper 001, eq 1
    "consensus_ivo": {"model": "double_integrator", "a_max": 1000.0},
    "virtual_spring": {"model": "double_integrator", "a_max": 100.0},  # paper 004, eq 3
    "virtual_spring_basic": {"model": "double_integrator", "a_max": 100.0},
    "orca_nav": {"model": "single_integrator"},  # holonomic ORCA (paper 001 Table I)
}
DEFAULT_MODEL: dict[str, Any] = {"model": "unicycle"}


def model_of(controller_id: str) -> dict[str, Any]:
    """The ``[robots]`` keys (model, a_max) used for ``controller_id``."""
    return MODELS.get(controller_id, DEFAULT_MODEL)


def open_scenario(n: int, robots: dict[str, Any], steps: int, seed: int = 7) -> Scenario:
    """The open-field grid-formation scenario with ``n`` robots.

    Args:
        n: Team size.
        robots: Extra ``[robots]`` keys (``model``, ``a_max`` in m/s^2).
        steps: Number of control steps after the first one (``t_max = steps * DT`` s).
        seed: Run seed (start noise).

    Returns:
        The validated scenario: square field of side ``sqrt(AREA_PER_ROBOT * n)`` m,
        leader on a straight line along +x through the middle.
    """
    side = math.sqrt(AREA_PER_ROBOT * n)
    cols = math.ceil(math.sqrt(n))
    rows = math.ceil(n / cols)
    back = 0.5 * (rows - 1) * SPACING  # m from the leader to the last row
    y = 0.5 * side
    data = {
        "name": f"open_grid_{n}", "dt": DT, "t_max": steps * DT, "seed": seed,
        "world": {"size": [side, side], "resolution": 10},
        "robots": {"radius": 0.2, "v_max": 0.6, "w_max": 2.0, **robots},
        "team": {"n": n, "start_noise": 0.05, "heading_noise": 0.05},
        "formation": {"shape": "grid", "spacing": SPACING},
        "leader": {"start": [back + 1.5, y], "goal": [side - 1.0, y], "speed": LEADER_SPEED,
                   "planner": "straight"},
        "sensors": {"max_neighbors": 8, "comm_radius": 5.0,
                    "lidar": {"beams": 36, "range_max": 4.0}},
    }
    return scenario_from_dict(data, f"<benchmarks.scaling N={n}>")
