"""Run metrics of paper 000 section 3.3 (eq 6-11) and of papers 002 and 004.

Every metric is a pure, vectorised function of a :class:`~dfcoa_opt.sim.log.RunLog`
(and, where it has settings, a :class:`~dfcoa_opt.scenario.schema.MetricSpec`, or a
``ScenarioSpec`` / ``Scenario`` whose ``metrics`` section is used). Time series
have one value per logged step ``t[k]``; summaries average over all logged steps.
Every definition and choice is written down in ``docs/metrics.md``. The modules:

- :mod:`~dfcoa_opt.metrics.formation`: the formation errors of eq 6-10;
- :mod:`~dfcoa_opt.metrics.risk`: the collision risk of eq 11;
- :mod:`~dfcoa_opt.metrics.outcome`: success, collision, deadlock or timeout;
- :mod:`~dfcoa_opt.metrics.contacts`: who touched what at a logged instant;
- :mod:`~dfcoa_opt.metrics.robots`: the per-robot metrics of papers 002 and 004;
- :mod:`~dfcoa_opt.metrics.deploy`: what the commands asked of a real robot;
- :mod:`~dfcoa_opt.metrics.world`: a world's difficulty along the leader's path;
- :mod:`~dfcoa_opt.metrics.solver`: the solve times of a controller that solves;
- :mod:`~dfcoa_opt.metrics.summary`: every scalar of a run under its JSON key;
- :mod:`~dfcoa_opt.metrics.settings`: the settings every metric reads;
- :mod:`~dfcoa_opt.metrics.units`: the unit of every key.

The public names of the first and the summary are re-exported here (``from
dfcoa_opt import metrics; metrics.summary(log)``).
"""

from dfcoa_opt.metrics.formation import (
    centroid_offset,
    centroids,
    formation_centroid_error,
    formation_shape_error,
    formation_stability_error,
    formation_stability_pct,
    open_steps,
    rms,
    rms_velocities,
    velocity_centroid_error,
)
from dfcoa_opt.metrics.risk import (
    RISK_DISTANCE_FLOOR,
    collision_risk,
    collision_risk_normalised,
    normalise_risk,
)
from dfcoa_opt.metrics.summary import (
    PAPER_000_TABLE5,
    filter_counts,
    localization_error,
    min_inter_robot_distance,
    min_obstacle_clearance,
    summary,
)
from dfcoa_opt.metrics.units import UNITS, unit

__all__ = ["PAPER_000_TABLE5", "RISK_DISTANCE_FLOOR", "UNITS", "centroid_offset", "centroids",
           "collision_risk", "collision_risk_normalised", "filter_counts",
           "formation_centroid_error", "formation_shape_error", "formation_stability_error",
           "formation_stability_pct", "localization_error", "min_inter_robot_distance",
           "min_obstacle_clearance", "normalise_risk", "open_steps", "rms", "rms_velocities",
           "summary", "unit", "velocity_centroid_error"]
