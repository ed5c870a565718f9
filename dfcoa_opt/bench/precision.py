"""Seeds until the success rate is known well enough: sequential seed allocation.

A sweep with ``max_seeds`` runs every cell -- a (scenario, variant, ladder
rung) -- with ``seeds`` seeds first. A cell whose success rate's Wilson 95 %
interval is still wider than ``±max_half_width`` gets more seeds (the next ones
in order), as many as that interval would need at the rate observed so far,
never more than ``max_seeds`` in all; this repeats until every cell is precise
enough or at ``max_seeds``. A cell that always or never succeeds is settled
early (0 of 10 runs: ``[0, 28 %]``, ±14 points), while a cell near 50 % gets up
to 40 seeds (±14.8 points).

With ``decide_at`` (a success rate, for example the ladders' 50 % break line),
a cell is also settled once its interval lies wholly on one side of it: the
report's verdict on that cell can no longer change (0 of 4 runs: ``[0, 49 %]``,
below 50 %). Every run is still a plain seeded run, so the allocation is a
deterministic function of the outcomes, and an interrupted sweep resumes to the
same runs.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import replace
from typing import Any

from dfcoa_opt.bench.report import stats
from dfcoa_opt.bench.runner import is_success
from dfcoa_opt.bench.sweep.specs import RunSpec

Cell = tuple[str, str, str, float | None]


def cell_of(run: RunSpec) -> Cell:
    """The cell of a run: scenario, variant, ladder, rung value."""
    return (run.scenario, run.variant_name, run.ladder, run.ladder_value)


def settled(successes: int, n: int, half_width: float, decide_at: float = 0.0) -> bool:
    """Whether a cell's success rate is known well enough.

    Args:
        successes: Successes so far.
        n: Runs so far (> 0).
        half_width: Target half-width of the Wilson 95 % interval (fraction).
        decide_at: A success rate (fraction) the interval may lie wholly above
            (low bound at or above it) or below (high bound below it) instead;
            0 for none.

    Returns:
        True when the interval is within ``±half_width`` or, with ``decide_at``,
        does not straddle it.
    """
    lo, hi = stats.wilson_interval(successes, n)
    return (hi - lo) / 2.0 <= half_width or (decide_at > 0.0 and (lo >= decide_at
                                                                   or hi < decide_at))


def seeds_needed(successes: int, n: int, half_width: float, limit: int,
                 decide_at: float = 0.0) -> int:
    """Seeds until the cell is :func:`settled` at the observed rate, capped at ``limit``.

    Args:
        successes: Successes so far.
        n: Runs so far (> 0).
        half_width: Target half-width of the 95 % interval (fraction).
        limit: Most seeds allowed.
        decide_at: See :func:`settled`.

    Returns:
        ``n`` when the cell is already settled or ``n >= limit``; else the least
        ``m`` in ``(n, limit]`` at which it would be at the same rate
        (``round(successes * m / n)`` of ``m``), or ``limit``.
    """
    if n >= limit or settled(successes, n, half_width, decide_at):
        return n
    rate = successes / n
    for m in range(n + 1, limit + 1):
        if settled(round(rate * m), m, half_width, decide_at):
            return m
    return limit


def extra_runs(runs: Sequence[RunSpec], outcomes: Mapping[str, bool], half_width: float,
               limit: int, decide_at: float = 0.0) -> list[RunSpec]:
    """The runs to add so that every cell's success rate is precise enough.

    Args:
        runs: The sweep's runs so far.
        outcomes: Run key -> success, for the runs that have a row (a failed run is
            no success); cells with a run still missing get nothing yet.
        half_width: Target half-width of the Wilson 95 % interval (fraction).
        limit: Most seeds per cell.
        decide_at: See :func:`settled`.

    Returns:
        New runs: per cell the next seeds after its largest, up to
        :func:`seeds_needed` in all.
    """
    cells: dict[Cell, list[RunSpec]] = {}
    for r in runs:
        cells.setdefault(cell_of(r), []).append(r)
    out: list[RunSpec] = []
    for members in cells.values():
        if any(r.key not in outcomes for r in members):
            continue
        n = len(members)
        wins = sum(outcomes[r.key] for r in members)
        need = seeds_needed(wins, n, half_width, limit, decide_at)
        last = max(members, key=lambda r: r.seed)
        out += [replace(last, seed=last.seed + i) for i in range(1, need - n + 1)]
    return out


def success_by_key(rows: Iterable[Mapping[str, Any]]) -> dict[str, bool]:
    """Run key -> whether the run succeeded (:func:`dfcoa_opt.bench.runner.is_success`)."""
    return {str(r["key"]): is_success(r) for r in rows}
