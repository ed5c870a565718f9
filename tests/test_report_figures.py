"""Report figures: trajectory panels, failure snapshots, ladder curves; ladders end to end."""

import csv
import io
from pathlib import Path

import numpy as np
import pytest
from test_metrics import make_log

from dfcoa_opt.bench import plots, report, trajectories
from dfcoa_opt.bench.executors import ExecutorConfig
from dfcoa_opt.bench.harness import run_sweep
from dfcoa_opt.bench.sweep import load_sweep

ROOT = Path(__file__).resolve().parents[1]
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def test_contacts_at_marks_exactly_the_robots_that_touch():
    pose = np.array([[[0.0, 0.0], [0.3, 0.0], [5.0, 0.0], [9.0, 0.0]]])  # 0-1 overlap (0.3 < 0.4)
    clearance = np.array([[5.0, 5.0, 5.0, 0.1]])  # robot 3 against a wall
    log = make_log(pose=pose, clearance=clearance, dyn_pos=np.array([[[5.0, 0.5]]]),
                   dyn_radius=np.array([0.4]))  # robot 2 overlaps a moving disc (0.5 < 0.6)
    assert trajectories.contacts_at(log, 0).tolist() == [True, True, True, True]
    log.dyn_pos[:] = [[[5.0, 0.7]]]  # 0.7 > 0.6: no longer
    assert trajectories.contacts_at(log, 0).tolist() == [True, True, False, True]


def test_nearest_step():
    log = make_log(pose=np.zeros((11, 1, 2)))  # t = 0, 0.1, ..., 1.0
    assert trajectories.nearest_step(log, 0.34) == 3
    assert trajectories.nearest_step(log, 99.0) == 10
    assert trajectories.nearest_step(log, float("inf")) == 10


def test_ladder_figure_draws_one_line_per_variant_with_the_given_points(tmp_path, monkeypatch):
    captured = {}
    real = plots.save_png

    def keep(fig, path):
        captured["fig"] = fig
        return real(fig, path)

    monkeypatch.setattr(plots, "save_png", keep)
    series = {"a": [(4, 1.0, 0.7, 1.0, 10), (100, 0.5, 0.35, 0.65, 40)],
              "b": [(4, 0.0, 0.0, 0.3, 10), (100, 0.0, 0.0, 0.3, 10)]}
    path = plots.ladder_figure(series, "team size", tmp_path / "l.png", "t", log_x=True)
    assert path.read_bytes()[:8] == PNG_MAGIC
    ax = captured["fig"].axes[0]
    assert ax.get_xscale() == "log" and ax.get_ylabel() == "success rate (%)"
    lines = [c.lines[0] for c in ax.containers]  # the data line of each error-bar plot
    assert len(lines) == 2
    assert sorted(tuple(ln.get_ydata()) for ln in lines) == [(0.0, 0.0), (100.0, 50.0)]
    labels = [t.get_text() for t in captured["fig"].legends[0].get_texts()]
    assert labels == ["a (n=10-40)", "b (n=10)"]


@pytest.fixture(scope="module")
def ladder_results(tmp_path_factory):
    """A tiny ladder sweep with sequential seeds, run serially."""
    folder = tmp_path_factory.mktemp("ladder")
    sweep = folder / "ladder.toml"
    scen = (ROOT / "scenarios" / "example_obstacles.toml").as_posix()
    sweep.write_text(f'scenarios = ["{scen}"]\ncontrollers = ["goto_slot", "orca_nav"]\n'
                     f'seeds = 2\nmax_seeds = 6\nmax_half_width = 0.25\n'
                     f'[grid]\nt_max = [4.0]\n[ladder]\nkey = "team.n"\nvalues = [2, 3]\n')
    res = run_sweep(sweep, folder / "res", ExecutorConfig("serial"), progress=False)
    return sweep, res


def test_ladder_sweep_adds_seeds_to_undecided_cells_and_reports_curves(ladder_results, tmp_path):
    sweep, res = ladder_results
    # 4 s runs never arrive: every cell is 0 of 2, whose Wilson half-width (0.329) is above
    # 0.25; 0 of 3 is still 0.281, 0 of 4 is 0.245: each cell ends with 4 seeds, below the cap
    assert len(res.sweep.runs) == 2 * 2 * 4 and res.ran == 16
    assert sorted({r.seed for r in res.sweep.runs}) == [0, 1, 2, 3]
    assert res.store.manifest()["keys"] == [r.key for r in res.sweep.runs]
    table = list(csv.DictReader(io.StringIO((res.store.root / "results.csv").read_text())))
    assert len(table) == 16 and {"variant", "outcome", "reached", "ladder_value"} <= set(table[0])
    assert {r["outcome"] for r in table} == {"timeout"} and {r["reached"] for r in table} == {
        "False"}
    again = run_sweep(sweep, res.store.root, ExecutorConfig("serial"), progress=False)
    assert again.ran == 0 and len(again.sweep.runs) == 16  # resumes to the same runs
    paths = report.make_report(res.store.root, tmp_path)
    names = [p.name for p in paths]
    assert "ladder_team.n_example_obstacles.png" in names and "ladders.csv" in names
    md = (tmp_path / "report.md").read_text()
    assert "## Ladder `team.n` on `example_obstacles`" in md
    assert "| goto_slot | 0% [0, 49] (0/4) | 0% [0, 49] (0/4) |" in md


def test_panels_have_one_titled_panel_per_variant_with_the_same_axes(ladder_results):
    _, res = ladder_results
    rows = [r for r in res.store.rows() if r["seed"] == 0 and r["ladder_value"] == 2.0]
    rows.append({**rows[0], "variant": "broken", "status": "failed", "log": None,
                 "error": "controller 'broken' raised ValueError: boom"})
    fig = trajectories.panels_figure(rows, res.store.root)
    axes = [ax for ax in fig.axes if ax.get_title()]
    assert [ax.get_title() for ax in axes] == ["broken — run failed", "goto_slot — timeout",
                                               "orca_nav — timeout"]
    assert len({(ax.get_xlim(), ax.get_ylim()) for ax in axes}) == 1
    assert "boom" in " ".join(t.get_text() for t in axes[0].texts)
    with pytest.raises(ValueError, match="mix"):
        trajectories.panels_figure(res.store.rows(), res.store.root)


def test_sweep_seeds_override_turns_sequential_seeds_off(ladder_results):
    sweep, _ = ladder_results
    assert load_sweep(sweep).max_seeds == 6 and load_sweep(sweep, seeds=1).max_seeds == 0
