"""Seeds until the success rate is known well enough: sequential seed allocation.

A sweep with ``max_seeds`` runs every cell -- a (scenario, variant, ladder
rung) -- with ``seeds`` seeds first. A cell whose success rate's Wilson 95 %
interval is still wider than ``±max_half_width`` gets more seeds (the next ones
in order), as many as that interval would need at the rate observed so far,
never more than ``max_seeds`` in all; this repeats until every cell is precise
enough or at ``max_seeds``. A cell that always or never succeeds is settled
early (0 of 10 runs: ``[0, 28 %]``, ±14 points), while a cell near 50 % gets up
to 40 seeds (±14.8 points). Every run is still a plain seeded run, so the
allocation is a deterministic function of the outcomes, and an interrupted
sweep resumes to the same runs.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import replace
from typing import Any

from dfcoa_opt.bench import stats
from dfcoa_opt.bench.runner import is_success
from dfcoa_opt.bench.sweep import RunSpec

Cell = tuple[str, str, str, float | None]


def cell_of(run: RunSpec) -> Cell:
    """The cell of a run: scenario, variant, ladder, rung value."""
    return (run.scenario, run.variant_name, run.ladder, run.ladder_value)


def seeds_needed(successes: int, n: int, half_width: float, limit: int) -> int:
    """Seeds for a Wilson half-width <= ``half_width`` at the observed rate, capped at ``limit``.

    Args:
        successes: Successes so far.
        n: Runs so far (> 0).
        half_width: Target half-width of the 95 % interval (fraction).
        limit: Most seeds allowed.

    Returns:
        ``n`` when the interval is already narrow enough or ``n >= limit``; else
        the least ``m`` in ``(n, limit]`` whose interval at the same rate
        (``round(successes * m / n)`` of ``m``) is narrow enough, or ``limit``.
    """
    if n >= limit or stats.wilson_half_width(successes, n) <= half_width:
        return n
    rate = successes / n
    for m in range(n + 1, limit + 1):
        if stats.wilson_half_width(round(rate * m), m) <= half_width:
            return m
    return limit


def extra_runs(runs: Sequence[RunSpec], outcomes: Mapping[str, bool], half_width: float,
               limit: int) -> list[RunSpec]:
    """The runs to add so that every cell's success rate is precise enough.

    Args:
        runs: The sweep's runs so far.
        outcomes: Run key -> success, for the runs that have a row (a failed run is
            no success); cells with a run still missing get nothing yet.
        half_width: Target half-width of the Wilson 95 % interval (fraction).
        limit: Most seeds per cell.

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
        need = seeds_needed(wins, n, half_width, limit)
        last = max(members, key=lambda r: r.seed)
        out += [replace(last, seed=last.seed + i) for i in range(1, need - n + 1)]
    return out


def success_by_key(rows: Iterable[Mapping[str, Any]]) -> dict[str, bool]:
    """Run key -> whether the run succeeded (:func:`dfcoa_opt.bench.runner.is_success`)."""
    return {str(r["key"]): is_success(r) for r in rows}
