"""The held-out benchmark's statistics: test worlds, difficulty, scores, defaults against tuned.

Inputs are the rows of the ``heldout`` sweep (every variant with its defaults,
and every ``<variant>@tuned`` of ``dfcoa tune``, on test seeds of the generated
families) and the variants files; nothing here simulates. The renderer,
:mod:`dfcoa_opt.bench.recipes.heldout`, turns these into tables and figures.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dfcoa_opt.bench.report import stats
from dfcoa_opt.bench.report.plots import as_number, variant_name
from dfcoa_opt.bench.runner import is_success

Row = Mapping[str, Any]
#: Suffix of a tuned variant (:data:`dfcoa_opt.bench.tune.TUNED`).
TUNED = "@tuned"
#: The scenario name of pooled rows.
POOLED = "all test worlds"
#: BARN's score clips the time to goal to this many reference times at most.
BARN_CLIP = 2.0
#: The worst-case level of the CVaR columns.
ALPHA = 0.9


def is_tuned(name: str) -> bool:
    """Whether a variant name is a tuned variant's."""
    return name.endswith(TUNED)


def method_of(name: str) -> str:
    """The method a variant name belongs to (``dfcoa@tuned`` -> ``dfcoa``)."""
    return name[:-len(TUNED)] if is_tuned(name) else name


def world_key(row: Row) -> tuple[str, int]:
    """The test world of a row: its scenario and seed."""
    return str(row["scenario"]), int(row["seed"])


def pooled(rows: Sequence[Row]) -> list[dict[str, Any]]:
    """The rows as one table over every test world: scenario :data:`POOLED`, seed = world number.

    Worlds are numbered in (scenario, seed) order, so the paired statistics of
    :mod:`dfcoa_opt.bench.report.paired` pair two variants world by world.
    """
    number = {w: i for i, w in enumerate(sorted({world_key(r) for r in rows}))}
    return [{**r, "scenario": POOLED, "seed": number[world_key(r)]} for r in rows]


def barn_score(row: Row) -> float:
    """BARN's score of a run: ``success x T_ref / clip(T, T_ref, 2 T_ref)``, in [0, 1].

    ``T`` is the time to goal and ``T_ref`` the leader's time along its reference
    path (``world_reference_time``). BARN clips to ``[4, 8]`` optimal times of a
    robot at full speed; here the reference moves at the leader's own speed, so
    the clip is ``[1, 2]`` reference times: a success scores 0.5 to 1.
    """
    if not is_success(row):
        return 0.0
    m = row.get("metrics") or {}
    ref, t = as_number(m.get("world_reference_time")), as_number(m.get("time_to_goal"))
    if not (math.isfinite(ref) and ref > 0 and math.isfinite(t)):
        return 0.0
    return ref / min(max(t, ref), BARN_CLIP * ref)


@dataclass(frozen=True)
class VariantStats:
    """One variant over a set of test worlds.

    Attributes:
        variant: Its name.
        runs: Runs.
        outcomes: Outcome -> count (``failed`` for runs that raised).
        success: Successes.
        interval: Wilson 95 % interval of the success rate.
        barn: Mean BARN score.
        cvar_fce: CVaR(0.9) of the formation centroid error RMS over every run, m.
        cvar_time: CVaR(0.9) of the time to goal over the successes, s (NaN without one).
    """

    variant: str
    runs: int
    outcomes: dict[str, int]
    success: int
    interval: tuple[float, float]
    barn: float
    cvar_fce: float
    cvar_time: float


def variant_stats(name: str, rows: Sequence[Row]) -> VariantStats:
    """:class:`VariantStats` of ``rows`` (one variant's)."""
    from dfcoa_opt.bench.report.failures import run_outcome

    outcomes: dict[str, int] = {}
    for r in rows:
        o = run_outcome(r)
        outcomes[o] = outcomes.get(o, 0) + 1
    wins = sum(is_success(r) for r in rows)
    fce = [as_number((r.get("metrics") or {}).get("fce_rms")) if r.get("status") == "ok"
           else math.nan for r in rows]
    times = [as_number((r.get("metrics") or {}).get("time_to_goal")) for r in rows
             if is_success(r)]
    return VariantStats(name, len(rows), outcomes, wins, stats.wilson_interval(wins, len(rows)),
                        float(np.mean([barn_score(r) for r in rows])), stats.cvar(fce, ALPHA),
                        stats.cvar(times, ALPHA) if times else math.nan)


@dataclass(frozen=True)
class World:
    """A test world seen by a set of variants.

    Attributes:
        scenario: The scenario (family file).
        seed: The test seed.
        metrics: Its ``world_*`` difficulty metrics.
        failure: Fraction of the variants that did not succeed there.
        variants: How many variants ran it.
    """

    scenario: str
    seed: int
    metrics: dict[str, float]
    failure: float
    variants: int


def worlds(rows: Sequence[Row], names: Sequence[str]) -> list[World]:
    """The test worlds every variant of ``names`` ran, with the variants' failure rate."""
    by: dict[tuple[str, int], dict[str, Row]] = {}
    for r in rows:
        if variant_name(r) in names:
            by.setdefault(world_key(r), {})[variant_name(r)] = r
    out = []
    for (scen, seed), mine in sorted(by.items()):
        if len(mine) != len(names):
            continue
        first = next(r for r in mine.values() if r.get("metrics"))
        metrics = {k: as_number(v) for k, v in (first.get("metrics") or {}).items()
                   if k.startswith("world_")}
        fail = 1.0 - sum(is_success(r) for r in mine.values()) / len(mine)
        out.append(World(scen, seed, metrics, fail, len(mine)))
    return out


def spearman(ws: Sequence[World]) -> tuple[float, float, int]:
    """Spearman's rho between the difficulty index and the failure rate, its p-value, n."""
    from scipy.stats import spearmanr

    x = [w.metrics.get("world_difficulty", math.nan) for w in ws]
    y = [w.failure for w in ws]
    keep = [i for i, v in enumerate(x) if math.isfinite(v)]
    if len(keep) < 3 or len({y[i] for i in keep}) < 2:
        return math.nan, math.nan, len(keep)
    res = spearmanr([x[i] for i in keep], [y[i] for i in keep])
    return float(res.statistic), float(res.pvalue), len(keep)


def difficulty_bins(ws: Sequence[World], count: int = 4) -> list[tuple[float, float]]:
    """At most ``count`` bins of the difficulty index with about as many worlds each.

    The edges are quantiles of the worlds' index; edges that coincide merge, so
    a subset with fewer distinct values than bins gets fewer bins (one bin
    ``(v, v)`` when every world has the same index). The last bin is closed on
    the right; the bins cover every world. A bin is known by its index
    (:func:`bin_of`), never by its label: two bins can round to one label.
    """
    x = np.sort([w.metrics["world_difficulty"] for w in ws])
    edges = np.unique(np.quantile(x, np.linspace(0.0, 1.0, max(1, min(count, len(x))) + 1)))
    if len(edges) == 1:
        return [(float(edges[0]), float(edges[0]))]
    return [(float(a), float(b)) for a, b in zip(edges[:-1], edges[1:], strict=True)]


def bin_of(value: float, bins: Sequence[tuple[float, float]]) -> int:
    """The index of the bin of a difficulty value (the last bin takes its right edge)."""
    for i, (lo, hi) in enumerate(bins):
        if lo <= value < hi or (i == len(bins) - 1 and value == hi):
            return i
    return len(bins) - 1 if value > bins[-1][1] else 0


def bin_labels(bins: Sequence[tuple[float, float]]) -> list[str]:
    """``"lo–hi"`` of each bin, with two decimals, or as many more as tell the bins apart."""
    labels: list[str] = []
    for digits in range(2, 17):
        labels = [f"{a:.{digits}f}–{b:.{digits}f}" for a, b in bins]
        if len(set(labels)) == len(labels):
            break
    return labels


def read_tuned(paths: Sequence[Path]) -> dict[str, dict[str, Any]]:
    """The ``[tuned]`` tables of variants files, by tuned variant name."""
    from dfcoa_opt.scenario.overrides import read_toml

    out = {}
    for p in paths:
        data = read_toml(p)
        for name in data.get("variants", {}):
            out[str(name)] = dict(data.get("tuned", {}))
    return out
