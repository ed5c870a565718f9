"""Benchmark report: statistics, tables, environment header, figures, end to end."""

from __future__ import annotations

import csv
import hashlib
import io
import json
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from dfcoa_opt import metrics as run_metrics
from dfcoa_opt.bench.report import document as report
from dfcoa_opt.bench.report import failures, paired, plots, stats, tables, trajectories
from dfcoa_opt.core.errors import DfcoaError
from dfcoa_opt.core.runtime import dispatch, provenance
from dfcoa_opt.scenario.loader import read_toml, scenario_from_dict
from dfcoa_opt.sim.simulator import run_scenario

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "scenarios" / "example_empty.toml"
#: t_{0.975, dof} for dof 1, 2, 3, from statistical tables (not computed with scipy).
T975 = {1: 12.706204736174707, 2: 4.302652729911275, 3: 3.182446305284263}
SHA = "0123456789abcdef" * 4
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def row(key, controller="ctl_a", status="ok", scenario="sc", seed=0, variant=None,
        finished="2024-05-01T10:00:00Z", error=None, **mets):
    return {"key": key, "scenario": scenario, "scenario_file": "/nonexistent.toml",
            "controller": controller, "variant": variant or controller, "seed": seed,
            "overrides": {}, "status": status, "error": error,
            "metrics": mets if status == "ok" else None, "digest": None, "log": None,
            "provenance": {"wall_time": 1.0, "finished": finished, "host": "h1", "pid": 1}}


def synthetic_rows():
    """ctl_a: 3 ok runs (1 success, 1 collision after arriving, 1 deadlock) + 1 failed;
    ctl_b: 1 ok run (timeout)."""
    return [
        row("a0", seed=0, outcome="success", reached=True, collisions=0, time_to_goal=10.0,
            fce_rms=1.0),
        row("a1", seed=1, outcome="collision", reached=True, collisions=2, time_to_goal=12.0,
            fce_rms=2.0),
        row("a2", seed=2, outcome="deadlock", reached=False, collisions=0, time_to_goal=None,
            fce_rms=3.0),
        row("a3", seed=3, status="failed", error="controller 'ctl_a' returned NaN at t=1.0 s",
            finished="2024-05-01T11:00:00-02:00"),  # 13:00 UTC: the newest instant
        row("b0", controller="ctl_b", outcome="timeout", reached=False, collisions=0,
            time_to_goal=None, fce_rms=0.5, finished="2024-05-01T12:00:00+00:00"),
    ]


def write_results(folder: Path, rows, manifest=None) -> Path:
    (folder / "rows").mkdir(parents=True)
    for r in rows:
        (folder / "rows" / f"{r['key']}.json").write_text(json.dumps(r))
    man = {"name": "demo", "sweep_file": "sweep.toml", "sweep_sha256": SHA,
           "created": "2024-05-01T09:00:00Z"} if manifest is None else manifest
    (folder / "manifest.json").write_text(json.dumps(man))
    return folder


# ------------------------------------------------------------------------ statistics
def test_ci_half_width_matches_hand_computation():
    mean, half, n = report.mean_ci95([1, 2, 3, 4])
    std = math.sqrt(((1.5**2 + 0.5**2) * 2) / 3)  # sample std, ddof 1
    assert (mean, n) == (2.5, 4)
    assert half == pytest.approx(T975[3] * std / 2.0, rel=1e-12)


def test_ci_skips_null_nan_and_needs_two_values():
    assert report.mean_ci95([None, float("nan"), 5.0, float("inf")])[::2] == (5.0, 1)
    assert math.isnan(report.mean_ci95([5.0])[1])
    mean, half, n = report.mean_ci95([])
    assert n == 0 and math.isnan(mean) and math.isnan(half)


def test_aggregate_outcome_rates_wilson_intervals_and_groups():
    groups = report.aggregate(synthetic_rows(), metrics=("time_to_goal", "fce_rms"))
    assert [(g["scenario"], g["variant"]) for g in groups] == [("sc", "ctl_a"), ("sc", "ctl_b")]
    a = groups[0]
    assert (a["runs"], a["failed"], a["ok"]) == (4, 1, 3)
    assert a["outcomes"] == {"success": 1, "collision": 1, "deadlock": 1, "timeout": 0}
    # rates of all runs: the failed run is none of the outcomes
    assert (a["success_rate"], a["collision_rate"], a["deadlock_rate"]) == (0.25, 0.25, 0.25)
    assert a["reached_rate"] == 2 / 4  # the old "success": reached, contacts or not
    assert a["success_ci"] == pytest.approx(stats.wilson_interval(1, 4))
    assert a["dominant_failure"] == "collision"  # tie of collision, deadlock, failed: order
    ttg = a["stats"]["time_to_goal"]
    assert (ttg["mean"], ttg["n"]) == (11.0, 2)  # the null of a2 is skipped
    assert ttg["ci95"] == pytest.approx(T975[1] * math.sqrt(2.0) / math.sqrt(2.0))
    assert a["stats"]["fce_rms"]["n"] == 3 and a["stats"]["fce_rms"]["mean"] == 2.0
    assert a["stats"]["fce_rms"]["distinct"] == 3
    assert a["errors"] == ["controller 'ctl_a' returned NaN at t=1.0 s"]
    b = groups[1]
    assert b["timeout_rate"] == 1.0 and b["dominant_failure"] == "timeout"
    assert b["stats"]["time_to_goal"]["n"] == 0
    assert math.isnan(b["stats"]["fce_rms"]["ci95"])


def test_aggregate_by_controller_only_merges_scenarios():
    rows = synthetic_rows() + [row("c0", scenario="other", fce_rms=5.0, outcome="success",
                                   collisions=0)]
    groups = report.aggregate(rows, metrics=("fce_rms",), by=("controller",))
    assert [g["controller"] for g in groups] == ["ctl_a", "ctl_b"]
    assert groups[0]["runs"] == 5 and groups[0]["stats"]["fce_rms"]["mean"] == 2.75


# ---------------------------------------------------------------------------- tables
def test_markdown_cells():
    groups = report.aggregate(synthetic_rows(), metrics=("time_to_goal", "fce_rms"))
    md = tables.markdown_table(groups, ("time_to_goal", "fce_rms"))
    lines = md.splitlines()
    assert lines[0] == ("| scenario | variant | runs | failed | success | collision | deadlock "
                        "| timeout | Time to goal (s) | FCE RMS (m) |")
    assert lines[2] == ("| sc | ctl_a | 4 | 1 | 25% [5, 70] (1/4) | 25% [5, 70] (1/4) | "
                        "25% [5, 70] (1/4) | 0% [0, 49] (0/4) | 11.000 ± 12.706 (n=2) | "
                        "2.000 ± 2.484 |")
    assert lines[3] == ("| sc | ctl_b | 1 | 0 | 0% [0, 79] (0/1) | 0% [0, 79] (0/1) | "
                        "0% [0, 79] (0/1) | 100% [21, 100] (1/1) | — (n=0) | 0.500 |")
    assert "- sc / ctl_a: controller 'ctl_a' returned NaN at t=1.0 s" in lines
    hidden = tables.markdown_table(groups, ("fce_rms",), hide=("scenario",))
    assert hidden.splitlines()[0].startswith("| variant | runs |")


def test_one_distinct_value_and_uninformative_columns_are_said_so():
    rows = [row(f"{c}{s}", controller=c, seed=s, outcome="collision", risk=1.0, fce_rms=s + 0.5)
            for c in ("a", "b") for s in range(3)]
    groups = report.aggregate(rows, metrics=("risk", "fce_rms"))
    md = tables.markdown_table(groups, ("risk", "fce_rms"))
    assert "| 1.000 (1 distinct run) |" in md and "± 0.000" not in md
    assert tables.uninformative(groups, ("risk", "fce_rms")) == ["risk"]
    assert "risk ⚠" in md.splitlines()[0] and "separates nothing here: risk." in md


def test_csv_has_the_four_outcome_rates_with_intervals():
    groups = report.aggregate(synthetic_rows(), metrics=("time_to_goal", "fce_rms"))
    table = list(csv.DictReader(io.StringIO(tables.csv_table(groups, ("time_to_goal",
                                                                      "fce_rms")))))
    assert [r["variant"] for r in table] == ["ctl_a", "ctl_b"]
    a, b = table
    assert (int(a["runs"]), int(a["failed"]), int(a["ok"])) == (4, 1, 3)
    for o in ("success", "collision", "deadlock", "timeout"):
        lo, hi = stats.wilson_interval(groups[0]["outcomes"][o], 4)
        assert float(a[f"{o}_ci_low"]) == pytest.approx(lo)
        assert float(a[f"{o}_ci_high"]) == pytest.approx(hi)
    assert float(a["success_rate"]) == 0.25 and float(a["reached_rate"]) == 0.5
    assert float(a["time_to_goal_mean"]) == 11.0 and int(a["time_to_goal_n"]) == 2
    assert float(a["time_to_goal_ci95"]) == pytest.approx(T975[1])
    assert float(a["fce_rms_ci95"]) == pytest.approx(T975[2] * 1.0 / math.sqrt(3))
    assert b["time_to_goal_mean"] == "" and b["fce_rms_ci95"] == ""  # NaN -> empty cell
    assert float(b["fce_rms_mean"]) == 0.5 and float(b["timeout_rate"]) == 1.0


def test_paired_risk_leaves_out_and_counts_the_runs_with_a_contact():
    """A raw risk after a contact is inf, null in the row: no +1e9 median, a stated count."""
    from dfcoa_opt.bench.report import paired

    risk_a = [5.0, None, 6.0, None, 6.0]  # seeds 1 and 3 touched something (null in JSON)
    risk_b = [4.0, 3.0, 5.0, 2.0, 5.0]
    rows = [row(f"{v}{s}", controller=v, seed=s, outcome="collision" if r is None else
                "success", risk_raw_mean=r) for v, risks in (("a", risk_a), ("b", risk_b))
            for s, r in enumerate(risks)]
    comps = paired.compare(rows, "b", metrics=("risk_raw_mean",))
    risk = next(c for c in comps if c.metric == "risk_raw_mean")
    assert (risk.n, risk.excluded, risk.estimate) == (3, 2, 1.0)
    success = next(c for c in comps if c.metric == "success")
    assert (success.n, success.excluded) == (5, 0)
    md = tables.paired_table(comps, ("risk_raw_mean",), "b")
    cell = md.splitlines()[2].split(" | ")[-1]
    assert cell.startswith("+1.000 [1.000, 1.000] p=") and cell.endswith("(2 excluded) |")
    assert "left out of that metric: `(k excluded)`" in md
    out = list(csv.DictReader(io.StringIO(tables.paired_csv(comps))))
    assert [(r["metric"], r["n"], r["excluded"]) for r in out] == [
        ("success", "5", "0"), ("risk_raw_mean", "3", "2")]


# -------------------------------------------------------------------------- rankings
def world_rows(pattern, names=("a", "b", "c"), scenario="sc"):
    """One run per variant and world: ``pattern[w][i]`` says whether ``names[i]`` succeeded
    on world (seed) ``w``; a run that does not succeed times out."""
    return [row(f"{scenario}_{v}_{w}", controller=v, seed=w, scenario=scenario,
                outcome="success" if won else "timeout", collisions=0)
            for w, wins in enumerate(pattern) for v, won in zip(names, wins, strict=True)]


def ranking_of(rows, baseline="a"):
    """The ranking table of one table's rows, as the report builds it."""
    groups = report.aggregate(rows, ("time_to_goal",))
    return tables.ranking_table(groups, paired.compare(rows, baseline, ()), baseline,
                                paired.success_pairs(rows))


def ranking_cells(md):
    """``(rank, variant, worlds to separate from the next)`` of each row of a ranking."""
    body = [line.split(" | ") for line in md.splitlines()[2:] if line.startswith("| ")]
    return [(cells[0][2:], cells[1], cells[-1][:-2]) for cells in body]


def test_ranking_90_and_88_percent_share_a_rank_and_20_percent_is_alone():
    """Same 50 worlds: a 45/50, b 44/50, c 10/50."""
    pattern = ([(1, 1, 1)] * 10 + [(1, 1, 0)] * 33 + [(1, 0, 0)] * 2 + [(0, 1, 0)]
               + [(0, 0, 0)] * 4)
    md = ranking_of(world_rows(pattern))
    # a vs b: only a on 2 of the 50 worlds, only b on 1: p_disc = 3/50 = 0.06, d = 0.02;
    # n = (1.959964 sqrt(0.06) + 0.841621 sqrt(0.06 - 0.0004))^2 / 0.0004
    #   = (0.480091 + 0.205466)^2 / 0.0004 = 0.469989 / 0.0004 = 1174.97 -> 1175 worlds.
    # b vs c (34 worlds only b, none only c) already differ: "—"; c has no next row: "—".
    assert ranking_cells(md) == [("1-2", "a", "≈ 1175"), ("1-2", "b", "—"), ("3", "c", "—")]
    assert "all 3 tested pairs of variants of the table Holm-corrected together" in md
    assert "Inside a shared rank" not in md  # a and b do not differ: nothing to list


def test_ranking_of_strongly_different_variants_is_1_2_3():
    """high 50/50, mid 25/50, low 0/50 on the same worlds; every pair differs (p < 1e-7)."""
    pattern = [(0, 1, 1)] * 25 + [(0, 1, 0)] * 25
    md = ranking_of(world_rows(pattern, names=("low", "high", "mid")), baseline="mid")
    assert ranking_cells(md) == [("1", "high", "—"), ("2", "mid", "—"), ("3", "low", "—")]


def test_ranking_groups_use_holm_over_every_pair():
    """a vs b: p = 0.031 alone, not significant once Holm-corrected with the other two pairs."""
    pattern = [(1, 1, 1)] * 20 + [(1, 1, 0)] * 3 + [(1, 0, 0)] * 6 + [(0, 0, 0)] * 11
    rows = world_rows(pattern)
    pairs = {(p.first, p.second): p for p in paired.success_pairs(rows)}
    # exact two-sided McNemar p = 2 * 0.5^k with all k discordant worlds on one side:
    # a-b: k = 6 -> 0.03125; a-c: k = 9 -> 0.00390625; b-c: k = 3 -> 0.25.
    # Holm, m = 3: 3 * 0.00390625 = 0.01171875; 2 * 0.03125 = 0.0625; max(1 * 0.25, 0.0625).
    expected = {("a", "b"): (6, 0, 0.03125, 0.0625), ("a", "c"): (9, 0, 0.00390625, 0.01171875),
                ("b", "c"): (3, 0, 0.25, 0.25)}
    assert sorted(pairs) == sorted(expected)
    for k, p in pairs.items():
        assert (p.only_first, p.only_second, p.p_value, p.p_holm) == pytest.approx(expected[k])
    assert all(p.worlds == 40 for p in pairs.values())
    # unadjusted, a would stand alone (it beats b and c at p < 0.05); adjusted, a ~ b and
    # b ~ c, so no cut is supported anywhere
    md = ranking_of(rows)
    assert [r for r, _, _ in ranking_cells(md)] == ["1-3", "1-3", "1-3"]
    assert "`a` and `c` (p = 0.0117)" in md  # the chain: they differ inside the shared rank


def test_rank_groups_never_cut_against_the_tests():
    """A cut needs every pair across it separated, in the order's direction."""
    table = ("sc", "", None)
    strong = paired.SuccessPair(table, "a", "b", 50, 30, 0, 1e-9, 1e-9)
    assert paired.rank_groups(["a", "b"], [strong]) == [(1, 1), (2, 2)]
    assert paired.rank_groups(["b", "a"], [strong]) == [(1, 2), (1, 2)]  # b is the worse one
    assert paired.rank_groups(["a", "b"], []) == [(1, 2), (1, 2)]  # untested: not separated
    other = paired.SuccessPair(("sc2", "", None), "a", "b", 50, 30, 0, 1e-9, 1e-9)
    with pytest.raises(ValueError, match="one table"):
        paired.rank_groups(["a", "b"], [strong, other])


def test_success_pairs_pair_by_world_within_each_table():
    """Only the seeds both ran are paired; each scenario is its own Holm family."""
    rows = world_rows([(1, 0)] * 8, names=("a", "b"))
    rows += world_rows([(1, 1)] * 3, names=("a", "b"), scenario="sc2")
    rows = [r for r in rows if not (r["variant"] == "b" and r["seed"] == 0
                                    and r["scenario"] == "sc")]
    by_table = {p.table[0]: p for p in paired.success_pairs(rows)}
    assert (by_table["sc"].worlds, by_table["sc"].only_first) == (7, 7)
    assert by_table["sc"].p_holm == by_table["sc"].p_value == 2 * 0.5 ** 7
    assert (by_table["sc2"].worlds, by_table["sc2"].p_value) == (3, 1.0)


def test_pooled_worlds_pair_across_families():
    """The held-out ranking pools families: seed 0 of two families are two worlds."""
    from dfcoa_opt.bench.report import heldout as ho

    rows = world_rows([(1, 0)] * 4, names=("a", "b"), scenario="fam1")
    rows += world_rows([(1, 0)] * 4, names=("a", "b"), scenario="fam2")
    (pair,) = paired.success_pairs(ho.pooled(rows))
    assert (pair.table[0], pair.worlds, pair.only_first) == (ho.POOLED, 8, 8)


def test_report_ranks_each_scenario(tmp_path):
    pattern = ([(1, 1, 1)] * 10 + [(1, 1, 0)] * 33 + [(1, 0, 0)] * 2 + [(0, 1, 0)]
               + [(0, 0, 0)] * 4)
    folder = write_results(tmp_path / "res", world_rows(pattern))
    report.make_report(folder, tmp_path / "rep", metrics=("time_to_goal",), baseline="b")
    md = (tmp_path / "rep" / "report.md").read_text()
    ranking = md.split("### Ranking")[1].split("### Paired")[0]
    assert ranking_cells(ranking.strip()) == [("1-2", "a", "≈ 1175"), ("1-2", "b", "—"),
                                              ("3", "c", "—")]


# ----------------------------------------------------------------------- environment
def test_environment_header(tmp_path, monkeypatch):
    rows = synthetic_rows()
    rows[0]["provenance"]["simd"] = "X86_V3"
    rows[1]["provenance"]["simd"] = "AVX512_ICL"
    rows[0]["provenance"]["simd_cap"] = rows[1]["provenance"]["simd_cap"] = "X86_V3"
    folder = write_results(tmp_path / "res", rows)
    monkeypatch.setattr(provenance, "PACKAGES", (*provenance.PACKAGES, "no-such-package-xyz"))
    head = report.environment_header(folder)
    assert "Date (newest finished run): 2024-05-01T11:00:00-02:00" in head
    assert SHA in head and f"`{SHA[:12]}`" in head and "**demo**" in head
    assert f"numpy {np.__version__}" in head and "no-such-package-xyz not installed" in head
    assert f"{os.cpu_count()} cores, numpy SIMD {dispatch.numpy_simd()}" in head
    assert "hosts: h1 (numpy SIMD AVX512_ICL, X86_V3; cap X86_V3)" in head


def test_numpy_simd_follows_numpy_dispatch():
    """The level is numpy's own choice: with every dispatch target disabled, the baseline."""
    from numpy._core import _multiarray_umath as umath

    here = dispatch.numpy_simd()
    assert here in [*umath.__cpu_dispatch__, *umath.__cpu_baseline__]
    assert umath.__cpu_features__[here]
    env = {**os.environ, "NPY_DISABLE_CPU_FEATURES": " ".join(umath.__cpu_dispatch__)}
    out = subprocess.run([sys.executable, "-c", "from dfcoa_opt.core.runtime import dispatch; "
                          "print(dispatch.numpy_simd())"],
                         env=env, capture_output=True, text=True, check=True).stdout.strip()
    assert out == umath.__cpu_baseline__[-1]


# --------------------------------------------------------------------------- loading
def test_load_rows_sorted_and_errors(tmp_path):
    folder = write_results(tmp_path / "res", synthetic_rows()[::-1])
    assert [r["key"] for r in report.load_rows(folder)] == ["a0", "a1", "a2", "a3", "b0"]
    (folder / "rows" / "zz.json").write_text('{"key": "zz", "scenario": ')
    with pytest.raises(DfcoaError, match=r"zz\.json: not valid JSON") as err:
        report.load_rows(folder)
    assert "\n" not in str(err.value) and "Traceback" not in str(err.value)
    (folder / "rows" / "zz.json").write_text('[1, 2]')
    with pytest.raises(DfcoaError, match=r"zz\.json: expected a JSON object"):
        report.load_rows(folder)
    (folder / "rows" / "zz.json").write_text('{"key": "zz"}')
    with pytest.raises(DfcoaError, match=r"zz\.json: missing field\(s\) scenario"):
        report.load_rows(folder)
    with pytest.raises(DfcoaError, match="folder not found"):
        report.load_rows(tmp_path / "missing")


def test_load_rows_keeps_only_the_manifest_keys(tmp_path):
    man = {"name": "demo", "sweep_file": "s.toml", "sweep_sha256": SHA, "created": "x",
           "keys": ["a0", "a1", "zz_not_run_yet"]}
    folder = write_results(tmp_path / "res", synthetic_rows(), manifest=man)
    (folder / "rows" / "stale.json").write_text("{broken")  # not in the manifest: not read
    assert [r["key"] for r in report.load_rows(folder)] == ["a0", "a1"]
    assert "Runs: 2 of 3 in the manifest (0 failed)" in report.environment_header(folder)
    with pytest.raises(DfcoaError, match="stale.json"):
        report.load_rows(folder, all_rows=True)


# ------------------------------------------------------------------------ end to end
@pytest.fixture(scope="module")
def results(tmp_path_factory) -> Path:
    """A real results folder: example_empty x goto_slot x seeds 0, 1 (2 s runs) + 1 failure."""
    folder = tmp_path_factory.mktemp("results")
    overrides = {"t_max": 2.0}
    rows = []
    for seed in (0, 1):
        data = read_toml(SCENARIO)
        data.setdefault("name", SCENARIO.stem)
        data["seed"] = seed
        data.update(overrides)
        scenario = scenario_from_dict(data, str(SCENARIO), SCENARIO.parent)
        log = run_scenario(scenario, "goto_slot", seed)
        key = f"example_empty__goto_slot__t2__s{seed}"
        log.save(folder / "logs" / f"{key}.npz")
        mets = {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                for k, v in run_metrics.summary(log, scenario).items()}
        rows.append({
            "key": key, "scenario": "example_empty", "scenario_file": str(SCENARIO),
            "controller": "goto_slot", "variant": "goto_slot", "seed": seed,
            "overrides": overrides, "status": "ok", "error": None, "metrics": mets,
            "digest": log.digest(), "log": f"logs/{key}.npz",
            "provenance": {"wall_time": 0.3, "finished": f"2024-06-0{seed + 1}T08:00:00Z",
                           "host": "testhost", "pid": 42}})
    rows.append({**rows[0], "key": "example_empty__broken__t2__s0", "controller": "broken",
                 "variant": "broken",
                 "status": "failed", "error": "unknown controller 'broken'", "metrics": None,
                 "digest": None, "log": None})
    folder = write_results(folder, [])
    for r in rows:
        (folder / "rows" / f"{r['key']}.json").write_text(json.dumps(r, allow_nan=False))
    return folder


def test_make_report_end_to_end(results, tmp_path):
    out = tmp_path / "rep"
    paths = report.make_report(results, out, metrics=("fce_rms", "time_to_goal"))
    names = [p.name for p in paths]
    assert names == ["report.md", "report.csv", "box_fce_rms.png", "box_time_to_goal.png",
                     "traj_example_empty_s0.png", "fail_example_empty_goto_slot_s0.png"]
    for p in paths[2:]:
        assert p.stat().st_size > 1000 and p.read_bytes()[:8] == PNG_MAGIC
    md = (out / "report.md").read_text()
    assert "## Scenario `example_empty`" in md and "sha256 `0123456789ab`" in md
    assert "Date (newest finished run): 2024-06-02T08:00:00Z" in md
    # 2 s runs never arrive: timeouts, explained with a snapshot at their end
    assert "| goto_slot | 2 | 0 | 0% [0, 66] (0/2) | 0% [0, 66] (0/2) | 0% [0, 66] (0/2) | " \
           "100% [34, 100] (2/2) |" in md
    assert "| broken | 1 | 1 | 0% [0, 79] (0/1) |" in md
    assert "- broken: unknown controller 'broken'" in md
    assert "most runs end in **timeout** (2/2); first: seed 0, [end](fail_example_empty" in md
    assert "most runs end in **failed** (1/1)" in md
    assert "- every variant: `t_max = 2.0`" in md and "![trajectories example_empty]" in md
    assert not re.search(r"[0-9a-f]{10}", md.split("## Scenario")[1])  # no hash anywhere
    rows = report.load_rows(results)
    table = {r["variant"]: r for r in csv.DictReader(io.StringIO((out / "report.csv")
                                                                .read_text()))}
    fce = [r["metrics"]["fce_rms"] for r in rows if r["status"] == "ok"]
    assert float(table["goto_slot"]["fce_rms_mean"]) == pytest.approx(np.mean(fce))
    assert int(table["goto_slot"]["fce_rms_n"]) == 2 and table["goto_slot"]["failed"] == "0"
    first = (out / "report.md").read_bytes()
    report.make_report(results, out, metrics=("fce_rms", "time_to_goal"))
    assert (out / "report.md").read_bytes() == first  # cached results -> identical file


def test_a_snapshot_limit_draws_fewer_failures_and_says_so(results, tmp_path):
    rows = [r for r in report.load_rows(results) if r["variant"] == "goto_slot"]
    rows += [{**r, "variant": "goto_slot_b"} for r in rows]
    groups = [{"scenario": "example_empty", "variant": v, "success_rate": 0.0,
               "ladder_value": None} for v in ("goto_slot", "goto_slot_b")]
    lines, shots = failures.explain(groups, rows, results, tmp_path / "all")
    assert len(shots) == 2 and not any("left out" in line for line in lines)
    with failures.snapshot_limit(1):
        lines, shots = failures.explain(groups, rows, results, tmp_path / "one")
    assert [p.name for p in shots] == ["fail_example_empty_goto_slot_s0.png"]
    assert "goto_slot_b` on `example_empty`" in lines[1] and "snapshot left out" in lines[1]
    assert len(failures.explain(groups, rows, results, tmp_path / "after")[1]) == 2  # reset
    with pytest.raises(ValueError, match="snapshot limit 0: must be at least 1"):
        with failures.snapshot_limit(0):
            pass


def test_default_out_dir_and_explicit_overlay_seed(results):
    paths = report.make_report(results, metrics=("fce_rms",), overlay_seed=1)
    assert paths[0] == results / "report" / "report.md"
    assert "traj_example_empty_s1.png" in [p.name for p in paths]


def test_panels_reject_mixed_seeds_and_overlays_note_a_missing_scenario(results, tmp_path):
    rows = [r for r in report.load_rows(results) if r["log"]]
    with pytest.raises(ValueError, match="mix"):
        trajectories.panels_figure(rows, results)
    moved = [{**r, "scenario_file": str(tmp_path / "gone.toml")} for r in rows]
    written, notes = trajectories.overlay_figures(moved, results, tmp_path)
    assert written == {} and len(notes) == 1 and "gone.toml: file not found" in notes[0]


def test_overlay_notes_a_scenario_file_changed_since_the_run(results, tmp_path):
    rows = [{**r, "scenario_sha256": "0" * 16} for r in report.load_rows(results)
            if r["log"] and r["seed"] == 0]
    written, notes = trajectories.overlay_figures(rows, results, tmp_path)
    assert len(written["example_empty"]) == 1
    assert len(notes) == 1 and "changed since the runs" in notes[0]
    real = hashlib.sha256(SCENARIO.read_bytes()).hexdigest()[:16]
    assert trajectories.overlay_figures([{**rows[0], "scenario_sha256": real}], results,
                                        tmp_path)[1] == []


def test_boxplot_without_finite_values_still_writes(tmp_path):
    path = plots.metric_boxplots(synthetic_rows(), "time_to_goal", tmp_path / "b.png",
                                 label="Time to goal (s)")
    assert path.read_bytes()[:8] == PNG_MAGIC
    path = plots.metric_boxplots([], "fce_rms", tmp_path / "empty.png")
    assert path.read_bytes()[:8] == PNG_MAGIC


def test_success_matrix_counts_each_variant_on_each_scenario():
    def row(v, s, seed, outcome, status="ok"):
        return {"key": f"{s}__{v}__s{seed}", "variant": v, "controller": v, "scenario": s,
                "seed": seed, "status": status, "metrics": {"outcome": outcome}}

    rows = [row("a", "x", 0, "success"), row("a", "x", 1, "collision"),
            row("a", "y", 0, "deadlock"), row("b", "x", 0, "success", status="failed"),
            row("b", "y", 0, "success"), row("b", "y", 1, "success")]
    assert tables.success_matrix(rows).splitlines() == [
        "| variant | x | y |", "|---|---|---|", "| a | **1/2** | 0/1 |", "| b | 0/1 | **2/2** |"]
