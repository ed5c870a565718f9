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

For rankings, :func:`success_pairs` tests success between every two variants
of a table the same way (Holm over all the pairs of the table), and
:func:`rank_groups` turns those tests into shared ranks.
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


def _shared_seeds(mine: Mapping[int, Row], other: Mapping[int, Row]) -> list[int]:
    """The seeds (worlds) both variants ran, in increasing order."""
    return sorted(set(mine) & set(other))


def _success_test(mine: Mapping[int, Row], other: Mapping[int, Row],
                  seeds: Sequence[int]) -> stats.McNemar:
    """McNemar's exact test of success of ``mine`` against ``other`` on ``seeds``.

    ``b10`` of the result counts the seeds where only ``mine`` succeeded.
    """
    return stats.mcnemar_exact([is_success(mine[s]) for s in seeds],
                               [is_success(other[s]) for s in seeds])


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
            seeds = _shared_seeds(mine, base)
            if not seeds:
                continue
            mc = _success_test(mine, base, seeds)
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


#: Significance level of the rank groups (Holm-adjusted McNemar p-values).
RANK_ALPHA = 0.05


@dataclass(frozen=True)
class SuccessPair:
    """McNemar's exact test of success between two variants of one table.

    Attributes:
        table: ``(scenario, ladder, ladder_value)`` as in :class:`Comparison`.
        first: One variant's name.
        second: The other's.
        worlds: Seeds (worlds) both ran; the test uses these only.
        only_first: Worlds where ``first`` succeeded and ``second`` did not.
        only_second: Worlds where ``second`` succeeded and ``first`` did not.
        p_value: Exact two-sided McNemar p-value (1 without a discordant world, NaN
            without a shared world).
        p_holm: ``p_value`` Holm-corrected over every pair of the table (NaN stays NaN
            and is not counted).
    """

    table: tuple[str, str, float | None]
    first: str
    second: str
    worlds: int
    only_first: int
    only_second: int
    p_value: float
    p_holm: float = math.nan

    def flipped(self) -> SuccessPair:
        """The same test seen from ``second``."""
        return replace(self, first=self.second, second=self.first,
                       only_first=self.only_second, only_second=self.only_first)


def success_pairs(rows: Sequence[Row]) -> list[SuccessPair]:
    """McNemar's exact test of success between every two variants, per table.

    Runs are paired by seed within a table exactly as in :func:`compare` (same
    scenario, ladder rung and seed = same world). The p-values of all the pairs of
    one table are Holm-corrected together.

    Args:
        rows: Result rows.

    Returns:
        One :class:`SuccessPair` per table and pair of variants (variants in
        first-seen order, ``first`` seen before ``second``), including pairs without
        a shared world (``worlds == 0``, NaN p-values).
    """
    by_seed = _by_seed(rows)
    out: list[SuccessPair] = []
    for table in dict.fromkeys(t for t, _ in by_seed):
        names = [v for t, v in by_seed if t == table]
        cells = []
        for i, first in enumerate(names):
            for second in names[i + 1:]:
                mine, other = by_seed[(table, first)], by_seed[(table, second)]
                seeds = _shared_seeds(mine, other)
                mc = _success_test(mine, other, seeds)
                cells.append(SuccessPair(table, first, second, len(seeds), mc.b10, mc.b01,
                                         mc.p_value))
        adjusted = stats.holm([c.p_value for c in cells])
        out += [replace(c, p_holm=float(p)) for c, p in zip(cells, adjusted, strict=True)]
    return out


def pair_index(pairs: Sequence[SuccessPair]) -> dict[tuple[str, str], SuccessPair]:
    """``(a, b) -> the test of a against b``, seen from ``a``, for both orders of each pair.

    Raises:
        ValueError: The pairs come from more than one table.
    """
    tables = {p.table for p in pairs}
    if len(tables) > 1:
        raise ValueError(f"pairs of one table expected, got {len(tables)} tables")
    out: dict[tuple[str, str], SuccessPair] = {}
    for p in pairs:
        out[(p.first, p.second)] = p
        out[(p.second, p.first)] = p.flipped()
    return out


def separated(upper: str, lower: str, index: Mapping[tuple[str, str], SuccessPair],
              alpha: float = RANK_ALPHA) -> bool:
    """Whether ``upper`` succeeds significantly more often than ``lower``.

    Holm-adjusted McNemar p below ``alpha`` and more worlds where only ``upper``
    succeeded; an untested pair (no shared world, not in ``index``) is not separated.
    """
    test = index.get((upper, lower))
    return (test is not None and test.p_holm < alpha
            and test.only_first > test.only_second)


def rank_groups(order: Sequence[str], pairs: Sequence[SuccessPair],
                alpha: float = RANK_ALPHA) -> list[tuple[int, int]]:
    """Shared ranks of variants in a given order: the ranks the paired tests support.

    Rule: the order is cut between positions ``i`` and ``i + 1`` only when *every*
    variant at or above ``i`` succeeds significantly more often than *every*
    variant below it (:func:`separated`: Holm-adjusted McNemar p < ``alpha``, on
    the worlds the two share). The pieces between cuts are the rank groups, and a
    variant's rank is its group's span of positions (1-based). Equivalently, any
    two variants the tests cannot order end up in one group together with every
    variant between them.

    Why this rule: a distinct rank then claims only what was tested -- every
    variant ranked above is significantly better than every variant ranked below
    -- so no numbered order outruns the worlds. It depends only on the order and on
    the pairwise tests (not on the direction of a walk through the list, unlike
    "start a new group when the variant differs from the group's first or from
    all of its members"), it is deterministic, and the groups are contiguous, so a
    rank is a number or a span (``2-4``) rather than the overlapping letters of a
    compact letter display. Its price: a chain of small steps (a ~ b, b ~ c, but a
    better than c) keeps a, b and c in one group although a and c differ; such
    pairs are listed by :func:`differ_within`.

    Args:
        order: Variant names, best first (ties already broken).
        pairs: The tests of the table (:func:`success_pairs`), one table only.
        alpha: Significance level of the Holm-adjusted p-values.

    Returns:
        ``(first, last)`` rank positions (1-based) of each variant of ``order``, in
        that order; ``first == last`` for a variant alone in its rank.
    """
    index = pair_index(pairs)
    k = len(order)
    cut_after = [all(separated(order[a], order[b], index, alpha)
                     for a in range(i + 1) for b in range(i + 1, k)) for i in range(k - 1)]
    spans: list[tuple[int, int]] = []
    start = 0
    for i in range(k):
        if i == k - 1 or cut_after[i]:
            spans += [(start + 1, i + 1)] * (i + 1 - start)
            start = i + 1
    return spans


def differ_within(order: Sequence[str], spans: Sequence[tuple[int, int]],
                  pairs: Sequence[SuccessPair],
                  alpha: float = RANK_ALPHA) -> list[SuccessPair]:
    """Pairs inside one rank group that do differ significantly (chains of small steps).

    Args:
        order: Variant names, best first.
        spans: Their ranks (:func:`rank_groups`).
        pairs: The tests of the table.
        alpha: Significance level of the Holm-adjusted p-values.

    Returns:
        The tests (seen from the higher-placed variant), in the order of ``order``.
    """
    index = pair_index(pairs)
    out = []
    for i, upper in enumerate(order):
        for j in range(i + 1, len(order)):
            test = index.get((upper, order[j]))
            if spans[i] == spans[j] and test is not None and test.p_holm < alpha:
                out.append(test)
    return out
