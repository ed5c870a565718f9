"""Markdown and CSV tables of a report: outcomes, metrics, paired comparisons, rankings.

Inputs are the groups of :func:`dfcoa_opt.bench.report.document.aggregate`, the
comparisons of :func:`dfcoa_opt.bench.report.paired.compare` and, for rankings, the
pairwise tests of :func:`dfcoa_opt.bench.report.paired.success_pairs`; nothing here
reads files.
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from dfcoa_opt.bench.report import paired, plots, stats
from dfcoa_opt.bench.report.paired import HIGHER_IS_BETTER, Comparison, SuccessPair
from dfcoa_opt.metrics.outcome import OUTCOMES

_MAX_ERRORS = 5  # distinct error messages listed under a table
_ERROR_CHARS = 160  # an error message is cut to this length in report.md
#: Outcome column titles.
OUTCOME_TITLES = {"success": "success", "collision": "collision", "deadlock": "deadlock",
                  "timeout": "timeout"}


def md_escape(text: Any) -> str:
    """Text safe inside a Markdown table cell (one line, no bare pipes)."""
    return " ".join(str(text).split()).replace("|", "\\|")


def rate_cell(rate: float, interval: Sequence[float], count: int, total: int) -> str:
    """``"45% [26, 66] (9/20)"``: a rate with its Wilson 95 % interval, in percent."""
    if not math.isfinite(rate):
        return "—"
    lo, hi = interval
    return f"{100 * rate:.0f}% [{100 * lo:.0f}, {100 * hi:.0f}] ({count}/{total})"


def number(x: float) -> str:
    """Three decimals, or three significant digits in exponent form from 1e4 on (risk)."""
    return f"{x:.3e}" if abs(x) >= 1e4 else f"{x:.3f}"


def metric_cell(stat: Mapping[str, Any], ok: int) -> str:
    """``"mean ± ci"``; ``"(n=k)"`` when fewer than ``ok`` values were finite.

    When every finite value is the same (``distinct == 1`` over two or more
    values) the cell says so instead of showing a zero-width interval.
    """
    mean, half, n = float(stat["mean"]), float(stat["ci95"]), int(stat["n"])
    if not math.isfinite(mean):
        text = "—"
    elif n > 1 and int(stat.get("distinct", 2)) == 1:
        text = f"{number(mean)} (1 distinct run)"
    else:
        text = f"{number(mean)} ± {number(half)}" if math.isfinite(half) else number(mean)
    return f"{text} (n={n})" if n < ok else text


def id_columns(groups: Sequence[Mapping[str, Any]], hide: Iterable[str]) -> list[str]:
    """The ``by`` fields of the groups, without ``hide``."""
    by = groups[0].get("by", ()) if groups else ()
    return [b for b in by if b not in set(hide)]


def uninformative(groups: Sequence[Mapping[str, Any]], metrics: Sequence[str]) -> list[str]:
    """Metrics with one and the same value in every run of every group (with two or more groups).

    Such a column cannot separate the variants (e.g. a risk clipped at 1 for all).
    """
    if len(groups) < 2:
        return []
    out = []
    for m in metrics:
        values = {g["stats"][m].get("value") for g in groups}
        if all(int(g["stats"][m].get("distinct", 0)) == 1 for g in groups) and len(values) == 1:
            out.append(m)
    return out


def markdown_table(groups: Sequence[Mapping[str, Any]], metrics: Sequence[str],
                   hide: Iterable[str] = ()) -> str:
    """Markdown table of aggregated groups, with notes below it.

    Columns: the grouping fields, runs, failed runs, the four outcome rates
    (% of all runs, Wilson 95 % interval, counts), then one column per metric:
    ``mean ± 95 % CI half-width`` over the runs that did not fail. Notes name the
    metrics identical for every variant, and up to five distinct run errors.

    Args:
        groups: Output of :func:`dfcoa_opt.bench.report.document.aggregate`.
        metrics: Summary keys, one column each (must have been aggregated).
        hide: Grouping fields not to show as columns (e.g. ``("scenario",)``).

    Returns:
        The Markdown text, ending with a newline.
    """
    ids = id_columns(groups, hide)
    flat = uninformative(groups, metrics)
    head = [*ids, "runs", "failed", *OUTCOME_TITLES.values()]
    head += [plots.metric_header(m) + (" ⚠" if m in flat else "") for m in metrics]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for g in groups:
        cells = [md_escape(g[b]) for b in ids] + [str(g["runs"]), str(g["failed"])]
        cells += [rate_cell(g[f"{o}_rate"], g[f"{o}_ci"], g["outcomes"][o], g["runs"])
                  for o in OUTCOMES]
        cells += [metric_cell(g["stats"][m], int(g["ok"])) for m in metrics]
        lines.append("| " + " | ".join(cells) + " |")
    if flat:
        lines += ["", "⚠ Identical in every run of every variant, so it separates nothing here: "
                  + ", ".join(plots.metric_header(m) for m in flat) + "."]
    failed = [(g, e) for g in groups for e in g.get("errors", [])]
    if failed:
        lines += ["", "Errors of failed runs:"]
        for g, err in failed[:_MAX_ERRORS]:
            who = " / ".join(md_escape(g[b]) for b in ids)
            short = md_escape(err)
            short = short if len(short) <= _ERROR_CHARS else short[:_ERROR_CHARS - 1] + "…"
            lines.append(f"- {who}: {short}")
        if len(failed) > _MAX_ERRORS:
            lines.append(f"- … and {len(failed) - _MAX_ERRORS} more distinct error(s)")
    return "\n".join(lines) + "\n"


def deploy_table(groups: Sequence[Mapping[str, Any]], metrics: Sequence[str],
                 hide: Iterable[str] = ()) -> str:
    """Markdown table of the deployability keys (``mean ± 95 % CI`` over the ok runs).

    A key no run has (the Robotarium's checks of robots other than the gritsbot,
    the wheels of holonomic robots) is left out; with none left the text is empty.
    """
    shown = [m for m in metrics if any(g["stats"][m]["n"] for g in groups)]
    if not shown:
        return ""
    ids = id_columns(groups, hide)
    head = [*ids, "runs", *(plots.metric_header(m) for m in shown)]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for g in groups:
        cells = [md_escape(g[b]) for b in ids] + [str(g["runs"])]
        cells += [metric_cell(g["stats"][m], int(g["ok"])) for m in shown]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _csv_num(value: Any) -> str:
    """A number as CSV text: shortest round-trip float, empty for NaN/inf and None."""
    if value is None:
        return ""
    if not isinstance(value, float):
        return str(value)
    return repr(value) if math.isfinite(value) else ""


def csv_table(groups: Sequence[Mapping[str, Any]], metrics: Sequence[str]) -> str:
    """CSV of aggregated groups, one numeric column per statistic.

    Columns: the grouping fields, ``runs``, ``failed``, ``ok``, then per outcome
    ``<outcome>_rate`` with ``<outcome>_ci_low`` and ``<outcome>_ci_high`` (Wilson
    95 %; fractions of all runs), ``reached_rate`` (the goal condition, contacts or
    not), then ``<metric>_mean``, ``<metric>_ci95``, ``<metric>_n`` and
    ``<metric>_distinct`` per metric (empty cells for NaN).
    """
    ids = id_columns(groups, ())
    head = [*ids, "runs", "failed", "ok"]
    head += [f"{o}_{s}" for o in OUTCOMES for s in ("rate", "ci_low", "ci_high")]
    head += ["reached_rate"]
    head += [f"{m}_{s}" for m in metrics for s in ("mean", "ci95", "n", "distinct")]
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(head)
    for g in groups:
        row: list[Any] = [g[b] for b in ids] + [g["runs"], g["failed"], g["ok"]]
        for o in OUTCOMES:
            row += [g[f"{o}_rate"], *g[f"{o}_ci"]]
        row.append(g["reached_rate"])
        row += [g["stats"][m][s] for m in metrics for s in ("mean", "ci95", "n", "distinct")]
        writer.writerow([_csv_num(v) for v in row])
    return buf.getvalue()


def _diff_cell(c: Comparison) -> str:
    """``"-0.120 [-0.200, -0.050] p=0.004 better"`` (success: rate difference in points).

    ``"(k excluded)"`` follows when k seeds had no finite value on either side.
    """
    excluded = f" ({c.excluded} excluded)" if c.excluded else ""
    if c.n == 0 or not math.isfinite(c.estimate):
        return "—" + excluded
    if c.metric == "success":
        text = f"{100 * c.estimate:+.0f} pts"
    else:
        text = "+" * (c.estimate >= 0) + number(c.estimate)
        if math.isfinite(c.ci_low):
            text += f" [{number(c.ci_low)}, {number(c.ci_high)}]"
    verdict = {"better": "**better**", "worse": "**worse**"}.get(c.verdict, "")
    return f"{text} p={c.p_holm:.3g} {verdict}".rstrip() + excluded


def paired_table(comparisons: Sequence[Comparison], metrics: Sequence[str],
                 baseline: str) -> str:
    """Markdown table of one table's comparisons: one row per variant, one column per metric."""
    variants = list(dict.fromkeys(c.variant for c in comparisons))
    cols = ["success", *metrics]
    cell = {(c.variant, c.metric): c for c in comparisons}
    head = ["variant − " + md_escape(baseline)] + [
        "success (rate)" if m == "success" else plots.metric_header(m) for m in cols]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for v in variants:
        lines.append("| " + " | ".join([md_escape(v)] + [
            _diff_cell(cell[(v, m)]) if (v, m) in cell else "—" for m in cols]) + " |")
    better = ", ".join(sorted(m for m in cols if m in HIGHER_IS_BETTER))
    lines += ["", f"Each cell: the median over seeds of (variant − {md_escape(baseline)}) with "
              "its bootstrap 95 % CI, and the Wilcoxon signed-rank p-value; success: the "
              "difference of the success rates in points and McNemar's exact p-value. "
              "A seed where either run has no finite value (a failed run, no time to goal, "
              "a raw risk after a contact) is left out of that metric: `(k excluded)`. "
              "p-values are Holm-corrected across this table; **better**/**worse** at 5 %. "
              f"Higher is better for {better}; lower for the rest."]
    return "\n".join(lines) + "\n"


def rank_label(span: tuple[int, int]) -> str:
    """``"3"`` for a variant alone in its rank, ``"2-4"`` for a rank shared by positions 2 to 4."""
    first, last = span
    return str(first) if first == last else f"{first}-{last}"


def worlds_to_separate(test: SuccessPair | None, alpha: float = paired.RANK_ALPHA,
                       power: float = 0.8) -> float:
    """Worlds a McNemar test would need to separate two variants at their observed rates.

    The observed proportions of the shared worlds where only one of them
    succeeded go into Connor's (1987) formula
    (:func:`dfcoa_opt.bench.report.stats.mcnemar_sample_size`, two-sided ``alpha``
    for this one pair, before any Holm correction, so a rough lower figure).

    Args:
        test: The pair's test (:class:`SuccessPair`), or None when it was not tested.
        alpha: Two-sided significance level.
        power: Power of the planned test.

    Returns:
        Worlds (pairs of runs), not rounded; NaN when the pair was not tested, had no
        shared world, already differs (Holm-adjusted p < ``alpha``) or succeeded
        equally often (no estimate).
    """
    if test is None or test.worlds == 0 or test.p_holm < alpha:
        return math.nan
    return stats.mcnemar_sample_size(test.only_first / test.worlds,
                                     test.only_second / test.worlds, alpha, power)


def ranking_legend(tested: int | None = None) -> str:
    """How to read a ranking's shared ranks and its last column (Markdown, one paragraph each).

    Args:
        tested: The pairs tested in the table, or None for a legend of several tables.
    """
    pairs = ("all the tested pairs" if tested is None
             else f"all {tested} tested pair{'' if tested == 1 else 's'}")
    return ("Rank: variants share a rank (`2-4`: anywhere from 2nd to 4th) when the worlds "
            "cannot order their success. The rank changes between two rows only where every "
            "variant above succeeds significantly more often than every variant below: "
            "McNemar's exact test on the worlds both ran (same scenario and seed), with the "
            f"p-values of {pairs} of variants of the table Holm-corrected together, p < 0.05. "
            "Within a shared rank the rows follow the observed rates only. The column against "
            "the baseline is Holm-corrected over its own set of tests, so it can call a "
            "difference the ranks do not.\n\nWorlds to separate from the next: the worlds "
            "(pairs of runs) a McNemar test would need to tell this variant from the next row "
            "with 80 % power at 5 % (two-sided, this pair alone, before Holm), at the observed "
            "shares of the worlds where only one of the two succeeded (Connor 1987); — : they "
            "already differ, share no world, never succeed on different worlds, or there is no "
            "next row.")


def ranking_table(groups: Sequence[Mapping[str, Any]], comparisons: Sequence[Comparison],
                  baseline: str, pairs: Sequence[SuccessPair], legend: bool = True) -> str:
    """Markdown ranking of the variants of one table, with the ranks the tests support.

    Order: success rate (high first), then collision rate (low first), then mean
    time to goal (short first; undefined last). Ranks: :func:`paired.rank_groups`
    (the order is cut only where every variant above succeeds significantly more
    often than every variant below: McNemar exact, Holm over all the pairs of the
    table, p < 0.05); variants of one group share the span of their positions
    (``2-4``). The last column gives, for each variant and the next one in the
    order, the worlds a McNemar test would need to separate them at the observed
    rates (:func:`worlds_to_separate`, Connor 1987, alpha 0.05, power 0.8). A
    sentence under the table says what a shared rank means and how many pairs were
    tested, then the pairs of one group that do differ, if any.

    Args:
        groups: The table's groups (:func:`dfcoa_opt.bench.report.document.aggregate`,
            one per variant).
        comparisons: Success of each variant against ``baseline``
            (:func:`paired.compare`; other metrics are ignored).
        baseline: The baseline variant's name.
        pairs: Success between every two variants of this table
            (:func:`paired.success_pairs` of the table's rows; one table only).
        legend: Put :func:`ranking_legend` under the table; False: one line with the
            count of tested pairs (a report of several rankings prints the legend once).

    Returns:
        The Markdown text, ending with a newline.

    Raises:
        ValueError: ``pairs`` from more than one table.
    """
    verdict = {c.variant: c for c in comparisons if c.metric == "success"}

    def key(g: Mapping[str, Any]) -> tuple[float, float, float]:
        ttg = float(g["stats"].get("time_to_goal", {}).get("mean", math.nan))
        return (-g["success_rate"], g["collision_rate"], ttg if math.isfinite(ttg) else math.inf)

    ranked = sorted(groups, key=key)
    order = [str(g["variant"]) for g in ranked]
    index = paired.pair_index(pairs)
    spans = paired.rank_groups(order, pairs)
    lines = ["| rank | variant | success | most frequent failure | success vs "
             f"{md_escape(baseline) or 'baseline'} | worlds to separate from the next |",
             "|---|---|---|---|---|---|"]
    for i, g in enumerate(ranked):
        v = order[i]
        c = verdict.get(v)
        vs = "baseline" if v == baseline else (_diff_cell(c) if c else "—")
        fail = g.get("dominant_failure")
        fail_text = (f"{fail} ({100 * g[f'{fail}_rate']:.0f}%)" if fail in OUTCOMES
                     else f"{fail}" if fail else "—")
        rate = rate_cell(g["success_rate"], g["success_ci"], g["outcomes"]["success"], g["runs"])
        need = (worlds_to_separate(index.get((v, order[i + 1])))
                if i + 1 < len(order) else math.nan)
        need_text = f"≈ {math.ceil(need)}" if math.isfinite(need) else "—"
        lines.append(f"| {rank_label(spans[i])} | {md_escape(v)} | {rate} | {fail_text} | {vs} "
                     f"| {need_text} |")
    names = set(order)
    tested = sum(math.isfinite(p.p_value) for p in pairs
                 if p.first in names and p.second in names)
    plural = "" if tested == 1 else "s"
    if legend:
        lines += ["", ranking_legend(tested)]
    else:
        lines += ["", f"Shared ranks: {tested} tested pair{plural} of variants, Holm-corrected "
                      "together (how to read the ranking: above the tables)."]
    inside = paired.differ_within(order, spans, pairs)
    if inside:
        lines += ["", "Inside a shared rank, significantly different (linked by variants "
                  "between them that neither differs from): " + "; ".join(
                      f"`{md_escape(t.first)}` and `{md_escape(t.second)}` (p = {t.p_holm:.3g})"
                      for t in inside) + "."]
    return "\n".join(lines) + "\n"


def ladder_table(groups: Sequence[Mapping[str, Any]], label: str) -> str:
    """Success rate per variant (rows) and rung (columns) of one ladder on one scenario."""
    values = sorted({float(g["ladder_value"]) for g in groups})
    variants = list(dict.fromkeys(str(g["variant"]) for g in groups))
    cell = {(str(g["variant"]), float(g["ladder_value"])): g for g in groups}
    head = [f"variant \\ {md_escape(label)}"] + [f"{v:g}" for v in values]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for v in variants:
        cells = [md_escape(v)]
        for x in values:
            g = cell.get((v, x))
            cells.append("—" if g is None else rate_cell(g["success_rate"], g["success_ci"],
                                                           g["outcomes"]["success"], g["runs"]))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def overrides_note(groups: Sequence[Mapping[str, Any]]) -> list[str]:
    """What the variants set (names, never hashes): the settings all share, then each one's own."""
    sets = {str(g["variant"]): {k: json.dumps(v, sort_keys=True)
                                for k, v in (g.get("overrides") or {}).items()}
            for g in groups}
    if not sets:
        return []
    common = dict(set.intersection(*(set(o.items()) for o in sets.values())))
    lines = [f"- every variant: `{k} = {v}`" for k, v in sorted(common.items())]
    for name, ov in sorted(sets.items()):
        own = {k: v for k, v in ov.items() if k not in common}
        if own:
            lines.append(f"- `{md_escape(name)}`: " + ", ".join(f"`{k} = {v}`"
                                                              for k, v in sorted(own.items())))
    return lines


def paired_csv(comparisons: Sequence[Comparison]) -> str:
    """CSV of every paired comparison (one row per table, variant and metric).

    ``n`` seeds paired, ``excluded`` seeds left out (a value not finite); an
    undefined number is an empty cell.
    """
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["scenario", "ladder", "ladder_value", "variant", "metric", "n", "excluded",
                "estimate", "ci_low", "ci_high", "p_value", "p_holm", "verdict"])
    for c in comparisons:
        w.writerow([*c.table[:2], "" if c.table[2] is None else c.table[2], c.variant, c.metric,
                    c.n, c.excluded, *(repr(v) if math.isfinite(v) else "" for v in
                           (c.estimate, c.ci_low, c.ci_high, c.p_value, c.p_holm)), c.verdict])
    return buf.getvalue()


def success_matrix(rows: Sequence[Mapping[str, Any]]) -> str:
    """Markdown: successes of every variant (rows) on every scenario (columns), ``k/n``.

    What a reader picking scenarios wants first: which ones separate the
    methods they compare, and which every method fails. A bold cell is a
    success rate of at least 50 %.
    """
    scen = sorted({str(r["scenario"]) for r in rows})
    names = sorted({plots.variant_name(r) for r in rows})
    count: dict[tuple[str, str], list[int]] = {}
    for r in rows:
        c = count.setdefault((plots.variant_name(r), str(r["scenario"])), [0, 0])
        c[0] += r.get("status") == "ok" and (r.get("metrics") or {}).get("outcome") == "success"
        c[1] += 1
    lines = ["| variant | " + " | ".join(md_escape(s) for s in scen) + " |",
             "|---|" + "---|" * len(scen)]
    for n in names:
        cells = []
        for s in scen:
            k, total = count.get((n, s), (0, 0))
            cell = f"{k}/{total}" if total else "—"
            cells.append(f"**{cell}**" if total and 2 * k >= total else cell)
        lines.append(f"| {md_escape(n)} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
