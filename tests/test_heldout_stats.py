"""The held-out report's statistics on rows made by hand."""

from __future__ import annotations

import math

import pytest

from dfcoa_opt.bench.recipes.heldout import _group_tables
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
    lines = _group_tables(["a"], rows, lambda r: r["scenario"], ["x", "y"])
    text = "\n".join(lines)
    assert "| a | 50% [9, 91] (1/2) | 0% [0, 66] (0/2) |" in text
    assert "| a | 50/50/0/0 | 0/0/100/0 |" in text
