"""The paper-table renderers: Table 5 of paper 000 and the A* comparison."""

import csv
import io
from pathlib import Path

import numpy as np
import pytest

from dfcoa_opt import metrics
from dfcoa_opt.bench.recipes import astar as recipes_astar
from dfcoa_opt.bench.recipes import dfcoa as recipes_dfcoa
from dfcoa_opt.planning.astar import plan
from dfcoa_opt.planning.improved_astar import ImprovedAStarParams

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"


class _Store:
    """The part of ResultsStore the Table 5 renderer reads."""

    def __init__(self, rows):
        self._rows = rows

    def rows(self):
        return self._rows


def _row(scenario, mode, seed, values, variant="dfcoa"):
    return {"scenario": scenario, "seed": seed, "status": "ok", "controller": "dfcoa",
            "variant": f"{variant}[mode={mode}]", "overrides": {"localization.mode": mode},
            "metrics": dict(values)}


def _cells(text, label):
    line = next(ln for ln in text.splitlines() if ln.startswith(f"| {label} |"))
    return [c.strip() for c in line.strip("|").split("|")]


def test_table5_has_every_paper_row_paper_values_and_our_means(tmp_path):
    paper = metrics.PAPER_000_TABLE5
    rows = []
    for i, scen in enumerate(recipes_dfcoa.SCENARIOS):
        for mode, shift in (("truth", 0.0), ("mcl", 0.5)):
            for seed, jitter in ((0, -0.25), (1, 0.25)):  # mean = paper value + shift
                vals = {k: v[i] + shift + jitter for k, v in paper.items()}
                vals.update(collisions=0, loc_rmse=0.1 if mode == "mcl" else 0.0,
                            time_to_goal=80.0)
                rows.append(_row(scen, mode, seed, vals))
    path = recipes_dfcoa._table5(_Store(rows), tmp_path)
    text = path.read_text()
    peak_keys = {k for k, *_ in recipes_dfcoa.PEAK_RISK_ROWS}
    for key, label, unit, pkey in recipes_dfcoa.TABLE5_ROWS:
        cells = _cells(text, label)
        assert cells[1] == unit
        # | label | unit | S1 paper | S1 truth | S1 mcl | S2 paper | S2 truth | S2 mcl |
        assert float(cells[2]) == pytest.approx(paper[pkey][0])
        assert float(cells[5]) == pytest.approx(paper[pkey][1])
        if key in peak_keys:  # from the raw risk, which these rows do not carry
            assert cells[3] == cells[4] == "—"
            continue
        for col, i, shift in ((3, 0, 0.0), (4, 0, 0.5), (6, 1, 0.0), (7, 1, 0.5)):
            mean = float(cells[col].split("±")[0])
            assert mean == pytest.approx(paper[key][i] + shift, abs=1e-4), (label, col)
    zero = "0.0000 ± 0.0000"
    assert _cells(text, "Collisions")[2:] == ["0", zero, zero, "0", zero, zero]
    assert "dfcoa_s1 mcl: 2 runs, 0 failed" in text
    # truth hits the paper values exactly -> met; mcl is 0.5 worse on FCE -> missed
    fce = _cells(text, "FCE RMS ≤ paper")
    assert fce[1:] == ["met", "**missed**", "met", "**missed**"]
    stab = _cells(text, "stability ≥ paper")
    assert stab[1:] == ["met", "met", "met", "met"]  # higher stability is better


def test_table5_marks_a_missing_mode_and_a_collision(tmp_path):
    paper = metrics.PAPER_000_TABLE5
    vals = {k: v[0] for k, v in paper.items()} | {"collisions": 2}
    text = recipes_dfcoa._table5(_Store([_row("dfcoa_s1", "truth", 0, vals)]), tmp_path).read_text()
    assert _cells(text, "collisions = 0")[1:] == ["**missed**", "—", "—", "—"]
    assert _cells(text, "FCE (RMS)")[4] == "—"  # S1 mcl: no runs


def test_peak_risk_divides_by_the_larger_peak_of_the_same_seed_mode_and_reading():
    raw = {("dfcoa_s1", 0): (4.0, 10.0), ("dfcoa_s2", 0): (2.0, 5.0),
           ("dfcoa_s1", 1): (3.0, 6.0), ("dfcoa_s2", 1): (1.0, 8.0)}
    rows = [_row(s, "truth", seed, {"risk_raw_mean": m, "risk_raw_max": x})
            for (s, seed), (m, x) in raw.items()]
    rows.append(_row("dfcoa_s1", "mcl", 0, {"risk_raw_mean": 1.0, "risk_raw_max": 2.0}))
    rows.append(_row("dfcoa_s1", "truth", 0, {"risk_raw_mean": 1.0, "risk_raw_max": 50.0},
                     variant="dfcoa_no_repulsion"))
    got = [(r["metrics"]["risk_peak_mean"], r["metrics"]["risk_peak_max"])
           for r in recipes_dfcoa.with_peak_risk(rows)]
    assert got[:4] == [(0.4, 1.0), (0.2, 0.5), (3.0 / 8.0, 0.75), (1.0 / 8.0, 1.0)]
    # no S2 run with that mode (or that reading): no peak over both
    assert all(np.isnan(v) for v in got[4] + got[5])
    # a run with a contact has no raw risk (null): no peak for its seed, no error
    touched = [_row("dfcoa_s1", "truth", 2, {"risk_raw_mean": None, "risk_raw_max": None}),
               _row("dfcoa_s2", "truth", 2, {"risk_raw_mean": 1.0, "risk_raw_max": 3.0})]
    peaks = [(r["metrics"]["risk_peak_mean"], r["metrics"]["risk_peak_max"])
             for r in recipes_dfcoa.with_peak_risk(touched)]
    assert all(np.isnan(v) for pair in peaks for v in pair)


def test_a_table5_cell_says_when_fewer_runs_than_the_column_had_a_value():
    group = {"_g": {"ok": 10},
             "fce_rms": {"mean": 0.5, "ci95": 0.01, "n": 10},
             "risk_peak_mean": {"mean": 0.25, "ci95": 0.02, "n": 7},
             "time_to_goal": {"mean": float("nan"), "ci95": float("nan"), "n": 0}}
    assert recipes_dfcoa._cell(group, "fce_rms") == "0.5000 ± 0.0100"
    assert recipes_dfcoa._cell(group, "risk_peak_mean") == "0.2500 ± 0.0200 (n=7 of 10)"
    assert recipes_dfcoa._cell(group, "time_to_goal") == "—"
    assert recipes_dfcoa._cell({}, "fce_rms") == "—"


def test_table5_prints_each_reading_beside_the_tables_truth_column(tmp_path):
    base = {"fce_rms": 1.0, "collisions": 0}
    rows = [_row(s, "truth", 0, base) for s in recipes_dfcoa.SCENARIOS]
    rows += [_row(s, "truth", 0, {**base, "fce_rms": 2.0}, variant="dfcoa_tracking_start")
             for s in recipes_dfcoa.SCENARIOS]
    text = recipes_dfcoa._table5(_Store(rows), tmp_path).read_text()
    main, readings = text.split("## Readings of the paper")
    # Table 5 is the base controller; the reading's runs show only in the readings' table
    assert _cells(main, "FCE (RMS)")[3] == "1.0000"
    cells = _cells(readings, "FCE (RMS)")
    # | label | unit | S1 paper | S1 base | S1 tracking | S1 no repulsion | S2 paper | ...
    assert cells[3:6] == ["1.0000", "2.0000", "—"] and cells[7:10] == ["1.0000", "2.0000", "—"]


@pytest.fixture(scope="module")
def astar_outputs(tmp_path_factory):
    dest = tmp_path_factory.mktemp("astar")
    arts = recipes_astar.render_astar(SCENARIOS, dest)
    return dest, arts


def test_astar_recipe_covers_both_dfcoa_maps_and_the_random_maps(astar_outputs):
    dest, arts = astar_outputs
    assert {a.path for a in arts} == {"astar_comparison.md", "astar_comparison.csv",
                                      "astar_paths.png"}
    text = (dest / "astar_comparison.md").read_text()
    assert "## dfcoa_s1: start (7.0, 7.0) → goal (12.0, 29.0)" in text
    assert "## dfcoa_s2: start (31.0, 4.0) → goal (20.55, 27.0)" in text
    assert f"on {recipes_astar.N_RANDOM} maps" in text
    assert text.count("| -27% |") == 3 * 2 and text.count("| -35% |") == 3 * 2  # paper column
    rows = list(csv.DictReader(io.StringIO((dest / "astar_comparison.csv").read_text())))
    maps = {r["map"] for r in rows}
    assert {"dfcoa_s1", "dfcoa_s2"} <= maps and len(maps) == 2 + recipes_astar.N_RANDOM
    assert all(r["found"] == "True" for r in rows)
    assert (dest / "astar_paths.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_astar_recipe_nodes_and_lengths_are_the_planners_own(astar_outputs):
    """The deterministic columns equal a direct plan with the scenario's options."""
    dest, _ = astar_outputs
    rows = {(r["map"], r["planner"]): r
            for r in csv.DictReader(io.StringIO((dest / "astar_comparison.csv").read_text()))}
    tasks, inflate = recipes_astar.dfcoa_tasks(SCENARIOS)
    assert inflate == pytest.approx(1.2)
    for task in tasks:
        res = plan(task.grid, task.start, task.goal, ImprovedAStarParams(inflate=inflate))
        row = rows[task.name, "improved_astar"]
        assert int(row["nodes"]) == res.expanded
        assert float(row["length_m"]) == pytest.approx(res.length, rel=1e-12)
        np.testing.assert_allclose(res.path[0], task.start)
        np.testing.assert_allclose(res.path[-1], task.goal)


def _recipe_run(tmp_path, name, overrides=None):
    """Run one paper recipe's real sweep (serially) and render it into ``tmp_path``."""
    from dfcoa_opt.bench.executors import ExecutorConfig
    from dfcoa_opt.bench.harness import run_sweep
    from dfcoa_opt.bench.recipes import registered

    rec = next(r for r in registered() if r.name == name)
    res = run_sweep(SCENARIOS / rec.sweep, tmp_path / "cache", ExecutorConfig("serial"),
                    progress=False, overrides=overrides)
    assert res.failed == 0
    arts = rec.render(res.store, tmp_path)
    return arts, res.store


def test_paper001_table1_reports_each_obstacle_mode_beside_the_paper(tmp_path):
    from dfcoa_opt.bench.recipes import paper001 as rp

    arts, store = _recipe_run(tmp_path, "paper001_ivo")
    text = (tmp_path / "table1.md").read_text()
    cells = {m: _cells(text, m) for m in ("orca", "ivo", "none")}
    for mode, row in cells.items():
        assert row[2] == rp.PAPER_TABLE1[mode]
    assert cells["orca"][3] == "0/2" and cells["ivo"][3] == "2/2" and cells["none"][3] == "2/2"
    assert int(cells["none"][7]) > 0 and int(cells["ivo"][7]) == 0 == int(cells["orca"][7])
    # the numbers are the logs' own
    for row in store.rows():
        log = rp.RunLog.load(store.root / row["log"])
        mode = row["overrides"]["controllers.orca_nav.obstacles"]
        gap = float(np.min(log.clearance) - log.meta["robot_radius"])
        assert cells[mode][5] == f"{gap:.3f}"
    assert {a.path for a in arts} == {"table1.md", "fig_orca.png", "fig_ivo.png", "fig_none.png"}
    assert all((tmp_path / a.path).stat().st_size > 0 for a in arts)


def test_paper001_table2_has_every_variant_and_the_leader_arrival(tmp_path):
    from dfcoa_opt.bench.recipes import paper001 as rp

    arts, store = _recipe_run(tmp_path, "paper001_consensus", {"t_max": 1.0})
    text = (tmp_path / "table2.md").read_text()
    assert rp.PAPER_TABLE2 in text
    body = [ln for ln in text.splitlines() if ln.startswith("| consensus")]
    # consensus, and consensus_ivo x 2 laws x with and without the next-step filter,
    # each at 2 speed limits
    assert len(body) == 10 == len(store.rows())
    assert sum("8.485" in ln for ln in body) == 5
    assert sum("safe_discrete" in ln for ln in body) == 4
    for row in store.rows():  # the leader (4.24 m/s, 35 m) is still moving at 1 s
        log = rp.RunLog.load(store.root / row["log"])
        assert rp.leader_arrival(log) == log.n_steps - 1
    assert sum(a.path.startswith("fig8_") for a in arts) == 10


def test_paper002_tables_put_the_papers_values_beside_the_logs_own(tmp_path):
    from dfcoa_opt.bench.recipes import paper002 as rp

    arts, store = _recipe_run(tmp_path, "paper002_tables", {"t_max": 2.0})
    text = (tmp_path / "tables.md").read_text()
    rows = store.rows()
    assert len(rows) == 3 * 5
    for name, (table, _angle) in rp.SCENARIOS.items():
        section = text.split(f"## Table {table}:")[1].split("## Table")[0]
        runs = [rp.RunLog.load(store.root / r["log"]) for r in sorted(
            (r for r in rows if r["scenario"] == name), key=lambda r: r["seed"])]
        dist = np.array([rp.distance_travelled(log) for log in runs])  # (seeds, 3)
        cells = _cells(section, "Distance")
        # | Distance | m | R1 paper | R1 ours | R2 paper | R2 ours | R3 paper | R3 ours |
        for i in range(3):
            assert float(cells[2 + 2 * i]) == pytest.approx(rp.PAPER[table]["dist"][i])
            mean = float(cells[3 + 2 * i].split(" [")[0])
            assert mean == pytest.approx(dist[:, i].mean(), abs=6e-4)
        err = _cells(section, "Error formation position")
        assert err[2] == "—" and err[3] == "—"  # the paper and we give none for Robot 1
        # 2 s is too short to reach the target: never reached, said so
        assert _cells(section, "Time to target")[3] == "—"
    # every run that did not succeed (at 2 s: all of them, timeouts) is listed with a snapshot
    failed = [r for r in rows if r["metrics"]["outcome"] != "success"]
    assert failed and all(f"`{r['scenario']}` seed {r['seed']}: **{r['metrics']['outcome']}**"
                          in text for r in failed)
    shots = {f"fail_{r['scenario']}_s{r['seed']}.png" for r in failed}
    assert {a.path for a in arts} == {"tables.md", *(f"fig_{n}.png" for n in rp.SCENARIOS),
                                      *shots}
    assert all((tmp_path / name).stat().st_size > 0 for name in shots)


def test_paper004_tables_put_the_papers_values_beside_the_logs_own(tmp_path):
    from dfcoa_opt.bench.recipes import paper004 as rp

    arts, store = _recipe_run(tmp_path, "paper004_tables", {"t_max": 1.0})
    text = (tmp_path / "tables.md").read_text()
    rows = store.rows()
    assert len(rows) == 16 * 10
    # Table 2, n = 5, leader: the paper's 10 runs and ours, mean [min, max]
    t2 = text.split("## Table 2")[1].split("## Table 3")[0]
    line = next(ln for ln in t2.splitlines() if ln.startswith("| 5 | Leader |"))
    cells = [c.strip() for c in line.strip("|").split("|")]
    assert cells[2] == "38.19 [38.18, 38.20]"
    runs = [rp.RunLog.load(store.root / r["log"]) for r in rows if r["scenario"] == "vs_n5_dyn0"]
    lead = [rp.path_length_per_robot(log)[0] for log in runs]
    assert float(cells[3].split(" [")[0]) == pytest.approx(np.mean(lead), abs=6e-3)
    assert cells[4] == "10"
    # Table 3 carries the paper's numbers; Table 4 has every n x obstacle count
    t3 = text.split("## Table 3")[1].split("## Table 4")[0]
    assert "| 20 | 6.52 |" in t3 and "827.66" in t3
    t4 = text.split("## Table 4")[1]
    assert sum(ln.startswith("| ") and "followers" in ln for ln in t4.splitlines()) == 4 * 3
    assert {a.path for a in arts} >= {"tables.md", "fig6_trajectories_static.png",
                                      "fig11_ideal_error_dynamic.png"}


def test_paper004_scenarios_are_table_1_and_the_generators_output(tmp_path):
    """The committed files equal generate.py's output and hold Table 1's numbers."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("gen004", SCENARIOS / "paper004/generate.py")
    gen = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(gen)
    from dfcoa_opt.core.geometry import rotate
    from dfcoa_opt.scenario.loader import load_scenario

    for n in (5, 10, 15, 20):
        for k in range(4):
            path = SCENARIOS / f"paper004/vs_n{n}_dyn{k}.toml"
            assert path.read_text() == gen.scenario(n, k), path
    sc = load_scenario(str(SCENARIOS / "paper004/vs_n20_dyn3.toml"))
    assert sc.n == 20
    starts = np.array([p[:2] for p in sc.spec.team.poses])
    np.testing.assert_allclose(starts[:5], [[1, 1], [0.5, 2], [2.3, 0.2], [1.2, 1.8], [1.3, 1.2]])
    np.testing.assert_allclose(starts[-5:], [[1, 2], [2.8, 0.2], [1.7, 1.8], [1.8, 1.2], [1.5, 1]])
    world_e = rotate(sc.offsets, sc.leader_heading)  # Table 1's errors E_i, world frame
    np.testing.assert_allclose(world_e[:5], [[0, 0], [-1.5, 1.5], [-3, 1.5], [-1.5, -1.5],
                                             [-3, -1.5]], atol=1e-9)
    np.testing.assert_allclose(world_e[5:10], [[-0.5, 2.5], [-2, 2.5], [-0.5, -0.5], [-2, -0.5],
                                               [1, 1]], atol=1e-9)
    centres = sorted(tuple(c.center) for c in sc.world.circles)
    assert centres == sorted([(9, 10), (11, 9), (10, 12), (14, 17), (15, 13), (15, 16), (20, 19)])
    assert len(sc.spec.world.dynamic_obstacles) == 3


def test_beyond_recipe_reports_solve_times_of_cbf_and_nmpc(tmp_path):
    """The "beyond" renderer: the cross-method table and a solve-time row per solver-backed
    controller, whose robot-step count is that of the logs."""
    from dfcoa_opt.bench.executors import ExecutorConfig
    from dfcoa_opt.bench.harness import run_sweep
    from dfcoa_opt.bench.recipes.beyond import render_beyond

    tiny = Path(__file__).parent / "data" / "bench" / "tiny.toml"
    sweep = tmp_path / "beyond.toml"
    sweep.write_text(f'name = "beyond"\nscenarios = ["{tiny}"]\n'
                     'controllers = ["nmpc", "goto_slot+cbf", "goto_slot"]\nseeds = 1\n'
                     '[[variants]]\nt_max = 1.0\n')
    res = run_sweep(sweep, tmp_path / "out", ExecutorConfig("serial"), progress=False)
    assert res.failed == 0
    arts = render_beyond(res.store, tmp_path / "fig")
    assert {"solve_times.md"} <= {a.path for a in arts}
    text = (tmp_path / "fig" / "solve_times.md").read_text()
    rows = [ln.split(" | ") for ln in text.splitlines() if ln.startswith("| nmpc")
            or ln.startswith("| goto_slot+cbf")]
    assert len(rows) == 2 and "| goto_slot |" not in text  # goto_slot has no solver
    nmpc = next(r for r in rows if r[0] == "| nmpc")
    assert float(nmpc[2]) > 0 and float(nmpc[3]) >= float(nmpc[2])
    assert int(nmpc[4]) == 3 * 11  # 3 robots x 11 logged steps of 1 s at dt 0.1
