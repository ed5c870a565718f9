"""`dfcoa figures` on a reduced configuration (tiny scenarios, 2 seeds)."""

import json
import shutil
from pathlib import Path

from dfcoa_opt.bench.executors import ExecutorConfig
from dfcoa_opt.cli import main
from dfcoa_opt.figures import make_figures, recipes

ROOT = Path(__file__).resolve().parents[1]
TINY = Path(__file__).parent / "data" / "bench" / "tiny.toml"


def _root(tmp_path: Path) -> Path:
    """A scenario root with the built-in recipes' sweep files pointing at tiny scenarios."""
    root = tmp_path / "scen"
    (root / "sweeps").mkdir(parents=True)
    (root / "bench").mkdir()
    shutil.copy(ROOT / "scenarios" / "example_empty.toml", root)
    shutil.copy(TINY, root / "bench" / "tiny.toml")
    for r in recipes():
        shutil.copy(ROOT / "scenarios" / r.sweep, root / r.sweep)
    return root


def test_figures_smoke_renders_every_recipe_and_reuses_the_cache(tmp_path):
    root, out, cache = _root(tmp_path), tmp_path / "out", tmp_path / "cache"
    index = make_figures(root, out, cache, ExecutorConfig("serial"), seeds=2, progress=False)
    text = index.read_text()
    for r in recipes():
        meta = json.loads((out / r.name / "artefacts.json").read_text())
        assert meta["artefacts"], r.name
        for a in meta["artefacts"]:
            assert (out / r.name / a["path"]).stat().st_size > 0
            assert f"`{r.name}/{a['path']}`" in text
    assert "| example_empty | goto_slot | yes |" in (out / "examples" / "summary.md").read_text()
    rows = {p: p.stat().st_mtime_ns for p in cache.rglob("rows/*.json")}
    assert len(rows) == 2 + 2  # examples: 1 scenario x 2 seeds; comparison: tiny x 2 seeds
    report = (out / "comparison" / "report.md").read_bytes()
    make_figures(root, out, cache, ExecutorConfig("serial"), seeds=2, progress=False)
    assert {p: p.stat().st_mtime_ns for p in cache.rglob("rows/*.json")} == rows  # cached
    assert (out / "comparison" / "report.md").read_bytes() == report  # same bytes again


def test_figures_cli_unknown_recipe_exits_2(tmp_path, capsys):
    code = main(["figures", "--scenarios", str(_root(tmp_path)), "--out", str(tmp_path / "o"),
                 "--only", "comparisn"])
    assert code == 2
    assert "did you mean 'comparison'" in capsys.readouterr().err
