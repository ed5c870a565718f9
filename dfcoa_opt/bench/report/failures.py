"""Why a variant fails: its most frequent failure and a snapshot of the first failing seed.

For every (scenario, variant) whose success rate is below 50 %, the report
names the most frequent non-success outcome (collision, deadlock, timeout, or
``failed`` for runs that raised) and links a snapshot of the smallest seed that
ended that way: the map and the robots at the first contact (collision), at the
onset of the deadlock, or at the end of the run (timeout).

A reduced ``make figures`` (the smoke test's 3 s missions, where every variant
fails) may draw fewer: inside :func:`snapshot_limit`, each :func:`explain`
call draws at most that many snapshots and says of the other groups that
their snapshot was left out.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from dfcoa_opt.bench.report import plots, trajectories
from dfcoa_opt.bench.results.logs import LogCompacted
from dfcoa_opt.bench.sweep.specs import KEY_MAX, safe_name, shorten
from dfcoa_opt.core.errors import DfcoaError

Row = Mapping[str, Any]
#: A (scenario, variant) is explained when its success rate is below this.
EXPLAIN_BELOW = 0.5
#: The failure classes, in the order used to break ties of equal counts.
FAILURES = ("collision", "deadlock", "timeout", "failed")
#: The snapshots an :func:`explain` call draws at most (None: every one), set by
#: :func:`snapshot_limit` in the process that renders.
_LIMIT: list[int | None] = [None]


@contextmanager
def snapshot_limit(n: int | None) -> Iterator[None]:
    """Within the block, each :func:`explain` call draws at most ``n`` snapshots (None: all).

    Args:
        n: Snapshots per call, at least 1; None leaves every snapshot in.

    Raises:
        ValueError: ``n`` below 1.
    """
    if n is not None and n < 1:
        raise ValueError(f"snapshot limit {n}: must be at least 1 (None: no limit)")
    before, _LIMIT[0] = _LIMIT[0], n
    try:
        yield
    finally:
        _LIMIT[0] = before


def run_outcome(row: Row) -> str:
    """A row's outcome, or ``"failed"`` for a run that raised."""
    if row.get("status") != "ok":
        return "failed"
    return str((row.get("metrics") or {}).get("outcome", "timeout"))


def dominant_failure(rows: Sequence[Row]) -> str | None:
    """The most frequent non-success outcome of some runs (None when all succeeded)."""
    counts = {f: sum(run_outcome(r) == f for r in rows) for f in FAILURES}
    best = max(FAILURES, key=lambda f: (counts[f], -FAILURES.index(f)))
    return best if counts[best] else None


def snapshot_time(row: Row) -> float:
    """When to show a failing run: first contact, deadlock onset, else its last instant, s."""
    m = row.get("metrics") or {}
    for key in ("first_contact_time", "deadlock_time"):
        t = m.get(key)
        if isinstance(t, (int, float)) and math.isfinite(t):
            return float(t)
    return math.inf


def explain(groups: Sequence[Mapping[str, Any]], rows: Sequence[Row], results_dir: Path,
            out_dir: Path) -> tuple[list[str], list[Path]]:
    """Markdown lines explaining every group below :data:`EXPLAIN_BELOW`, and their snapshots.

    Args:
        groups: Aggregated groups of one table
            (:func:`dfcoa_opt.bench.report.document.aggregate`).
        rows: Their rows.
        results_dir: The results folder (logs).
        out_dir: Where the snapshots go (``fail_<scenario>_<variant>_s<seed>.png``).

    Returns:
        The lines (a bullet per explained group) and the snapshot files written.
    """
    lines: list[str] = []
    written: list[Path] = []
    for g in groups:
        if g["success_rate"] >= EXPLAIN_BELOW:
            continue
        mine = [r for r in rows if str(r["scenario"]) == str(g["scenario"])
                and plots.variant_name(r) == str(g["variant"])
                and r.get("ladder_value") == g.get("ladder_value")]
        why = dominant_failure(mine)
        if why is None:
            continue
        share = sum(run_outcome(r) == why for r in mine)
        first = min((r for r in mine if run_outcome(r) == why), key=lambda r: int(r["seed"]))
        text = (f"- `{g['variant']}` on `{g['scenario']}`: success {100 * g['success_rate']:.0f}%;"
                f" most runs end in **{why}** ({share}/{len(mine)}); first: seed {first['seed']}")
        if why == "failed":
            lines.append(f"{text}: {' '.join(str(first.get('error')).split())[:160]}")
            continue
        if _LIMIT[0] is not None and len(written) >= _LIMIT[0]:
            lines.append(f"{text} (snapshot left out: this reduced run draws {_LIMIT[0]} per "
                         "scenario)")
            continue
        t = snapshot_time(first)
        stem = f"fail_{safe_name(g['scenario'])}_{safe_name(g['variant'])}_s{first['seed']}"
        name = f"{shorten(stem, KEY_MAX)}.png"
        try:
            if not first.get("log"):
                raise DfcoaError("the run has no log")
            path = trajectories.snapshot_figure(first, results_dir, out_dir / name, t)
        except LogCompacted:
            raise  # ``make figures`` runs the run again and renders anew
        except DfcoaError as exc:
            lines.append(f"{text} (no snapshot: {exc})")
            continue
        written.append(path)
        when = {"collision": "first contact", "deadlock": "deadlock onset"}.get(why, "end")
        lines.append(f"{text}, [{when}]({name})")
    return lines, written
