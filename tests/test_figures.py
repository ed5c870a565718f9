"""`dfcoa figures` on a reduced configuration: the real recipes, 1 seed, 3 s missions."""

import json
from pathlib import Path

import pytest

from dfcoa_opt.bench import recipes as registry
from dfcoa_opt.bench.executors import ExecutorConfig
from dfcoa_opt.bench.figures import COST_FILE, make_figures
from dfcoa_opt.cli import main
from dfcoa_opt.sim.log import is_compact, is_pruned

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"
QUICK = {"t_max": 3.0}


def test_figures_smoke_renders_every_recipe_and_reuses_the_cache(tmp_path):
    out, cache = tmp_path / "out", tmp_path / "cache"
    cfg = ExecutorConfig("process", 2)
    # one failure snapshot a scenario: under 3 s missions every variant fails, and drawing
    # the comparison's 105 failures took most of this test's time
    index = make_figures(SCENARIOS, out, cache, cfg, seeds=1, progress=False, overrides=QUICK,
                         snapshots=1)
    text = index.read_text()
    report = (out / "comparison" / "report.md").read_text()
    sections = report.split("### Why it fails")[1:]
    assert sections and all(s.count("snapshot left out") >= 1 for s in sections)
    drawn = sorted(p.name for p in (out / "comparison").glob("fail_*.png"))
    assert len(drawn) == len(sections)
    for r in registry.registered():
        meta = json.loads((out / r.name / "artefacts.json").read_text())
        assert meta["artefacts"], r.name
        for a in meta["artefacts"]:
            assert (out / r.name / a["path"]).stat().st_size > 0
            assert f"`{r.name}/{a['path']}`" in text
    rows = {p: p.stat().st_mtime_ns for p in cache.rglob("rows/*.json")}
    failed = [json.loads(p.read_text())["error"] for p in rows
              if json.loads(p.read_text())["status"] != "ok"]
    assert not failed
    # every log a figure read keeps the fields read (pruned); the others are compacted (the
    # ladders draw none)
    compacted = pruned = 0
    for listing in cache.glob("*/logs_read.json"):
        read = json.loads(listing.read_text())
        for log in (listing.parent / "logs").glob("*.npz"):
            assert is_compact(log) == (log.stem not in read), log
            compacted += log.stem not in read
            pruned += is_pruned(log)
    assert compacted >= len(list((cache / "ladders" / "logs").glob("*.npz"))) > 0
    assert pruned > 0
    # every recipe's cost against its budget: its runs' simulation time (runs copied from
    # another recipe excluded) plus its rendering's
    for r in registry.registered():
        cost = json.loads((cache / r.name / COST_FILE).read_text())
        assert cost["budget_cpu_s"] == r.budget and cost["render_s"] > 0
        assert cost["cost_cpu_s"] == pytest.approx(cost["simulation_cpu_s"] + cost["render_s"])
        if r.sweep is None:
            assert cost["simulation_cpu_s"] == 0.0
            continue
        provs = [json.loads(p.read_text())["provenance"] for p in (cache / r.name).glob(
            "rows/*.json")]
        own = sum(pv["wall_time"] for pv in provs if not pv.get("reused_from"))
        assert cost["simulation_cpu_s"] == pytest.approx(own)
        if r.name == "beyond":  # it takes the comparison's runs, which cost it nothing
            assert any(pv.get("reused_from") for pv in provs)
            assert own < sum(pv["wall_time"] for pv in provs)
    report = (out / "paper004_baseline" / "baseline.md").read_bytes()
    stale = out / "paper004_baseline" / "fig5_basic_static_old.png"  # an older file name
    stale.write_bytes(b"old")
    # again, one recipe alone: every recipe takes its cached runs by the same code, so the
    # cheapest shows it (the comparison's 128 artefacts took 60 s to render a second time;
    # test_report checks that its report is the same bytes from cached results)
    make_figures(SCENARIOS, out, cache, cfg, only=["paper004_baseline"], seeds=1,
                 progress=False, overrides=QUICK)
    assert not stale.exists()  # files the recipe no longer writes are removed
    assert {p: p.stat().st_mtime_ns for p in cache.rglob("rows/*.json")} == rows  # cached
    assert (out / "paper004_baseline" / "baseline.md").read_bytes() == report  # same bytes


def test_figures_cli_unknown_recipe_exits_2(tmp_path, capsys):
    code = main(["figures", "--out", str(tmp_path / "o"), "--only", "comparisn"])
    assert code == 2
    assert "did you mean 'comparison'" in capsys.readouterr().err


def test_cli_set_must_be_toml(tmp_path, capsys):
    code = main(["figures", "--out", str(tmp_path / "o"), "--set", "t_max=1.2.3"])
    assert code == 2
    assert "--set: t_max: '1.2.3' is not a TOML value or a bare word" in capsys.readouterr().err


def test_renders_overlap_in_a_process_and_local_renderers_run_inline(tmp_path, monkeypatch):
    """Picklable renderers go to the render process (its errors come back); others inline."""
    import operator

    import pytest

    def local(scenarios, dest):  # a closure: cannot be pickled, so it renders inline
        (dest / "hello.md").write_text(str(scenarios))
        return [registry.Artefact("hello.md", "-", "test")]

    registry.registered()  # register the real recipes first, so that they stay out of the table
    monkeypatch.setattr(registry.RECIPES, "_table",
                        {"local": registry.Recipe("local", None, "T", local)})
    cfg = ExecutorConfig("process", 2)
    index = make_figures(SCENARIOS, tmp_path / "out", tmp_path / "cache", cfg, progress=False)
    assert (tmp_path / "out" / "local" / "hello.md").read_text() == str(SCENARIOS)
    assert "`local/hello.md`" in index.read_text()
    # operator.sub(Path, Path) raises in the render process; the error reaches the caller
    monkeypatch.setattr(registry.RECIPES, "_table",
                        {"bad": registry.Recipe("bad", None, "T", operator.sub)})
    with pytest.raises(TypeError, match="unsupported operand"):
        make_figures(SCENARIOS, tmp_path / "out2", tmp_path / "cache", cfg, progress=False)


def test_every_recipe_has_a_budget_and_the_docs_show_the_codes():
    """The budgets live in the recipes' modules; docs/performance.md holds their table."""
    recipes = registry.registered()
    assert recipes and all(r.budget is not None and r.budget > 0 for r in recipes)
    doc = (Path(__file__).resolve().parents[1] / "docs" / "performance.md").read_text()
    start = doc.index("<!-- budget-table")
    table = doc[doc.index("\n", start) + 1:doc.index("<!-- /budget-table -->")]
    assert table == registry.budget_table()


@pytest.mark.parametrize("budget", [0, -5.0, "60"])
def test_a_recipe_budget_must_be_positive_cpu_seconds(budget):
    with pytest.raises(ValueError, match="budget must be a positive number of CPU-s"):
        registry.recipe("x", title="x", budget=budget)


def test_the_cost_line_flags_a_recipe_over_its_budget():
    from dfcoa_opt.bench.figures import cost_text

    r = registry.Recipe("x", None, "x", print, budget=100.0)
    assert cost_text(r, 99.6) == "cost 100 CPU-s of a 100 budget"
    assert cost_text(r, 120.0) == "cost 120 CPU-s of a 100 budget OVER BUDGET"
    assert "no budget applies" in cost_text(r, 120.0, judged=False)  # seeds or overrides
