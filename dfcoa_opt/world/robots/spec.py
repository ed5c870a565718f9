"""Scenario schema, the ``[robots]`` section: model, limits, wheels, profile and dynamics.

Part of :mod:`dfcoa_opt.scenario.schema` (which re-exports :class:`RobotSpec`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from dfcoa_opt.core.errors import ScenarioError
from dfcoa_opt.core.params import param


@dataclass(frozen=True)
class RobotSpec:
    """Robot model and its limits (all robots of a team are identical)."""

    model: Literal["unicycle", "single_integrator", "double_integrator"] = param(
        "unicycle", doc="Kinematic model.")
    profile: str | None = param(None, doc="A robot profile (docs/robots.md: turtlebot3_burger, "
                                          "turtlebot3_waffle_pi, jackal, gritsbot) that sets "
                                          "this table's and the LiDAR's defaults; keys given "
                                          "in the scenario override them.")
    dynamics: Literal["kinematic", "actuated"] = param(
        "kinematic", doc="'kinematic': the command is the velocity at once; 'actuated' "
                         "(unicycle only): wheel set points with acceleration limits and motor "
                         "lag (docs/robots.md).")
    radius: float = param(0.2, doc="Body radius (collision disc).", unit="m", gt=0.0)
    v_max: float = param(0.5, doc="Largest forward speed (speed norm for integrators).",
                         unit="m/s", gt=0.0)
    v_min: float | None = param(None, doc="Smallest forward speed of a unicycle; default -v_max.",
                                unit="m/s")
    w_max: float = param(1.5, doc="Largest turn rate.", unit="rad/s", gt=0.0)
    a_max: float = param(1.0, doc="Largest acceleration norm (double integrator).",
                         unit="m/s^2", gt=0.0)
    wheel_radius: float = param(0.05, doc="Wheel radius r of paper 000 eq 1-2.", unit="m", gt=0.0)
    track_width: float = param(0.3, doc="Track width d of paper 000 eq 1-2.", unit="m", gt=0.0)
    wheel_speed_max: float = param(math.inf, doc="Largest wheel speed (inf = no limit).",
                                   unit="rad/s", gt=0.0, finite=False)
    wheel_accel_max: float = param(math.inf, doc="With dynamics = 'actuated': largest "
                                                 "acceleration of each wheel's rim (inf = no "
                                                 "limit).", unit="m/s^2", gt=0.0, finite=False)
    motor_time_constant: float = param(0.0, doc="With dynamics = 'actuated': time constant of "
                                                "the first-order lag of each wheel's speed to "
                                                "its set point (0 = none).", unit="s", ge=0.0)
    wheel_noise_std: float = param(0.0, doc="With dynamics = 'actuated': standard deviation of "
                                            "Gaussian noise on each wheel's set point, drawn "
                                            "every step from the run's generator.",
                                   unit="rad/s", ge=0.0)
    substeps: int = param(4, doc="With dynamics = 'actuated': arcs per step (exact for a "
                                 "command of constant curvature; more substeps follow a "
                                 "changing curvature more closely).", ge=1, le=1000)
    nid_distance: float = param(0.1, doc="Offset of the near-identity point used to run "
                                         "velocity commands on unicycles.", unit="m", gt=0.0)
    mass: float = param(1.0, doc="Mass, turns force disturbances into acceleration.",
                        unit="kg", gt=0.0)
    command_noise_std: float = param(0.0, doc="Standard deviation of Gaussian noise added to "
                                              "each component of the applied command, in its "
                                              "unit (v m/s and omega rad/s; vx, vy m/s; ax, ay "
                                              "m/s^2), drawn every step from the run's "
                                              "generator.", ge=0.0)

    @property
    def v_lower(self) -> float:
        """Effective smallest forward speed in m/s."""
        return -self.v_max if self.v_min is None else self.v_min

    def check(self, src: str, key: str) -> None:
        """v_min <= v_max; actuated dynamics only for unicycles."""
        if self.v_min is not None and self.v_min > self.v_max:
            raise ScenarioError(src, f"{key}.v_min", f"must be <= v_max ({self.v_max})")
        if self.dynamics == "actuated" and self.model != "unicycle":
            raise ScenarioError(src, f"{key}.dynamics", f"'actuated' applies to model = "
                                                        f"'unicycle', not '{self.model}'")
        actuated_only = {"wheel_accel_max": math.inf, "motor_time_constant": 0.0,
                         "wheel_noise_std": 0.0}
        for name, default in actuated_only.items():
            if self.dynamics == "kinematic" and getattr(self, name) != default:
                raise ScenarioError(src, f"{key}.{name}", "only applies with dynamics = "
                                                          "'actuated'")
