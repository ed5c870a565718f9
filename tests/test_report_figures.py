"""Report figures: trajectory panels, failure snapshots, ladder curves; ladders end to end."""

import csv
import io
import re
from pathlib import Path

import numpy as np
import pytest
from matplotlib.colors import to_rgb
from matplotlib.patches import Circle as CirclePatch
from test_metrics import make_log

from dfcoa_opt.bench.executors import ExecutorConfig
from dfcoa_opt.bench.harness import run_sweep
from dfcoa_opt.bench.report import document as report
from dfcoa_opt.bench.report import plots, trajectories
from dfcoa_opt.bench.results.logs import read_log
from dfcoa_opt.bench.sweep import load_sweep
from dfcoa_opt.metrics import contacts
from dfcoa_opt.viz import layout, plotting

ROOT = Path(__file__).resolve().parents[1]
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def test_contacts_at_names_exactly_the_robots_that_touch_and_what():
    pose = np.array([[[0.0, 0.0], [0.3, 0.0], [5.0, 0.0], [9.0, 0.0]]])  # 0-1 overlap (0.3 < 0.4)
    clearance = np.array([[5.0, 5.0, 5.0, 0.1]])  # robot 3 against a wall
    log = make_log(pose=pose, clearance=clearance, dyn_pos=np.array([[[5.0, 0.5]]]),
                   dyn_radius=np.array([0.4]))  # robot 2 overlaps a moving disc (0.5 < 0.6)

    def found():
        return [(c.kind, c.robot, c.other) for c in contacts.contacts_at(log, 0)]

    assert found() == [("robot", 0, 1), ("obstacle", 3, -1), ("moving", 2, 0)]
    log.dyn_pos[:] = [[[5.0, 0.7]]]  # 0.7 > 0.6: no longer
    assert found() == [("robot", 0, 1), ("obstacle", 3, -1)]


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
    assert len(lines) == 1  # b, at 0 % on both rungs, is named, not drawn
    assert sorted(tuple(ln.get_ydata()) for ln in lines) == [(100.0, 50.0)]
    labels = [" ".join(t.get_text().split()) for t in captured["fig"].legends[0].get_texts()]
    assert labels == ["a (n=10-40)", "0 % on every rung (see the table): b"]


def _bbox_in(artist, fig):
    """An artist's box in figure pixels, after the figure was drawn once."""
    return artist.get_window_extent(fig.canvas.get_renderer())


def test_ladder_figure_names_the_variants_at_0_percent_on_every_rung_in_a_note(tmp_path,
                                                                               monkeypatch):
    """11 of 13 variants at 0 % stacked their error bars into one block: they get a note."""
    figs = _capture(monkeypatch, plots)
    zero = [(v, 0.0, 0.0, 0.49, 4) for v in (0.0, 0.1, 0.3, 0.5, 1.0)]
    series = {"consensus": zero, "dfcoa": zero, "lf_vo": [(v, 1.0, 0.51, 1.0, 4) for v in
                                                          (0.0, 0.1, 0.3, 0.5, 1.0)],
              "orca_nav": zero, "reshape": [*zero[:2], (0.3, 0.4, 0.22, 0.61, 20), *zero[3:]],
              "virtual_spring": zero}
    plots.ladder_figure(series, "message latency (s)", tmp_path / "l.png", "t")
    fig = figs[0]
    ax = fig.axes[0]
    drawn = [c.lines[0] for c in ax.containers]
    assert len(drawn) == 2  # lf_vo and reshape, the ones with a curve
    texts = [t.get_text() for t in fig.legends[0].get_texts()]
    assert texts[:2] == ["lf_vo (n=4)", "reshape (n=4-20)"]
    note = " ".join(texts[2].split())
    assert note == "0 % on every rung (see the table): consensus, dfcoa, orca_nav, virtual_spring"
    assert not _bbox_in(fig.legends[0], fig).overlaps(_bbox_in(ax, fig))  # off the data
    # every variant at 0 %: nothing drawn, the note names them all, the rungs set the axis
    plots.ladder_figure({"a": zero, "b": zero}, "latency (s)", tmp_path / "z.png", "t")
    ax = figs[1].axes[0]
    assert not ax.containers and ax.get_xlim()[0] < 0.0 and ax.get_xlim()[1] > 1.0
    assert "no variant succeeds on any rung" in [t.get_text() for t in ax.texts]
    assert [" ".join(t.get_text().split()) for t in figs[1].legends[0].get_texts()] == [
        "0 % on every rung (see the table): a, b"]


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


def test_ladder_sweep_with_decide_at_stops_a_cell_once_it_is_wholly_below_the_line(tmp_path):
    scen = (ROOT / "scenarios" / "example_obstacles.toml").as_posix()
    sweep = tmp_path / "ladder.toml"
    sweep.write_text(f'scenarios = ["{scen}"]\ncontrollers = ["goto_slot", "orca_nav"]\n'
                     f'seeds = 2\nmax_seeds = 6\nmax_half_width = 0.25\ndecide_at = 0.6\n'
                     f'[grid]\nt_max = [4.0]\n[ladder]\nkey = "team.n"\nvalues = [2, 3]\n')
    res = run_sweep(sweep, tmp_path / "res", ExecutorConfig("serial"), progress=False)
    # 0 of 2 is [0, 65.8 %], across 60 %; 0 of 3 is [0, 56.2 %], wholly below: 3 seeds a cell,
    # one fewer than without decide_at (above)
    assert len(res.sweep.runs) == 2 * 2 * 3 and res.ran == 12


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
    assert {(ax.get_xlabel(), ax.get_ylabel()) for ax in axes} == {("x (m)", "y (m)")}
    (legend,) = fig.legends
    texts = [t.get_text() for t in legend.get_texts()]
    assert texts[:6] == ["robots (a colour each)", "final position", "leader path", "start",
                         "goal", "obstacle"]
    assert "first contact" not in texts  # no panel has a contact to mark
    layout.png_bytes(fig)  # laid out and drawn: the legend is clear of every panel
    assert not any(_bbox_in(legend, fig).overlaps(_bbox_in(ax, fig)) for ax in fig.axes)
    assert "boom" in " ".join(t.get_text() for t in axes[0].texts)
    with pytest.raises(ValueError, match="mix"):
        trajectories.panels_figure(res.store.rows(), res.store.root)


def test_sweep_seeds_override_turns_sequential_seeds_off(ladder_results):
    sweep, _ = ladder_results
    assert load_sweep(sweep).max_seeds == 6 and load_sweep(sweep, seeds=1).max_seeds == 0


# ------------------------------------------------- names, outcomes, panels, snapshots, boxes
HASH = re.compile(r"[0-9a-f]{10}")


def test_variant_name_and_outcome_text_fall_back_for_old_rows():
    assert plots.variant_name({"variant": "goto_slot+cbf", "controller": "goto_slot"}) == (
        "goto_slot+cbf")
    assert plots.variant_name({"controller": "lf_vo"}) == "lf_vo"  # row without the field
    assert plots.variant_name({"variant": "", "controller": "lf_vo"}) == "lf_vo"

    def ok(**metrics):
        return {"status": "ok", "metrics": metrics}

    text = trajectories.outcome_text
    assert text(ok(outcome="collision", first_contact_time=12.34)) == "collision at t = 12.34 s"
    assert text(ok(outcome="deadlock", deadlock_time=40)) == "deadlock from t = 40.00 s"
    assert text(ok(outcome="success", first_contact_time=None)) == "success"
    assert text(ok(outcome="collision", first_contact_time=None)) == "collision"
    assert text(ok(fce_rms=1.0)) == "?"  # old row: outcome unknown
    assert text({"status": "failed", "metrics": None}) == "run failed"


def _capture(monkeypatch, module):
    """Keep the figures ``module.save_png`` renders (and still write them)."""
    figs = []
    real = module.save_png

    def keep(fig, path):
        figs.append(fig)
        return real(fig, path)

    monkeypatch.setattr(module, "save_png", keep)
    return figs


def _save_edited(res, row, key, edit):
    """A copy of ``row`` whose log is the row's log changed by ``edit(log)``, saved anew."""
    log = read_log(res.store.root, row)
    edit(log)
    log.save(res.store.root / "logs" / f"{key}.npz")
    return {**row, "key": key, "log": f"logs/{key}.npz"}


def test_panels_one_per_variant_span_every_trajectory_and_name_no_hash(ladder_results,
                                                                       tmp_path, monkeypatch):
    _, res = ladder_results
    rows = sorted((r for r in res.store.rows() if r["seed"] == 0 and r["ladder_value"] == 2.0),
                  key=lambda r: r["controller"])
    assert all(HASH.search(str(r["overrides_hash"])) for r in rows)  # there is a hash to avoid

    def far(log):
        log.pose[-1, 0, :2] = (-9.0, 30.0)  # robot 0 ends far off the 24 m x 14 m map

    gone = _save_edited(res, rows[0], "far_away", far)
    rows = [{**rows[0], "variant": "goto_slot+hit", "metrics": {
                **rows[0]["metrics"], "outcome": "collision", "first_contact_time": 1.25}},
            {**rows[1], "variant": "orca_nav+stuck", "metrics": {
                **rows[1]["metrics"], "outcome": "deadlock", "deadlock_time": 2.0}},
            {**gone, "variant": "gone"}, *rows,
            {**rows[0], "variant": "broken", "status": "failed", "log": None, "metrics": None,
             "error": "controller 'broken' raised ValueError: " + "x" * 200}]
    figs = _capture(monkeypatch, trajectories)
    written, notes = trajectories.overlay_figures(rows, res.store.root, tmp_path, seed=0)
    assert notes == [] and [p.name for p in written["example_obstacles"]] == [
        "traj_example_obstacles_s0.png"]
    assert written["example_obstacles"][0].read_bytes()[:8] == PNG_MAGIC
    fig, = figs
    titled = [ax for ax in fig.axes if ax.get_title()]
    assert [ax.get_title() for ax in titled] == [
        "broken — run failed", "gone — timeout", "goto_slot — timeout",
        "goto_slot+hit — collision at t = 1.25 s", "orca_nav — timeout",
        "orca_nav+stuck — deadlock from t = 2.00 s"]
    assert len(fig.axes) == 8 and sum(not ax.axison for ax in fig.axes) == 2  # 2 rows of 4
    assert fig.get_suptitle() == "example_obstacles — seed 0"
    assert not any(HASH.search(ax.get_title()) for ax in titled)
    limits = {(ax.get_xlim(), ax.get_ylim()) for ax in titled}
    assert len(limits) == 1
    (x0, x1), (y0, y1) = limits.pop()
    assert x0 <= -9.0 and y1 >= 30.0 and x1 >= 24.0 and y0 <= 0.0  # map and the far robot
    failed = " ".join(t.get_text() for t in titled[0].texts)
    assert "run failed:" in failed and "raised ValueError" in failed and "x" * 100 not in failed


def test_panels_reject_mixed_scenarios(ladder_results):
    _, res = ladder_results
    rows = [r for r in res.store.rows() if r["seed"] == 0 and r["ladder_value"] == 2.0]
    with pytest.raises(ValueError, match="mix"):
        trajectories.panels_figure([rows[0], {**rows[1], "scenario": "other"}], res.store.root)


def test_panel_of_a_collision_marks_its_first_contact(ladder_results, monkeypatch):
    _, res = ladder_results
    row = next(r for r in res.store.rows() if r["seed"] == 0 and r["ladder_value"] == 3.0
               and r["controller"] == "goto_slot")
    k = 12

    def bump(log):  # robots 1 and 2 overlap from step k on (0.3 m < 2 x 0.2 m)
        log.pose[k:, 2, :2] = log.pose[k:, 1, :2] + (0.0, 0.3)
        log.clearance[:] = 5.0
        log.robot_contacts[k:] = 1

    hit = _save_edited(res, row, "bumping", bump)
    hit = {**hit, "variant": "goto_slot+hit", "metrics": {
        **row["metrics"], "outcome": "collision", "first_contact_time": k * 0.1}}
    fig = trajectories.panels_figure([hit], res.store.root)
    ax = fig.axes[0]
    assert ax.get_title() == f"goto_slot+hit — collision at t = {k * 0.1:.2f} s"
    log = read_log(res.store.root, hit)
    (mark,) = [ln for ln in ax.lines if ln.get_marker() == "X"]
    assert np.allclose(np.column_stack(mark.get_data()), [log.pose[k, 1, :2] + (0.0, 0.15)])
    red = [p for p in ax.patches if isinstance(p, CirclePatch) and not p.get_fill()]
    assert sorted(tuple(p.center) for p in red) == sorted(
        tuple(log.pose[k, i, :2]) for i in (1, 2))
    assert {"in contact", "first contact"} <= {t.get_text() for t in fig.legends[0].get_texts()}
    lead = next(ln for ln in ax.lines if ln.get_label() == "leader path")
    assert lead.get_zorder() < min(c.get_zorder() for c in ax.collections
                                   if c.get_label() == "trajectories")


def test_snapshot_draws_the_nearest_step_and_marks_exactly_the_robots_in_contact(
        ladder_results, tmp_path, monkeypatch):
    _, res = ladder_results
    row = next(r for r in res.store.rows() if r["seed"] == 0 and r["ladder_value"] == 3.0
               and r["controller"] == "orca_nav")
    k = 10

    def touch(log):  # robots 0 and 1 overlap at step k (0.3 m < 2 x 0.2 m), robot 2 is free
        log.pose[k, :, :2] = [(4.0, 7.0), (4.3, 7.0), (5.5, 7.0)]
        log.clearance[k] = 5.0
        log.pose[k + 1, :, :2] = [(4.0, 7.0), (4.0, 7.0), (4.0, 7.0)]  # all at one point

    row = _save_edited(res, row, "touching", touch)
    figs = _capture(monkeypatch, trajectories)
    log = read_log(res.store.root, row)
    t = float(log.t[k]) + 0.4 * float(log.meta["dt"])  # nearer to step k than to k + 1
    path = trajectories.snapshot_figure(row, res.store.root, tmp_path / "s.png", t)
    assert path.read_bytes()[:8] == PNG_MAGIC
    ax = figs[0].axes[0]
    discs = [p for p in ax.patches if isinstance(p, CirclePatch)
             and np.isclose(p.get_radius(), 0.2)]
    assert len(discs) == 3
    red = np.asarray(to_rgb(plotting.CONTACT_COLOR))
    rings = sorted(tuple(p.center) for p in ax.patches if isinstance(p, CirclePatch)
                   and not p.get_fill() and np.allclose(p.get_edgecolor()[:3], red))
    assert rings == [(4.0, 7.0), (4.3, 7.0)]  # robots 0 and 1, not 2
    (mark,) = [ln for ln in ax.lines if ln.get_marker() == "X"]
    assert np.allclose(np.column_stack(mark.get_data()), [(4.15, 7.0)])
    assert ax.get_title() == ("example_obstacles / orca_nav / seed 0\ntimeout\n"
                              "at t = 1.00 s: robot 0 and robot 1")
    # the legend says what the crosses (slots), the triangle (leader) and the X mean
    legend = figs[0].legends[0]
    marks = {t.get_text(): getattr(h, "get_marker", lambda: None)()
             for h, t in zip(legend.legend_handles, legend.get_texts(), strict=True)}
    assert marks["formation slots"] == "x" and marks["leader"] == "^"
    assert marks["contact"] == "X" and "in contact" in marks
    fig = figs[0]  # drawn by save_png: the title is inside the figure
    title = fig.axes[0].title.get_window_extent(fig.canvas.get_renderer())
    assert title.x0 >= 0 and title.x1 <= fig.bbox.x1 and title.y1 <= fig.bbox.y1
    grey = [p for p in ax.patches if isinstance(p, CirclePatch)
            and np.isclose(p.get_radius(), 0.3)]  # the moving disc, where the log has it
    assert len(grey) == 1 and np.allclose(grey[0].center, log.dyn_pos[k, 0])
    trajectories.snapshot_figure(row, res.store.root, tmp_path / "t.png", t, title="mine")
    assert figs[1].axes[0].get_title() == "mine"


def test_boxplot_has_one_box_per_variant_named_without_hash(tmp_path, monkeypatch):
    def r(controller, seed, value, variant=None):
        out = {"scenario": "sc", "controller": controller, "seed": seed, "status": "ok",
               "overrides_hash": "c4d9c17a7e", "metrics": {"fce_rms": value}}
        return out if variant is None else {**out, "variant": variant}

    rows = [r("dfcoa", 0, 1.0, "dfcoa"), r("dfcoa", 1, 2.0, "dfcoa"),
            r("dfcoa", 0, 3.0, "dfcoa_compensated"), r("lf_vo", 0, 4.0)]  # old row: no variant
    figs = _capture(monkeypatch, plots)
    plots.metric_boxplots(rows, "fce_rms", tmp_path / "b.png")
    ax = figs[0].axes[0]
    labels = [t.get_text() for t in ax.get_xticklabels()]
    assert labels == ["dfcoa\n(n=2)", "dfcoa_compensated\n(n=1)", "lf_vo\n(n=1)"]
    dots = sorted(float(y) for ln in ax.lines if ln.get_marker() == "o" for y in ln.get_ydata())
    assert dots == [1.0, 2.0, 3.0, 4.0]


def test_ladder_figure_is_linear_unless_asked(tmp_path, monkeypatch):
    figs = _capture(monkeypatch, plots)
    plots.ladder_figure({"a": [(0.1, 1.0, 0.8, 1.0, 5), (0.2, 0.4, 0.1, 0.7, 5)]},
                        "noise (m)", tmp_path / "l.png", "t")
    ax = figs[0].axes[0]
    assert ax.get_xscale() == "linear" and ax.get_ylim() == (-3.0, 103.0)
    assert ax.get_xlabel() == "noise (m)"
