"""Figure recipe "ladders": where each method breaks, along graded difficulty.

Ladders over the common scenarios, set by overrides (the scenario files are
not changed): doorway width 4.0 -> 1.0 m (corridor), clutter density
0.02 -> 0.12 (clutter), team size 4 -> 100 (large_100); message latency,
dropout and pose noise (crossing); and the robot's own limits on crossing and
S1 (motor time constant, wheel acceleration limit, robot profile; the actuated
model of docs/robots.md). Seeds are added to each
(rung, variant) until its success rate's Wilson 95 % interval is within ±20
points (:mod:`dfcoa_opt.bench.precision`). The report draws success rate
against the rung's value, one line per variant.
"""

from __future__ import annotations

from pathlib import Path

from dfcoa_opt.bench.recipes import Artefact, recipe
from dfcoa_opt.bench.recipes.comparison import report_artefacts
from dfcoa_opt.bench.results.store import ResultsStore


@recipe("ladders", sweep="sweeps/ladders.toml",
        title="Difficulty ladders: geometry, messages and the robot's limits", budget=700)
def render_ladders(store: ResultsStore, dest: Path) -> list[Artefact]:
    """The report of the ladder sweep: a success-rate curve and table per ladder."""
    return report_artefacts(store, dest, "no paper (difficulty ladders)")
