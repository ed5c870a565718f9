"""Paired comparisons of every variant against a sweep's baseline.

All variants run on the same seeds of each scenario, so a variant and the
baseline are compared seed by seed (:mod:`dfcoa_opt.bench.report.stats`):

- a metric: the median of the per-seed differences ``variant - baseline``, its
  bootstrap 95 % CI, and the two-sided Wilcoxon signed-rank p-value; seeds where
  either value is not finite (a failed run, no time to goal, a raw risk after a
  contact, which is ``inf``) are left out and counted (``excluded``);
- success: the difference of the success rates and McNemar's exact test (a
  failed run counts as no success).

Within one table (a scenario, or one rung of a ladder) every p-value is Holm
corrected, and each cell is marked better, worse or no difference at 5 %.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

from dfcoa_opt.bench.report import stats
from dfcoa_opt.bench.report.plots import as_number, variant_name
from dfcoa_opt.bench.runner import is_success

Row = Mapping[str, Any]

#: Metrics compared pairwise by default, after success (keys of ``metrics.summary``).
PAIRED_METRICS: tuple[str, ...] = (
    "time_to_goal", "fce_rms", "fse_rms", "fce_open_rms", "fse_open_rms", "risk_raw_mean",
    "min_inter_robot_distance", "min_obstacle_clearance", "path_length_mean",
)
#: Metrics where a larger value is better; for every other metric smaller is better.
HIGHER_IS_BETTER = frozenset({"success", "stability_pct", "min_inter_robot_distance",
                              "min_obstacle_clearance"})


@dataclass(frozen=True)
class Comparison:
    """One cell: a variant against the baseline on one metric of one table.

    Attributes:
        table: ``(scenario, ladder, ladder_value)`` (ladder ``""``, value None outside one).
        variant: The variant's name.
        metric: ``"success"`` or a summary key.
        n: Seeds paired.
        estimate: Success: rate difference (fraction); a metric: median paired
            difference, in the metric's unit.
        ci_low: Lower end of the 95 % CI of ``estimate`` (NaN for success).
        ci_high: Upper end.
        p_value: Two-sided p-value (McNemar exact or Wilcoxon).
        p_holm: Holm-corrected p-value within the table.
        verdict: ``"better"``, ``"worse"`` or ``"no difference"`` (at 5 %, after Holm).
        excluded: Seeds left out of a metric's comparison because either value was
            not finite (0 for success).
    """

    table: tuple[str, str, float | None]
    variant: str
    metric: str
    n: int
    estimate: float
    ci_low: float
    ci_high: float
    p_value: float
    p_holm: float = math.nan
    verdict: str = "no difference"
    excluded: int = 0


def table_of(row: Row) -> tuple[str, str, float | None]:
    """The comparison table a row belongs to: scenario, ladder, ladder value."""
    value = row.get("ladder_value")
    return (str(row["scenario"]), str(row.get("ladder") or ""),
            None if value is None else float(value))


def _by_seed(rows: Sequence[Row]) -> dict[tuple[tuple[str, str, float | None], str],
                                          dict[int, Row]]:
    out: dict[tuple[tuple[str, str, float | None], str], dict[int, Row]] = {}
    for r in rows:
        out.setdefault((table_of(r), variant_name(r)), {})[int(r["seed"])] = r
    return out


def compare(rows: Sequence[Row], baseline: str,
            metrics: Sequence[str] = PAIRED_METRICS, seed: int = 0) -> list[Comparison]:
    """Every variant against ``baseline``, per table, Holm-corrected within each table.

    Args:
        rows: Result rows.
        baseline: The baseline variant's name.
        metrics: Summary keys compared after success.
        seed: Seed of the bootstrap resampling (fixed: the report is reproducible).

    Returns:
        The comparisons, by table, variant (in first-seen order) and metric
        (success first); empty when the baseline has no run.
    """
    groups = _by_seed(rows)
    tables = list(dict.fromkeys(t for t, _ in groups))
    out: list[Comparison] = []
    for table in tables:
        base = groups.get((table, baseline))
        if base is None:
            continue
        cells: list[Comparison] = []
        for (t, variant), mine in groups.items():
            if t != table or variant == baseline:
                continue
            seeds = sorted(set(mine) & set(base))
            if not seeds:
                continue
            a = [is_success(mine[s]) for s in seeds]
            b = [is_success(base[s]) for s in seeds]
            mc = stats.mcnemar_exact(a, b)
            cells.append(Comparison(table, variant, "success", mc.n, mc.difference, math.nan,
                                    math.nan, mc.p_value))
            for metric in metrics:
                x = [_metric(mine[s], metric) for s in seeds]
                y = [_metric(base[s], metric) for s in seeds]
                d = stats.paired_difference(x, y, seed=seed)
                cells.append(Comparison(table, variant, metric, d.n, d.median, d.ci_low,
                                        d.ci_high, d.p_value, excluded=d.excluded))
        adjusted = stats.holm([c.p_value for c in cells])
        out += [replace(c, p_holm=float(p), verdict=stats.verdict(
            c.estimate, float(p), c.metric in HIGHER_IS_BETTER)) for c, p in zip(
            cells, adjusted, strict=True)]
    return out


def _metric(row: Row, metric: str) -> float:
    """A metric of a row as a float; NaN for a failed run or a missing value."""
    if row.get("status") != "ok":
        return math.nan
    return as_number((row.get("metrics") or {}).get(metric))
