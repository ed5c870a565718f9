"""The benchmark scripts' set-ups still load (no timing here: `make bench` does that)."""

import numpy as np

from benchmarks.bench_astar import s1_grid
from benchmarks.scaling.report import loglog_slope
from benchmarks.scaling.scenario import model_of, open_scenario
from dfcoa_opt.control.registry import available


def test_astar_benchmark_map_is_s1_at_one_cell_per_metre():
    grid = s1_grid()
    assert grid.occupied.shape == (35, 35)
    assert 0 < grid.occupied.sum() < 35 * 35


def test_scaling_scenarios_build_for_every_controller():
    for cid in available():
        sc = open_scenario(16, model_of(cid), steps=5)
        assert sc.n == 16


def test_loglog_slope_recovers_a_power_law():
    n = np.array([4.0, 16.0, 64.0, 256.0, 1000.0])
    assert abs(loglog_slope(n, 3e-6 * n**1.3) - 1.3) < 1e-9


def test_figures_row_can_be_left_out(monkeypatch, capsys):
    from benchmarks import bench_figures

    monkeypatch.setenv("BENCH_FIGURES", "0")
    assert bench_figures.run() == []
    assert "left out" in capsys.readouterr().out


def test_each_recipe_cost_is_a_row_against_its_budget(tmp_path):
    """make bench's recipe rows read the cost.json of dfcoa figures; run.py bounds each
    by the recipe's budget."""
    import json

    from benchmarks import bench_figures, run
    from dfcoa_opt.bench.figures import COST_FILE
    from dfcoa_opt.bench.recipes import registered

    for name, cost in (("heldout", 698.2), ("examples", 40.7)):
        (tmp_path / name).mkdir()
        (tmp_path / name / COST_FILE).write_text(json.dumps({"recipe": name,
                                                             "cost_cpu_s": cost}))
    rows = bench_figures.recipe_rows(tmp_path)
    assert [r["what"] for r in rows] == [bench_figures.recipe_title("examples"),
                                        bench_figures.recipe_title("heldout")]
    assert rows[1]["median_us"] == 698.2e6
    budget = {r.name: r.budget for r in registered()}["heldout"]
    assert run._target(rows[1]["what"]) == f"<= {budget * 1e6:g} us"
