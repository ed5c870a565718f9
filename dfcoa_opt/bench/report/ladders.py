"""The ladder sections of a report: success rate against each rung, and where variants break."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from dfcoa_opt.bench.report import failures, plots, tables
from dfcoa_opt.bench.sweep.specs import KEY_MAX, safe_name, shorten


def sections(groups: Sequence[Mapping[str, Any]], manifest: Mapping[str, Any],
             out_dir: Path, written: list[Path]) -> list[str]:
    """Markdown and figures of every ladder: success rate against the rung's value.

    Args:
        groups: Aggregated groups of the ladder rows (by scenario, ladder, rung, variant).
        manifest: The sweep's manifest (the ladders' rung order and axis scale).
        out_dir: Where the figures go (``ladder_<label>_<scenario>.png``).
        written: Written figures are appended here.

    Returns:
        The Markdown lines.
    """
    ladders = [lad for lad in manifest.get("ladders") or [] if isinstance(lad, Mapping)]
    log_x = {str(lad.get("label")): bool(lad.get("log_x")) for lad in ladders}
    order = {str(lad.get("label")): [float(v) for v in lad.get("values") or []]
             for lad in ladders}
    md: list[str] = []
    for label in dict.fromkeys(str(g["ladder"]) for g in groups):
        for scen in sorted({str(g["scenario"]) for g in groups if str(g["ladder"]) == label}):
            mine = [g for g in groups if str(g["ladder"]) == label and str(g["scenario"]) == scen]
            series: dict[str, list[tuple[float, float, float, float, int]]] = {}
            for g in sorted(mine, key=lambda g: float(g["ladder_value"])):
                lo, hi = g["success_ci"]
                series.setdefault(str(g["variant"]), []).append(
                    (float(g["ladder_value"]), g["success_rate"], lo, hi, int(g["runs"])))
            name = f"{shorten(f'ladder_{safe_name(label)}_{safe_name(scen)}', KEY_MAX)}.png"
            written.append(plots.ladder_figure(series, label, out_dir / name,
                                               f"{scen}: success rate against {label}",
                                               log_x=log_x.get(label, False)))
            widest = max(((hi - lo) / 2 for g in mine for lo, hi in [g["success_ci"]]),
                         default=math.nan)
            md += [f"## Ladder `{label}` on `{scen}`", "", tables.ladder_table(mine, label),
                   f"Success rate with its Wilson 95 % interval; the widest interval is "
                   f"±{100 * widest:.0f} points (one that lies wholly above or below 50 % "
                   f"settles where the variant breaks however wide it is).", "",
                   f"![ladder {label}]({name})", ""]
            md += ["Where each variant breaks, going up the ladder (the rungs in the sweep "
                   "file's order, easy to hard): the first rung below 50 % success and its "
                   "most frequent failure.", "",
                   *_break_points(mine, order.get(label, [])), ""]
    return md


def _break_points(groups: Sequence[Mapping[str, Any]], order: Sequence[float]) -> list[str]:
    """One line per variant: the first rung (in ``order``) below 50 % success, and why."""
    rank = {v: i for i, v in enumerate(order)}
    lines = []
    for variant in dict.fromkeys(str(g["variant"]) for g in groups):
        mine = sorted((g for g in groups if str(g["variant"]) == variant),
                      key=lambda g: rank.get(float(g["ladder_value"]), len(rank)))
        low = [g for g in mine if g["success_rate"] < failures.EXPLAIN_BELOW]
        if not low:
            lines.append(f"- `{variant}`: at least 50 % success on every rung")
        elif low[0] is mine[0] and len(low) == len(mine):
            lines.append(f"- `{variant}`: below 50 % on every rung; at the easiest, "
                         f"{float(mine[0]['ladder_value']):g}: {mine[0]['dominant_failure']}")
        else:
            g = low[0]
            lines.append(f"- `{variant}`: breaks at {float(g['ladder_value']):g} "
                         f"({100 * g['success_rate']:.0f} % success, mostly "
                         f"{g['dominant_failure']})")
    return lines
