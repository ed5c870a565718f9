"""Published runs (runs.csv) and ``dfcoa compare``: a plugin controller among published methods.

The published sweeps here are small copies of the recipes' (one family or scenario, two
worlds, short runs), published into a temporary figures folder by the same code that
``make figures`` runs; the compared controller is the README's, from a plugin file.
"""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import pytest

from dfcoa_opt.bench.compare import compare
from dfcoa_opt.bench.executors import ExecutorConfig
from dfcoa_opt.bench.harness import run_sweep
from dfcoa_opt.bench.recipes.comparison import METRICS as COMPARISON_METRICS
from dfcoa_opt.bench.recipes.heldout import METRICS as HELDOUT_METRICS
from dfcoa_opt.bench.report.document import make_report
from dfcoa_opt.bench.results.published import RUNS_FILE, read_runs, write_runs
from dfcoa_opt.cli import main
from dfcoa_opt.core.errors import DfcoaError

ROOT = Path(__file__).resolve().parents[1]
SERIAL = ExecutorConfig("serial")
PLUGIN = '''from dataclasses import dataclass

import numpy as np

import dfcoa_opt as d
from dfcoa_opt.core.params import param


@d.register("capped_goto")
class CappedGoto:
    command = "velocity"

    @dataclass(frozen=True)
    class Params:
        v_cap: float = param(0.4, doc="Largest speed.", unit="m/s", gt=0.0, tune=(0.1, 1.0))

    def __init__(self, params):
        self.p = params

    def reset(self, scenario, rng):
        pass

    def act(self, obs):
        u = obs.slot - obs.pose[:, :2]
        n = np.maximum(np.linalg.norm(u, axis=1, keepdims=True) / self.p.v_cap, 1.0)
        return u / n
'''
HELDOUT = '''name = "heldout"
scenarios = ["../heldout/rooms.toml"]
split = "test"
first_seed = 20000
seeds = 2
controllers = ["goto_slot"]
variant_files = ["tuned/*.toml"]
baseline = "goto_slot@tuned"
[grid]
t_max = [6.0]
stop_on_collision = [true]
stop_on_deadlock = [true]
'''
TUNE = '''name = "tune"
scenarios = ["../heldout/rooms.toml"]
split = "train"
first_seed = 0
seeds = 2
controllers = ["goto_slot"]
[grid]
t_max = [6.0]
stop_on_collision = [true]
stop_on_deadlock = [true]
[tune]
trials = 2
sampler_seed = 0
startup_trials = 1
out = "tuned"
'''
COMPARISON = f'''name = "comparison"
scenarios = ["{(ROOT / "tests" / "data" / "bench" / "tiny.toml").as_posix()}"]
controllers = ["goto_slot", "consensus"]
seeds = 2
baseline = "goto_slot"
'''


def _published(tmp: Path, recipe: str, sweep_text: str, metrics) -> tuple[Path, Path]:
    """A scenario root with the recipe's small sweep, and a figures folder publishing it."""
    scen = tmp / "scenarios"
    (scen / "sweeps" / "tuned").mkdir(parents=True)
    (scen / "heldout").mkdir()
    shutil.copy(ROOT / "scenarios" / "heldout" / "rooms.toml", scen / "heldout" / "rooms.toml")
    shutil.copy(ROOT / "scenarios" / "sweeps" / "tuned" / "goto_slot.toml",
                scen / "sweeps" / "tuned" / "goto_slot.toml")
    (scen / "sweeps" / f"{recipe}.toml").write_text(sweep_text)
    (scen / "sweeps" / "tune.toml").write_text(TUNE)
    res = run_sweep(scen / "sweeps" / f"{recipe}.toml", tmp / "published_results", SERIAL,
                    progress=False)
    assert res.failed == 0
    figures = tmp / "paper_figures"
    write_runs(res.store.rows(), figures / recipe / RUNS_FILE, metrics, recipe)
    return scen, figures


@pytest.fixture(scope="module")
def heldout(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("heldout")
    (tmp / "capped.py").write_text(PLUGIN)
    scen, figures = _published(tmp, "heldout", HELDOUT, HELDOUT_METRICS)
    return tmp, scen, figures


def test_published_runs_read_back_to_the_same_rows_and_the_same_report(tmp_path):
    """Every kept field and metric reads back bit for bit (NaN too); the report is the same."""
    (tmp_path / "scenarios" / "sweeps").mkdir(parents=True)
    (tmp_path / "scenarios" / "heldout").mkdir()
    sweep = tmp_path / "s.toml"
    sweep.write_text(COMPARISON)
    res = run_sweep(sweep, tmp_path / "res", SERIAL, progress=False)
    rows = res.store.rows()
    back, meta = read_runs(write_runs(rows, tmp_path / RUNS_FILE, COMPARISON_METRICS, "cmp"))
    assert meta["recipe"] == "cmp" and meta["commit"]
    assert len(back) == len(rows) == 4
    for a, b in zip(rows, back, strict=True):  # in the store's order
        for f in ("key", "variant", "controller", "scenario", "seed", "status", "digest",
                  "code", "log", "overrides"):
            assert a.get(f) == b.get(f), f
        assert b["metrics"] == {k: a["metrics"].get(k) for k in b["metrics"]}
    make_report(res.store.root, tmp_path / "a")
    make_report(res.store.root, tmp_path / "b", rows=back)
    assert ((tmp_path / "a" / "report.md").read_text()
            == (tmp_path / "b" / "report.md").read_text())


def test_numbers_keep_their_bits_nan_and_inf_included(tmp_path):
    row = {"key": "k", "variant": "v", "controller": "c", "scenario": "s", "seed": 3,
           "status": "ok", "digest": "d", "overrides": {"a.b": [1, 2.5]},
           "metrics": {"fce_rms": 0.1 + 0.2, "time_to_goal": math.nan, "risk_raw_max": math.inf,
                       "reached": True, "outcome": "success"}}
    (back,), _ = read_runs(write_runs([row], tmp_path / RUNS_FILE, ["fce_rms", "risk_raw_max"],
                                      "r"))
    m = back["metrics"]
    assert m["fce_rms"] == 0.1 + 0.2 and m["risk_raw_max"] == math.inf
    assert math.isnan(m["time_to_goal"]) and m["reached"] is True and m["outcome"] == "success"
    assert back["overrides"] == {"a.b": [1, 2.5]} and back["error"] is None and back["seed"] == 3


def test_a_malformed_published_file_is_one_line_naming_the_line(tmp_path):
    bad = tmp_path / RUNS_FILE
    bad.write_text("key,variant\n")
    with pytest.raises(DfcoaError, match=r"runs.csv: line 1: not a published runs file"):
        read_runs(bad)


def test_compare_heldout_tunes_and_ranks_a_plugin_among_the_published(heldout):
    tmp, scen, figures = heldout
    with pytest.MonkeyPatch.context() as mp:  # a relative results folder, as from the CLI
        mp.chdir(tmp)
        result = compare("heldout", "capped_goto", "out", scenarios=scen, figures=figures,
                         plugin_files=[str(tmp / "capped.py")], tune=True, config=SERIAL,
                         progress=False)
    assert result.variant == "capped_goto@tuned" and result.tuned_file is not None
    assert result.tuned_file.parent == tmp / "out" / "tuned"  # not into the repository
    assert not (scen / "sweeps" / "tuned" / "capped_goto.toml").exists()
    assert result.ran == 2 and result.verified == 2 and not result.mismatches
    assert result.rank.endswith(" of 2") and result.success.endswith("/2)")
    text = result.report.read_text()
    assert "| capped_goto@tuned |" in text and "| goto_slot@tuned |" in text
    assert "every digest the same" in text and "ranks" in result.summary()


def test_compare_names_a_published_row_this_code_does_not_reproduce(heldout):
    tmp, scen, figures = heldout
    altered = tmp / "altered"
    shutil.copytree(figures, altered)
    path = altered / "heldout" / RUNS_FILE
    lines = path.read_text().splitlines(keepends=True)
    digest = lines[2].split(",")[10]
    path.write_text("".join([*lines[:2], lines[2].replace(digest, "0" * 64), *lines[3:]]))
    result = compare("heldout", "capped_goto", tmp / "out_altered", scenarios=scen,
                     figures=altered, plugin_files=[str(tmp / "capped.py")], config=SERIAL,
                     progress=False, verify="all")
    assert result.verified == 4 and len(result.mismatches) == 1
    assert result.mismatches[0].published == "0" * 64
    summary = result.summary()
    assert "warning: 1 of 4 published runs simulated again give other digests" in summary
    assert f"came from commit {read_runs(path)[1]['commit']}" in summary
    assert result.report.read_text().startswith("> **Warning:** ")


def test_compare_comparison_from_the_command_line(tmp_path, capsys, monkeypatch):
    (tmp_path / "capped.py").write_text(PLUGIN.replace("capped_goto", "capped_cli"))
    scen, figures = _published(tmp_path, "comparison", COMPARISON, COMPARISON_METRICS)
    monkeypatch.chdir(tmp_path)
    assert main(["compare", "comparison", "--plugin", "capped.py", "--controller",
                 "capped_cli", "--scenarios", str(scen), "--published", str(figures),
                 "--out", "cmp", "--executor", "serial", "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("capped_cli ranks ") and " of 3 " in out
    assert "verified: 2 published runs simulated again give their published digests" in out
    report = (tmp_path / "cmp" / "report" / "report.md").read_text()
    assert "| capped_cli |" in report and "| consensus |" in report


@pytest.mark.parametrize("argv,msg", [
    (["compare", "ladders", "--controller", "goto_slot"], "recipe 'ladders' publishes no runs"),
    (["compare", "heldout", "--controller", "nope"], "unknown controller 'nope'"),
])
def test_compare_errors_are_one_line(argv, msg, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and msg in err[0]


def test_the_heldout_report_pictures_each_failure_of_the_first_ranked_variant(heldout, tmp_path):
    """Every world the best tuned variant failed is listed by family, with its snapshot."""
    from dfcoa_opt.bench.recipes.heldout import heldout_report
    from dfcoa_opt.bench.results.store import ResultsStore
    from dfcoa_opt.bench.runner import is_success

    tmp, _, _ = heldout
    store = ResultsStore(tmp / "published_results")
    rows = [r for r in store.rows() if r["variant"].endswith("@tuned")]
    failed = sorted(int(r["seed"]) for r in rows if not is_success(r))
    assert failed  # 6 s runs on rooms: none reaches the goal
    heldout_report(rows, tmp_path, "goto_slot@tuned", {}, "header", store.root)
    text = (tmp_path / "heldout.md").read_text()
    section = text.split("## Where the first-ranked variant fails")[1]
    assert f"### rooms: {len(failed)} of {len(rows)} failed" in section
    for seed in failed:
        assert f"- seed {seed}: " in section
        assert (tmp_path / f"fail_rooms_s{seed}.png").stat().st_size > 10_000
