"""The held-out report's statistics on rows made by hand."""

from __future__ import annotations

import math
import re

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dfcoa_opt.bench.recipes.heldout import _difficulty_series, _group_tables
from dfcoa_opt.bench.report import heldout as ho


def _row(variant: str, scenario: str, seed: int, outcome: str, t: float | None = None,
         difficulty: float = 0.5, ref: float = 80.0, fce: float = 0.5) -> dict:
    return {"variant": variant, "controller": variant.split("@")[0], "scenario": scenario,
            "seed": seed, "status": "ok",
            "metrics": {"outcome": outcome, "time_to_goal": t, "fce_rms": fce,
                        "world_difficulty": difficulty, "world_reference_time": ref}}


def test_barn_score_by_hand() -> None:
    assert ho.barn_score(_row("a", "s", 0, "success", t=80.0)) == 1.0      # at T_ref
    assert ho.barn_score(_row("a", "s", 0, "success", t=120.0)) == pytest.approx(80 / 120)
    assert ho.barn_score(_row("a", "s", 0, "success", t=400.0)) == 0.5      # clipped at 2 T_ref
    assert ho.barn_score(_row("a", "s", 0, "success", t=60.0)) == 1.0       # clipped at T_ref
    assert ho.barn_score(_row("a", "s", 0, "collision", t=80.0)) == 0.0


def test_variant_stats_by_hand() -> None:
    rows = [_row("a", "s", k, o, t, fce=f) for k, (o, t, f) in enumerate(
        [("success", 80.0, 0.1), ("success", 100.0, 0.2), ("deadlock", None, 3.0),
         ("collision", None, 0.4)])]
    s = ho.variant_stats("a", rows)
    assert (s.runs, s.success, s.outcomes) == (4, 2, {"success": 2, "deadlock": 1,
                                                      "collision": 1})
    assert s.barn == pytest.approx((1.0 + 0.8) / 4)
    assert s.cvar_fce == 3.0 and s.cvar_time == 100.0  # the worst 10 % of 4 and of 2: one
    assert math.isnan(ho.variant_stats("a", rows[2:]).cvar_time)


def test_worlds_failure_rates_spearman_and_bins() -> None:
    rows = []
    for seed, diff in enumerate([0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8]):
        for v, wins_below in (("a@tuned", 0.45), ("b@tuned", 0.65)):  # harder worlds fail more
            rows.append(_row(v, "s", seed, "success" if diff < wins_below else "deadlock",
                             t=90.0, difficulty=diff))
    rows.append(_row("c", "s", 0, "success", 90.0, difficulty=0.1))  # not one of the names
    ws = ho.worlds(rows, ["a@tuned", "b@tuned"])
    assert [w.failure for w in ws] == [0, 0, 0, 0, 0.5, 0.5, 1, 1]
    rho, p, n = ho.spearman(ws)
    assert n == 8 and rho == pytest.approx(0.9258, abs=1e-3) and p < 0.01
    bins = ho.difficulty_bins(ws)
    assert len(bins) == 4 and bins[0][0] == 0.1 and bins[-1][1] == 0.8
    assert [ho.bin_of(w.metrics["world_difficulty"], bins) for w in ws] == [0, 0, 1, 1, 2, 2,
                                                                            3, 3]


def test_pooled_rows_pair_world_by_world() -> None:
    rows = [_row("a", "x", 3, "success"), _row("a", "y", 3, "deadlock"),
            _row("b", "x", 3, "deadlock"), _row("b", "y", 3, "deadlock")]
    pooled = ho.pooled(rows)
    assert {r["scenario"] for r in pooled} == {ho.POOLED}
    assert [r["seed"] for r in pooled] == [0, 1, 0, 1]  # (x, 3) and (y, 3) are two worlds


def test_group_tables_count_each_groups_own_runs() -> None:
    rows = [_row("a", "x", 0, "success"), _row("a", "x", 1, "collision"),
            _row("a", "y", 0, "deadlock"), _row("a", "y", 1, "deadlock")]
    lines = _group_tables(["a"], rows, lambda r: r["scenario"], {"x": "x", "y": "y"})
    text = "\n".join(lines)
    assert "| a | 50% [9, 91] (1/2) | 0% [0, 66] (0/2) |" in text
    assert "| a | 50/50/0/0 | 0/0/100/0 |" in text


def test_bins_that_round_to_one_label_stay_apart_and_coinciding_edges_merge() -> None:
    """The subset of the report: four quartile edges of 0.291..0.33 read 0.29-0.29 twice."""
    def ws_of(diffs):
        rows = [_row("a@tuned", "rooms", s, "success", 90.0, difficulty=d)
                for s, d in enumerate(diffs)]
        return ho.worlds(rows, ["a@tuned"])

    bins = ho.difficulty_bins(ws_of([0.2910, 0.2935, 0.2942, 0.31, 0.33]))
    labels = ho.bin_labels(bins)
    assert len(bins) == 4 and len(set(labels)) == 4
    assert ho.difficulty_bins(ws_of([0.3, 0.3, 0.3])) == [(0.3, 0.3)]
    assert len(ho.difficulty_bins(ws_of([0.1, 0.2]))) == 2  # two worlds: at most two bins
    assert len(ho.difficulty_bins(ws_of([0.1, 0.1, 0.1, 0.5]))) == 2  # edges 0.1 x3 merge


_DIFFS = st.lists(st.sampled_from([0.29, 0.2901, 0.2904, 0.291, 0.2949, 0.2951, 0.30, 0.31,
                                   0.33, 0.5]), min_size=1, max_size=12)


@settings(max_examples=80, deadline=None)
@given(diffs=_DIFFS, families=st.lists(st.sampled_from(["rooms", "crowd", "cellular"]),
                                       min_size=12, max_size=12),
       wins=st.lists(st.booleans(), min_size=24, max_size=24))
def test_every_table_counts_each_world_once_per_variant(diffs, families, wins) -> None:
    """Any subset of worlds: the by-family and by-difficulty tables and the figure's data count
    every world of every variant exactly once, with the totals of the ranking (its runs)."""
    names = ["a@tuned", "b@tuned"]
    rows = [_row(v, families[i], i, "success" if wins[2 * i + j] else "deadlock", 90.0,
                 difficulty=d) for i, d in enumerate(diffs) for j, v in enumerate(names)]
    ws = ho.worlds(rows, names)
    bins = ho.difficulty_bins(ws)
    bin_of = {(w.scenario, w.seed): ho.bin_of(w.metrics["world_difficulty"], bins) for w in ws}
    tables = {
        "family": _group_tables(names, rows, lambda r: str(r["scenario"]),
                                {f: f for f in sorted(set(families[:len(diffs)]))}),
        "difficulty": _group_tables(names, rows, lambda r: bin_of.get(ho.world_key(r)),
                                    dict(enumerate(ho.bin_labels(bins)))),
    }
    series = _difficulty_series(names, rows, bins, bin_of)
    for n in names:
        ranked = [r for r in rows if r["variant"] == n]  # what the ranking counts
        wins_n = sum(r["metrics"]["outcome"] == "success" for r in ranked)
        for what, lines in tables.items():
            line = next(ln for ln in lines if ln.startswith(f"| {n} | ") and "(" in ln)
            counts = [tuple(map(int, m)) for m in re.findall(r"\((\d+)/(\d+)\)", line)]
            assert sum(k for k, _ in counts) == wins_n, what
            assert sum(m for _, m in counts) == len(ranked), what
        assert sum(p[4] for p in series[ho.method_of(n)]) == len(ranked)
        assert sum(round(p[1] * p[4]) for p in series[ho.method_of(n)]) == wins_n
