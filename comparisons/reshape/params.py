"""Parameters of ``reshape``: :class:`ReshapeParams`, its ``[controllers.reshape]`` table.

The controller (:class:`~comparisons.reshape.controller.Reshape`, whose
``Params`` it is) and one run's central planner
(:class:`~comparisons.reshape.central.CentralPlanner`) read them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from dfcoa_opt.core.params import param

__all__ = ["ReshapeParams"]


@dataclass(frozen=True)
class ReshapeParams:
    """Parameters of ``reshape`` (``[controllers.reshape]``)."""

    replan_period: float = param(0.5, doc="Time between two plans (from 10 ms: the relay "
                                          "keeps 10 s of plans).", unit="s", ge=0.01)
    lookahead: float = param(3.0, doc="Look-ahead along the leader's path beyond the "
                                      "formation's progress.", unit="m", gt=0.0,
                             tune=(1.0, 6.0))
    s_min: float = param(0.5, doc="Smallest scale of a template (raised so that the "
                                  "scaled slots keep 0.3 m between robots).", gt=0.0, le=1.0)
    scales: int = param(4, doc="Scales tried in [s_min, 1].", ge=1, le=1000)
    rotation_max: float = param(math.pi / 3, doc="Largest rotation tried either side of "
                                                 "the look-ahead direction.", unit="rad",
                                ge=0.0)
    rotations: int = param(5, doc="Rotations tried (odd: includes 0).", ge=1, le=1000)
    templates: tuple[str, ...] = param(("scenario", "line", "column"),
                                       doc="Templates: 'scenario' (the file's shape), "
                                           "'line' (abreast), 'column' (single file).")
    template_cost: float = param(1.0, doc="Cost of a template other than the scenario's.")
    margin: float = param(0.1, doc="Clearance kept beyond the robot radius in the region.",
                          unit="m", ge=0.0, tune=(0.0, 0.3))
    horizon: float = param(2.0, doc="Moving discs are swept over this time.", unit="s",
                           ge=0.0)
    hysteresis: float = param(0.1, doc="A new assignment must be this fraction cheaper.",
                              ge=0.0, lt=1.0)
    gamma: float = param(5.0, doc="Class-K gain of the CBF tracking filter (the filter "
                                  "caps it at 1/dt).", unit="1/s", gt=0.0, tune=(1.0, 10.0),
                         scale="log")
    kp: float = param(1.0, doc="Proportional gain towards the target.", unit="1/s", gt=0.0,
                      tune=(0.3, 3.0), scale="log")
    weight_progress: float = param(1.0, doc="Cost weight of |t - g|^2.", unit="1/m^2",
                                   ge=0.0)
    weight_scale: float = param(4.0, doc="Cost weight of (1 - s)^2.", ge=0.0,
                                tune=(0.5, 20.0), scale="log")
    weight_rotation: float = param(0.5, doc="Cost weight of the rotation squared.",
                                   unit="1/rad^2", ge=0.0)
    switch_cost: float = param(0.5, doc="Cost of changing template.", ge=0.0)
    route_detour: float = param(0.1, doc="A route of a larger scale may be this fraction "
                                         "longer than the quickest passage.", ge=0.0)
    route_clearance: float = param(0.3, doc="Extra distance a formation route keeps from "
                                            "obstacles where it can.", unit="m", ge=0.0)
    route_lead: float = param(1.0, doc="On a route, the slots lead the formation's centre "
                                       "(single file: its middle) by this much.", unit="m",
                              gt=0.0)
    unstick_time: float = param(3.0, doc="A robot that stayed within 0.1 m of one point "
                                        "this long, away from its target, is stuck.",
                                unit="s", gt=0.0)
    unstick_angle: float = param(math.pi / 3, doc="A stuck robot's command is turned by "
                                                  "this (counter-clockwise).", unit="rad")
    coordinate: bool = param(False, doc="The coordination layer of ``reshape_passage`` "
                                        "(docs/methods/reshape_passage.md): a column led by its "
                                        "front robot, a route kept past the blocked stretch, "
                                        "a stuck team's recovery route, the goal's formation "
                                        "on the stopped leader, a filter gain capped at "
                                        "wheel_accel_max / v_max.")
    yield_time: float = param(0.0, doc="The tracking filter grows each sensed moving disc "
                                        "by its speed times this: robots give way earlier "
                                        "to faster discs.", unit="s", ge=0.0)
    stuck_window: float = param(4.0, doc="coordinate: a team whose progress and robots "
                                         "stood still this long is stuck.", unit="s",
                                gt=0.0)
    recover_time: float = param(10.0, doc="coordinate: a stuck team follows a route this "
                                          "long.", unit="s", gt=0.0)
    route_period: float = param(2.0, doc="Time between two route searches while the "
                                         "formation stays on its route.", unit="s", gt=0.0)
