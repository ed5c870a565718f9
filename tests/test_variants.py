"""Sweep files: named variants, baseline, grids named by value, ladders, sequential seeds."""

import re
from pathlib import Path

import pytest

from dfcoa_opt.bench import precision
from dfcoa_opt.bench.sweep import load_sweep
from dfcoa_opt.core.errors import ScenarioError

ROOT = Path(__file__).resolve().parents[1]
SCEN = (ROOT / "scenarios" / "example_obstacles.toml").as_posix()
HEX = re.compile(r"[0-9a-f]{10}")


def _sweep(tmp_path, body, name="s.toml"):
    path = tmp_path / name
    path.write_text(f'scenarios = ["{SCEN}"]\n' + body)
    return path


def test_named_variants_controllers_and_baseline(tmp_path):
    sw = load_sweep(_sweep(tmp_path, 'controllers = ["goto_slot"]\nseeds = 2\n'
                                     'baseline = "goto_slot"\n[variants]\n'
                                     'slow = { controller = "goto_slot", '
                                     '"controllers.goto_slot.kp" = 0.3 }\n'
                                     '"dfcoa_comp" = { controller = "dfcoa", '
                                     '"controllers.dfcoa.compensate_tracking_offset" = true }\n'))
    names = [r.variant_name for r in sw.runs]
    assert list(dict.fromkeys(names)) == ["goto_slot", "slow", "dfcoa_comp"]
    by = {r.variant_name: r for r in sw.runs}
    assert by["slow"].controller == "goto_slot"
    assert by["slow"].overrides_dict == {"controllers.goto_slot.kp": 0.3}
    assert by["goto_slot"].overrides_dict == {}
    assert by["dfcoa_comp"].controller == "dfcoa"
    assert {r.key for r in sw.runs} == {f"example_obstacles__{v}__s{s}"
                                        for v in ("goto_slot", "slow", "dfcoa_comp")
                                        for s in (0, 1)}
    assert sw.describe()["baseline"] == "goto_slot"
    assert [v["name"] for v in sw.describe()["variants"]] == ["goto_slot", "slow", "dfcoa_comp"]


def test_variants_table_alone_runs_only_the_named_variants(tmp_path):
    sw = load_sweep(_sweep(tmp_path, 'seeds = 1\n[variants]\n'
                                     'a = { controller = "goto_slot" }\n'))
    assert [r.variant_name for r in sw.runs] == ["a"]


def test_grid_names_variants_by_the_values_that_vary_and_never_by_hash(tmp_path):
    sw = load_sweep(_sweep(tmp_path, 'controllers = ["goto_slot", "dfcoa"]\nseeds = 1\n'
                                     '[grid]\n"controllers.goto_slot.kp" = [0.5, 2.0]\n'
                                     '"controllers.dfcoa.compensate_tracking_offset" = [true]\n'))
    assert sorted(r.variant_name for r in sw.runs) == [
        "dfcoa", "goto_slot[kp=0.5]", "goto_slot[kp=2]"]
    assert not any(HEX.search(r.key) for r in sw.runs)


@pytest.mark.parametrize("body, key, fragment", [
    ('baseline = "nobody"\ncontrollers = ["goto_slot"]\n', "baseline",
     "not a variant of this sweep"),
    ('[variants]\nx = { kp = 1 }\n', "variants.x.controller", "is required"),
    ('[variants]\nx = 3\n', "variants.x", "must be a table"),
    ('[variants]\n"a b" = { controller = "goto_slot" }\n', "variants.a b", "must be non-empty"),
    ('[variants]\nx = { controller = "goto_slott" }\n', "variants.x.controller",
     "did you mean 'goto_slot'"),
    ('controllers = ["goto_slot"]\n[variants]\ngoto_slot = { controller = "dfcoa" }\n',
     "variants.goto_slot", "also a plain controller"),
    ('controllers = ["goto_slot"]\n[ladder]\nkey = "team.n"\n', "ladder",
     "needs either key and values"),
    ('controllers = ["goto_slot"]\n[ladder]\nkey = "team.n"\nvalues = [2, 2]\n', "ladder",
     "same value"),
    ('controllers = ["goto_slot"]\n[ladder]\nvalues = [2, 3]\n', "ladder.key", "is required"),
    ('controllers = ["goto_slot"]\n[[ladder]]\nkey = "team.n"\nvalues = [2]\n',
     "ladder[0].scenarios", "is required"),
    ('controllers = ["goto_slot"]\n[ladder]\nkey = "team.n"\nvalues = ["x"]\n',
     "ladder.values[0]", "must be a number"),
    ('controllers = ["goto_slot"]\nseeds = 5\nmax_seeds = 3\n', "max_seeds", ">= seeds"),
    ('controllers = ["goto_slot"]\n[ladder]\nkey = "team.n"\nvalues = [2]\n'
     'variants = ["goto_slott"]\n', "ladder[0].variants", "did you mean 'goto_slot'"),
])
def test_bad_variants_and_ladders_give_one_line_errors(tmp_path, body, key, fragment):
    path = _sweep(tmp_path, body)
    with pytest.raises(ScenarioError) as err:
        load_sweep(path)
    msg = str(err.value)
    assert msg.startswith(f"{path}: {key}"), msg
    assert fragment in msg and "\n" not in msg


def test_ladder_with_one_key_and_with_rungs(tmp_path):
    sw = load_sweep(_sweep(tmp_path, 'controllers = ["goto_slot"]\nseeds = 2\n'
                                     '[ladder]\nkey = "team.n"\nvalues = [2, 3]\n'))
    rungs = {(r.ladder, r.ladder_value, r.overrides) for r in sw.runs}
    assert rungs == {("team.n", 2.0, '{"team.n":2}'), ("team.n", 3.0, '{"team.n":3}')}
    assert "example_obstacles__goto_slot__team.n_2__s1" in {r.key for r in sw.runs}
    corridor = (ROOT / "scenarios" / "bench" / "corridor.toml").as_posix()
    path = tmp_path / "rungs.toml"
    path.write_text(f'''controllers = ["goto_slot"]
seeds = 1
[[ladder]]
label = "doorway width (m)"
scenarios = ["{corridor}"]
log_x = true
[[ladder.rungs]]
value = 3.0
"world.obstacles[0].max" = [11.5, 5.5]
"world.obstacles[1].min" = [10.0, 8.5]
[[ladder.rungs]]
value = 1.4
"world.obstacles[0].max" = [11.5, 6.3]
''')
    sw = load_sweep(path)
    assert [(r.scenario, r.ladder_value) for r in sw.runs] == [("corridor", 3.0),
                                                                ("corridor", 1.4)]
    assert sw.runs[0].overrides_dict == {"world.obstacles[0].max": [11.5, 5.5],
                                         "world.obstacles[1].min": [10.0, 8.5]}
    assert sw.describe()["ladders"] == [{"label": "doorway width (m)", "log_x": True,
                                         "values": [3.0, 1.4]}]


def test_a_ladder_that_names_its_variants_runs_only_those(tmp_path):
    corridor = (ROOT / "scenarios" / "bench" / "corridor.toml").as_posix()
    sw = load_sweep(_sweep(tmp_path, f'''controllers = ["goto_slot", "dfcoa"]
seeds = 1
[[ladder]]
label = "team"
scenarios = ["{SCEN}"]
key = "team.n"
values = [2, 3]
variants = ["dfcoa"]
[[ladder]]
label = "latency"
scenarios = ["{corridor}"]
key = "comms.latency"
values = [0.0, 0.5]
'''))
    by = {(r.ladder, r.variant_name) for r in sw.runs}
    # the sweep's own scenario (no ladder) and the second ladder run every variant
    assert by == {("", "goto_slot"), ("", "dfcoa"), ("team", "dfcoa"),
                  ("latency", "goto_slot"), ("latency", "dfcoa")}


def test_a_rung_that_breaks_the_scenario_is_a_one_line_error(tmp_path):
    path = _sweep(tmp_path, 'controllers = ["goto_slot"]\n[ladder]\nkey = "team.n"\n'
                            'values = [2, -1]\n')
    with pytest.raises(ScenarioError, match="team.n"):
        load_sweep(path)


# ----------------------------------------------------------------- sequential seeds
def test_seeds_needed_settles_extreme_cells_early_and_caps_at_the_limit():
    assert precision.seeds_needed(0, 10, 0.15, 40) == 10  # [0, 27.8 %]
    assert precision.seeds_needed(10, 10, 0.15, 40) == 10
    m = precision.seeds_needed(5, 10, 0.15, 40)  # 50 %: needs about 40
    assert 38 <= m <= 40
    assert precision.seeds_needed(5, 10, 0.05, 40) == 40  # out of reach: the cap
    assert precision.seeds_needed(5, 40, 0.05, 40) == 40  # at the cap already


def test_decide_at_settles_a_cell_whose_interval_lies_on_one_side_of_the_line():
    # 0 of 4: Wilson [0, 49.0 %] is +-24.5 points wide, yet wholly below 50 %
    assert not precision.settled(0, 4, 0.2)
    assert precision.settled(0, 4, 0.2, decide_at=0.5)
    assert precision.settled(4, 4, 0.2, decide_at=0.5)  # [51.0 %, 100 %]
    assert not precision.settled(4, 4, 0.2, decide_at=0.6)  # straddles 60 %
    assert not precision.settled(0, 3, 0.2, decide_at=0.5)  # [0, 56.2 %] straddles it
    assert not precision.settled(2, 4, 0.2, decide_at=0.5)
    assert precision.seeds_needed(0, 4, 0.2, 40, decide_at=0.5) == 4
    assert precision.seeds_needed(0, 4, 0.2, 40) == 6  # [0, 39.0 %] at 6
    # 7 of 8: [52.9 %, 97.8 %], +-22 points, wholly above 50 %
    assert precision.seeds_needed(7, 8, 0.2, 40, decide_at=0.5) == 8
    assert precision.seeds_needed(7, 8, 0.2, 40) > 8


def test_extra_runs_continue_the_seeds_of_undecided_cells_only(tmp_path):
    sw = load_sweep(_sweep(tmp_path, 'controllers = ["goto_slot", "dfcoa"]\nseeds = 10\n'
                                     'max_seeds = 40\n'))
    won = {r.key: (r.controller == "goto_slot" or r.seed % 2 == 0) for r in sw.runs}
    extra = precision.extra_runs(sw.runs, won, 0.15, 40)
    assert {r.controller for r in extra} == {"dfcoa"}  # goto_slot: 10/10, settled
    assert sorted(r.seed for r in extra) == list(range(10, 10 + len(extra)))
    assert len(extra) == precision.seeds_needed(5, 10, 0.15, 40) - 10
    # a cell with a run still missing gets nothing yet
    del won[sw.runs[-1].key]
    assert precision.extra_runs(sw.runs, won, 0.15, 40) == []
    assert sw.max_seeds == 40 and load_sweep(sw.source, seeds=2).max_seeds == 0


def test_extra_runs_with_decide_at_add_nothing_to_cells_wholly_on_one_side(tmp_path):
    sw = load_sweep(_sweep(tmp_path, 'controllers = ["goto_slot", "dfcoa"]\nseeds = 4\n'
                                     'max_seeds = 40\nmax_half_width = 0.2\ndecide_at = 0.5\n'))
    assert sw.spec.decide_at == 0.5
    won = {r.key: r.controller == "goto_slot" for r in sw.runs}  # 4 of 4 and 0 of 4
    assert len(precision.extra_runs(sw.runs, won, 0.2, 40)) == 2 * (6 - 4)
    assert precision.extra_runs(sw.runs, won, 0.2, 40, sw.spec.decide_at) == []
    with pytest.raises(ScenarioError, match="decide_at"):
        load_sweep(_sweep(tmp_path, 'controllers = ["goto_slot"]\ndecide_at = 1.0\n'))


@pytest.mark.parametrize("path", sorted((ROOT / "scenarios" / "sweeps").glob("*.toml")),
                         ids=lambda p: p.stem)
def test_every_recipe_sweep_loads_with_readable_unique_names(path):
    sw = load_sweep(path)
    assert sw.runs and len({r.key for r in sw.runs}) == len(sw.runs)
    assert not any(HEX.search(r.variant_name) for r in sw.runs)
