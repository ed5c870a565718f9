"""Formation errors of two variants over the instants open in both runs (issue 20's target)."""

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import dfcoa_opt as d
from dfcoa_opt.bench.report.shared_open import shared_open_errors, shared_open_table
from dfcoa_opt.metrics import open_steps, summary

ROOT = Path(__file__).resolve().parents[1]
OBSTACLES = ROOT / "scenarios" / "example_obstacles.toml"


@pytest.fixture(scope="module")
def runs():
    sc = d.load(OBSTACLES, t_max=30.0)
    return sc, d.run(sc, "goto_slot", seed=0).log, d.run(sc, "goto_slot+cbf", seed=0).log


def test_a_run_against_itself_gives_its_own_open_stretch_errors(runs):
    sc, a, _ = runs
    cfg = sc.spec.metrics
    own = summary(a, sc)
    got = shared_open_errors(a, a, cfg)
    assert 0.0 < got.fraction < 1.0  # the example has open and obstructed stretches
    assert got.fraction == pytest.approx(open_steps(a, cfg).mean())
    assert got.fce == pytest.approx((own["fce_open_rms"],) * 2)
    assert got.fse == pytest.approx((own["fse_open_rms"],) * 2)


def test_only_instants_open_in_both_runs_count(runs):
    sc, a, b = runs
    cfg = sc.spec.metrics
    got = shared_open_errors(a, b, cfg)
    n = min(len(a.t), len(b.t))
    assert got.fraction <= min(open_steps(a, cfg)[:n].mean(), open_steps(b, cfg)[:n].mean())
    wider = shared_open_errors(a, b, replace(cfg, open_clearance=cfg.open_clearance + 2.0))
    assert wider.fraction <= got.fraction  # a wider clearance opens no more instants
    none = shared_open_errors(a, b, replace(cfg, open_clearance=1e6))
    assert none.fraction == 0.0 and all(math.isnan(v) for v in none.fce + none.fse)


def test_runs_logged_at_different_instants_are_refused(runs):
    sc, a, b = runs
    shifted = replace(b, t=b.t + 0.05)
    with pytest.raises(ValueError, match="not logged at the same instants"):
        shared_open_errors(a, shifted, sc.spec.metrics)


def test_the_table_pairs_the_seeds_of_a_sweep(tmp_path):
    spec = {"scenarios": [str(OBSTACLES)], "controllers": ["goto_slot", "goto_slot+cbf"],
            "seeds": 2}
    res = d.sweep(spec, tmp_path / "res", jobs=1, overrides={"t_max": 30.0}, progress=False)
    text = shared_open_table(res.folder, "goto_slot", "goto_slot+cbf", clearances=(1.0, 1e6))
    rows = [line for line in text.splitlines() if line.startswith("| example_obstacles")]
    assert len(rows) == 2 and "| 2/2 |" in rows[0] and "| 0/2 |" in rows[1]
    cells = rows[0].split("|")
    fce_a = float(cells[5].split("/")[0])
    logs = [(res.log("example_obstacles", "goto_slot", k),
             res.log("example_obstacles", "goto_slot+cbf", k)) for k in (0, 1)]
    cfg = d.load(OBSTACLES).spec.metrics
    want = np.median([shared_open_errors(x, y, cfg).fce[0] for x, y in logs])
    assert fce_a == pytest.approx(want, abs=5e-4)
    assert shared_open_table(res.folder, "goto_slot", "nobody") == ""
