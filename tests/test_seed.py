"""One meaning of the seed: ``d.run``, ``dfcoa run --seed`` and a sweep give the same run."""

from __future__ import annotations

from pathlib import Path

import pytest

import dfcoa_opt as d
from dfcoa_opt.cli import main
from dfcoa_opt.core.errors import DfcoaError
from dfcoa_opt.scenario.loader import reseed
from dfcoa_opt.sim.log import RunLog

ROOT = Path(__file__).resolve().parents[1]
COMMON = [ROOT / "scenarios" / "dfcoa_s1.toml", ROOT / "scenarios" / "dfcoa_s2.toml",
          *sorted((ROOT / "scenarios" / "bench").glob("*.toml"))]
CLUTTER = ROOT / "scenarios" / "bench" / "clutter.toml"
SEEDS = (0, 1, 2)


def test_the_seven_common_scenarios_are_all_here():
    assert [p.stem for p in COMMON] == ["dfcoa_s1", "dfcoa_s2", "clutter", "corridor", "crossing",
                                        "large_100", "large_20"]


@pytest.fixture(scope="module")
def sweep_digests(tmp_path_factory) -> dict[tuple[str, int], str]:
    """Every (scenario, seed) of one sweep, run in this process."""
    res = d.sweep({"scenarios": [str(p) for p in COMMON], "controllers": ["goto_slot"],
                   "seeds": len(SEEDS)}, tmp_path_factory.mktemp("sweep"), jobs=1,
                  progress=False)
    return {(r["scenario"], r["seed"]): r["digest"] for r in res.rows}


@pytest.mark.parametrize("path", COMMON, ids=lambda p: p.stem)
def test_every_entry_point_gives_the_same_run_for_a_seed(path, sweep_digests, tmp_path):
    loaded = d.load(path)  # drawn for the file's own seed
    for seed in SEEDS:
        assert main(["run", str(path), "--seed", str(seed), "--out", str(tmp_path),
                     "--json"]) == 0
        cli = RunLog.load(tmp_path / f"{path.stem}-goto_slot-s{seed}.npz").digest()
        assert d.run(path, "goto_slot", seed=seed).log.digest() == cli
        assert d.run(loaded, "goto_slot", seed=seed).log.digest() == cli
        assert d.run(d.load(path, seed=seed), "goto_slot").log.digest() == cli
        assert sweep_digests[(path.stem, seed)] == cli


def test_a_loaded_clutter_scenario_is_drawn_again_for_the_run_seed():
    loaded = d.load(CLUTTER, t_max=5.0)
    assert loaded.seed_dependent and loaded.spec.seed not in SEEDS
    runs = [d.run(loaded, "goto_slot", seed=s) for s in SEEDS]
    fields = [tuple(c.center for c in r.scenario.world.circles) for r in runs]
    assert len(set(fields)) == len(SEEDS)  # one field per seed ...
    for seed, r, field in zip(SEEDS, runs, fields, strict=True):
        again = d.load(CLUTTER, seed=seed, t_max=5.0)  # ... the one its file load draws,
        assert r.scenario.spec.seed == seed and r.scenario.spec.t_max == 5.0  # overrides kept
        assert field == tuple(c.center for c in again.world.circles)
        assert r.scenario.leader_path.tobytes() == again.leader_path.tobytes()
    assert len({r.log.digest() for r in runs}) == len(SEEDS)


def test_a_scenario_without_a_seeded_world_is_not_rebuilt():
    s = d.load(ROOT / "scenarios" / "bench" / "corridor.toml")
    assert not s.seed_dependent and reseed(s, s.spec.seed + 1) is s
    fixed = d.load(CLUTTER, world__clutter__seed=11)  # the field has a seed of its own
    assert not fixed.seed_dependent and reseed(fixed, 0) is fixed


def test_a_seeded_world_without_its_file_data_stops_with_one_line():
    from dataclasses import replace

    bare = replace(d.load(CLUTTER), data=None)
    assert reseed(bare, bare.spec.seed) is bare
    with pytest.raises(DfcoaError, match=r"clutter\.toml: its world follows the seed, "
                                         r"so load it with seed 3") as err:
        d.run(bare, "goto_slot", seed=3)
    assert "\n" not in str(err.value)
