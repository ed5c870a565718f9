"""Two variants' formation errors over the steps that are open for both of them.

``fce_open_rms`` and ``fse_open_rms`` (:func:`dfcoa_opt.metrics.open_steps`)
average each run over its own open steps. When one variant stands in front of
an obstacle for most of the run and the other gets past it, those are
different stretches of the map, so the two numbers do not compare tracking
(the comparison sets ``reshape`` against ``goto_slot+cbf`` there). This
module pairs the runs of one scenario and seed and keeps only the instants at
which both runs are open, at the metric's open clearance and at a wider one
(``reshape``'s look-ahead, 3 m: a planner that looks ahead deforms the
formation before anything is within 1 m).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from dfcoa_opt.bench.report.document import load_rows
from dfcoa_opt.bench.report.plots import scenario_for_row, variant_name
from dfcoa_opt.bench.results.logs import read_log
from dfcoa_opt.metrics import (
    formation_centroid_error,
    formation_shape_error,
    open_steps,
    rms,
)
from dfcoa_opt.scenario.schema import MetricSpec
from dfcoa_opt.sim.log import RunLog

#: Open clearances (m) of the table: the metrics' default and reshape's look-ahead.
CLEARANCES = (1.0, 3.0)


@dataclass(frozen=True)
class SharedOpen:
    """Formation errors of two runs over the instants open in both.

    Attributes:
        fraction: Shared open instants over the shorter run's instants.
        fce: ``(a, b)`` RMS formation centroid error (eq 14 of paper 000), m.
        fse: ``(a, b)`` RMS formation shape error, m.
    """

    fraction: float
    fce: tuple[float, float]
    fse: tuple[float, float]


def shared_open_errors(a: RunLog, b: RunLog, cfg: MetricSpec) -> SharedOpen:
    """Errors of runs ``a`` and ``b`` (one scenario, one seed) where both are open.

    Args:
        a: One run.
        b: The other run, logged at the same instants (its ``t`` starts like ``a``'s).
        cfg: Metric settings; ``cfg.open_clearance`` (m) decides what is open.

    Raises:
        ValueError: The two logs do not share their first instants.
    """
    return _PairErrors(a, b).at(cfg)


class _PairErrors:
    """Both runs' error series, computed once; :meth:`at` masks them per clearance."""

    def __init__(self, a: RunLog, b: RunLog) -> None:
        n = min(len(a.t), len(b.t))
        if not np.allclose(a.t[:n], b.t[:n]):
            raise ValueError("shared_open_errors: the two runs are not logged at the same "
                             "instants")
        self.logs, self.n = (a, b), n
        self.fce = [np.asarray(formation_centroid_error(x))[:n] for x in (a, b)]
        self.fse = [np.asarray(formation_shape_error(x))[:n] for x in (a, b)]

    def at(self, cfg: MetricSpec) -> SharedOpen:
        """:func:`shared_open_errors` with the settings ``cfg``."""
        a, b = self.logs
        both = open_steps(a, cfg)[:self.n] & open_steps(b, cfg)[:self.n]
        return SharedOpen(float(both.mean()) if self.n else math.nan,
                          (rms(self.fce[0][both]), rms(self.fce[1][both])),
                          (rms(self.fse[0][both]), rms(self.fse[1][both])))


def shared_open_table(results_dir: str | Path, a: str, b: str,
                      clearances: Sequence[float] = CLEARANCES) -> str:
    """Markdown: per scenario and clearance, the medians over seeds of both variants' errors.

    Args:
        results_dir: A sweep's results folder (rows and logs).
        a: The first variant's name.
        b: The second variant's name.
        clearances: Open clearances to tabulate, m.

    Returns:
        The table, with a heading; "" when the sweep has no seed run by both.
    """
    root = Path(results_dir)
    rows = [r for r in load_rows(root) if r.get("status") == "ok" and not r.get("ladder")]
    by = {(r["scenario"], variant_name(r), r["seed"]): r for r in rows}
    lines = []
    for scen in sorted({s for s, v, _ in by if v == a}):
        seeds = sorted(k for s, v, k in by if s == scen and v == a and (s, b, k) in by)
        if not seeds:
            continue
        cfg = scenario_for_row(by[(scen, a, seeds[0])]).spec.metrics
        pairs = [_PairErrors(read_log(root, by[(scen, a, k)]),
                             read_log(root, by[(scen, b, k)])) for k in seeds]
        for c in clearances:
            res = [p.at(replace(cfg, open_clearance=c)) for p in pairs]
            used = [r for r in res if not math.isnan(r.fce[0])]

            def med(values: list[float]) -> str:
                return f"{np.median(values):.3f}" if values else "—"

            lines.append(
                f"| {scen} | {c:g} | {len(used)}/{len(seeds)} | "
                f"{100 * np.median([r.fraction for r in res]):.0f} % | "
                f"{med([r.fce[0] for r in used])} / {med([r.fce[1] for r in used])} | "
                f"{med([r.fse[0] for r in used])} / {med([r.fse[1] for r in used])} |")
    if not lines:
        return ""
    return "\n".join([
        f"## `{a}` against `{b}` on shared open stretches", "",
        "Each seed's two runs keep only the instants at which both are open (every robot "
        "at least the clearance from every obstacle and moving disc). Medians over the "
        "seeds that have such instants (dfcoa_opt/bench/report/shared_open.py).", "",
        f"| scenario | clearance (m) | seeds with shared open steps | shared open steps "
        f"(median) | fce_rms {a} / {b} (m) | fse_rms {a} / {b} (m) |",
        "|---|---|---|---|---|---|", *lines, ""])
