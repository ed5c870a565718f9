import shutil
from pathlib import Path

from dfcoa_opt.figures import make_figures

ROOT = Path(__file__).resolve().parents[1]


def test_make_figures_writes_a_table_and_one_png_per_run(tmp_path):
    scen = tmp_path / "scen"
    scen.mkdir()
    shutil.copy(ROOT / "scenarios" / "example_empty.toml", scen)
    table = make_figures(scen, tmp_path / "out")
    text = table.read_text()
    assert "| example_empty | goto_slot | yes |" in text
    pngs = list((tmp_path / "out" / "examples").glob("*.png"))
    assert [p.name for p in pngs] == ["example_empty-goto_slot.png"]
