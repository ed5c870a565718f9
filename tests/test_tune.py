"""Tuning: declared tunables, seed splits, variants files, and dfcoa tune's reproducibility."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import pytest

from dfcoa_opt.bench.executors import ExecutorConfig
from dfcoa_opt.bench.results.store import ResultsStore
from dfcoa_opt.bench.runner import is_success
from dfcoa_opt.bench.sweep import load_sweep, sweep_from_dict
from dfcoa_opt.bench.tune import (
    Trial,
    choose,
    objective,
    tune_variant,
    tuning_sweep,
    validation_runs,
)
from dfcoa_opt.cli import main
from dfcoa_opt.control.registry import available, check_overrides, controller_tunables
from dfcoa_opt.core.errors import DfcoaError, ScenarioError
from dfcoa_opt.scenario.loader import apply_overrides, read_toml, scenario_from_dict

HELDOUT = Path(__file__).resolve().parents[1] / "scenarios" / "heldout"


# ------------------------------------------------------------------ tunables
@pytest.mark.parametrize("cid", [*available(), "goto_slot+cbf"])
def test_every_method_declares_two_to_six_valid_tunables(cid: str) -> None:
    params = controller_tunables(cid)
    assert 2 <= len(params) <= 6
    for t in params:
        assert t.low <= t.default <= t.high, t
        for value in (t.low, t.high):  # both ends are valid parameter values
            data = apply_overrides({"controllers": {}}, {t.key: value})
            check_overrides(data["controllers"], "x")
        if t.scale == "log":
            assert t.low > 0


# ------------------------------------------------------------------ splits
def _heldout(name: str = "cellular") -> dict:
    data = read_toml(HELDOUT / f"{name}.toml")
    data["name"] = name
    return data


@pytest.mark.parametrize(("splits", "match"), [
    ({"train": [0, 99], "test": [50, 150]}, r"splits\.test: \[50, 150\] overlaps splits\.train "
                                            r"\[0, 99\]"),
    ({"train": [0, 99], "validation": [99, 99]}, r"splits\.validation: \[99, 99\] overlaps"),
    ({"test": [10, 5]}, r"splits\.test: \[10, 5\]: the first seed must not exceed the last"),
])
def test_overlapping_seed_ranges_are_refused(splits: dict, match: str) -> None:
    with pytest.raises(ScenarioError, match=match) as e:
        scenario_from_dict({**_heldout(), "splits": splits}, "f.toml", HELDOUT)
    assert "\n" not in str(e.value)


def _sweep(**keys) -> dict:
    return {"scenarios": [str(HELDOUT / "crowd.toml")], "controllers": ["goto_slot"],
            "seeds": 2, **keys}


def test_a_sweep_keeps_to_its_split() -> None:
    ok = sweep_from_dict(_sweep(split="test", first_seed=20000))
    assert {r.seed for r in ok.runs} == {20000, 20001}
    with pytest.raises(ScenarioError, match=r"split: 'test': seed 0 of scenario crowd is a "
                                            r"'train' seed, outside its test seeds "
                                            r"\[20000, 29999\]"):
        sweep_from_dict(_sweep(split="test"))
    with pytest.raises(ScenarioError, match=r"seed 30000 of scenario crowd is in no split"):
        sweep_from_dict(_sweep(split="test", first_seed=29999))
    with pytest.raises(ScenarioError, match=r"scenario example_empty .* declares no \[splits\] "
                                            r"train seed range"):
        sweep_from_dict({"scenarios": [str(HELDOUT.parent / "example_empty.toml")],
                         "controllers": ["goto_slot"], "seeds": 1, "split": "train"})
    # seeds 29996-29997 are test seeds, but max_seeds may add up to 30001
    sweep_from_dict(_sweep(split="test", first_seed=29996, seeds=2))
    with pytest.raises(ScenarioError, match=r"seed 30000 of scenario crowd is in no split"):
        sweep_from_dict(_sweep(split="test", first_seed=29996, seeds=2, max_seeds=6))


def test_dfcoa_tune_tunes_on_training_seeds_only(tmp_path: Path) -> None:
    sweep = tmp_path / "t.toml"
    body = {"scenarios": [str(HELDOUT / "crowd.toml")], "controllers": ["goto_slot"],
            "seeds": 2, "tune": {"trials": 2}}
    for split, first, match in (("test", 20000, r"split: dfcoa tune tunes on training seeds "
                                                r"only: set split = \"train\" \(got 'test'\)"),
                                ("train", 20000, r"seed 20000 of scenario crowd is a 'test' "
                                                 r"seed")):
        sweep.write_text(_toml({**body, "split": split, "first_seed": first}))
        with pytest.raises(ScenarioError, match=match):
            tuning_sweep(sweep)
    assert main(["tune", str(sweep), "--variant", "goto_slot", "--out",
                 str(tmp_path / "r")]) == 2


# ------------------------------------------------------------------ variants files
def _toml(data: dict) -> str:
    lines, tables = [], []
    for k, v in data.items():
        if isinstance(v, dict):
            tables.append((k, v))
        else:
            lines.append(f"{k} = {json.dumps(v)}")
    for name, table in tables:
        lines.append(f"[{name}]")
        lines += [f"{json.dumps(k)} = {json.dumps(v)}" for k, v in table.items()]
    return "\n".join(lines) + "\n"


def test_variant_files_and_variant_seeds(tmp_path: Path) -> None:
    (tmp_path / "tuned").mkdir()
    (tmp_path / "tuned" / "g.toml").write_text(
        '[tuned]\nvariant = "goto_slot"\n[variants."goto_slot@tuned"]\ncontroller = "goto_slot"\n'
        '"controllers.goto_slot.kp" = 0.5\n')
    sw = sweep_from_dict(_sweep(split="test", first_seed=20000, seeds=1,
                                variant_files=["tuned/*.toml"],
                                variant_seeds={"*@tuned": 3}), tmp_path)
    tuned = [r for r in sw.runs if r.variant_name == "goto_slot@tuned"]
    assert [r.seed for r in tuned] == [20000, 20001, 20002]
    assert tuned[0].overrides_dict["controllers.goto_slot.kp"] == 0.5
    assert [r.seed for r in sw.runs if r.variant_name == "goto_slot"] == [20000]
    with pytest.raises(ScenarioError, match=r"variant_seeds\.\*@tunde: names no variant"):
        sweep_from_dict(_sweep(variant_seeds={"*@tunde": 3}), tmp_path)
    (tmp_path / "tuned" / "bad.toml").write_text('[tuned]\nvariant = "x"\n')
    with pytest.raises(ScenarioError, match=r"bad\.toml: variants: is required"):
        sweep_from_dict(_sweep(variant_files=["tuned/*.toml"]), tmp_path)


# ------------------------------------------------------------------ dfcoa tune
def _mini(tmp_path: Path, trials: int) -> Path:
    scen = copy.deepcopy(_heldout("cellular"))
    scen["t_max"] = 4.0
    (tmp_path / "mini.toml").write_text(_scenario_toml(scen))
    sweep = tmp_path / "tune.toml"
    sweep.write_text(_toml({"name": "mini", "scenarios": ["mini.toml"], "split": "train",
                            "seeds": 2, "controllers": ["goto_slot+cbf"],
                            "tune": {"trials": trials, "startup_trials": 2, "sampler_seed": 3,
                                     "out": "tuned"},
                            "grid": {"controllers.cbf.solver": ["exact"]}}))
    return sweep


def _scenario_toml(data: dict, prefix: str = "") -> str:
    scalars = {k: v for k, v in data.items() if not isinstance(v, dict)}
    out = [f"{k} = {json.dumps(v)}" for k, v in scalars.items()]
    for k, v in data.items():
        if isinstance(v, dict):
            out += [f"[{prefix}{k}]", _scenario_toml(v, f"{prefix}{k}.")]
    return "\n".join(out) + "\n"


def test_tune_is_reproducible_and_resumes(tmp_path: Path) -> None:
    serial = ExecutorConfig("serial")
    sweep, spec = tuning_sweep(_mini(tmp_path, 4))
    one = tune_variant(sweep, spec, "goto_slot+cbf", tmp_path / "a", serial, tmp_path / "oa")
    # the same seed, fresh: the same trials and the same file
    two = tune_variant(sweep, spec, "goto_slot+cbf", tmp_path / "b", serial, tmp_path / "ob")
    assert [t.params for t in one.trials] == [t.params for t in two.trials]
    assert one.path.read_text() == two.path.read_text()
    # killed after two trials, resumed: what the uninterrupted run proposed
    sweep2, spec2 = tuning_sweep(tmp_path / "tune.toml", trials=2)
    part = tune_variant(sweep2, spec2, "goto_slot+cbf", tmp_path / "c", serial, tmp_path / "oc")
    assert len(part.trials) == 2 and part.ran == 4
    rest = tune_variant(sweep, spec, "goto_slot+cbf", tmp_path / "c", serial, tmp_path / "oc")
    assert rest.ran == 4  # only trials 2 and 3 ran
    assert [t.params for t in rest.trials] == [t.params for t in one.trials]
    assert rest.path.read_text() == one.path.read_text()
    # trial 0 is the defaults; the file names the best trial's parameters
    assert one.trials[0].params == {"controllers.goto_slot.kp": 1.0,
                                    "controllers.goto_slot.feedforward": True,
                                    "controllers.cbf.gamma": 2.0, "controllers.cbf.margin": 0.05,
                                    "controllers.cbf.obstacle_range": 3.0}
    text = read_toml(one.path)
    best = max(one.trials, key=lambda t: (t.value, -t.number))
    assert text["tuned"]["best_trial"] == best.number
    assert text["variants"]["goto_slot+cbf@tuned"] == {"controller": "goto_slot+cbf",
                                                       **best.params}
    assert len({json.dumps(t.params, sort_keys=True) for t in one.trials}) == 4


def test_the_best_training_trials_are_chosen_again_on_validation_seeds(tmp_path: Path) -> None:
    sweep_path = _mini(tmp_path, 4)
    body = read_toml(sweep_path)
    body["tune"]["validation_trials"] = 2
    sweep_path.write_text(_toml(body))
    sweep, spec = tuning_sweep(sweep_path)
    res = tune_variant(sweep, spec, "goto_slot+cbf", tmp_path / "a", ExecutorConfig("serial"),
                       tmp_path / "o")
    # the budget: 2 training trials and 2 finalists, each 2 runs
    assert len(res.trials) == 2 and len(res.validated) == 2 and res.ran == 8
    assert sorted(t.number for t in res.validated) == [0, 1]
    # the defaults are a finalist; on 2 worlds no lead is significant, so they stay
    assert res.validated[0].number == 0 and res.best.number == 0
    chosen = res.validated[0]
    assert res.best.params == chosen.params
    text = read_toml(res.path)
    assert text["tuned"]["validation_trials"] == 2
    assert text["tuned"]["validation_seeds"] == "10000-10001"  # cellular's validation range
    assert text["tuned"]["validation_success"] == chosen.successes
    assert text["tuned"]["best_trial"] == chosen.number
    # the validation rows are the finalists' parameters on validation seeds
    runs = validation_runs([r for r in sweep.runs if r.variant_name == "goto_slot+cbf"],
                           "goto_slot+cbf", chosen)
    assert [r.seed for r in runs] == [10000, 10001]
    rows = [ResultsStore(tmp_path / "a" / "goto_slot+cbf").read_row(r.key) for r in runs]
    assert sum(is_success(r) for r in rows) == chosen.successes
    assert objective(rows)[0] == chosen.value
    # resumed: nothing is simulated again, and the same file is written
    again = tune_variant(sweep, spec, "goto_slot+cbf", tmp_path / "a", ExecutorConfig("serial"),
                         tmp_path / "o2")
    assert again.ran == 0 and again.path.read_text() == res.path.read_text()
    body["tune"]["validation_trials"] = 4
    sweep_path.write_text(_toml(body))
    with pytest.raises(ScenarioError, match=r"tune\.validation_trials: 4 finalists x 1 leave "
                                            r"no training trial of the 4 trials"):
        tuning_sweep(sweep_path)
    body["tune"]["validation_trials"], body["tune"]["validation_repeat"] = 2, 2
    sweep_path.write_text(_toml(body))
    with pytest.raises(ScenarioError, match=r"tune\.validation_repeat: 2 finalists x 2 leave "):
        tuning_sweep(sweep_path)
    body["tune"]["validation_trials"], body["tune"]["validation_repeat"] = 1, 1
    sweep_path.write_text(_toml(body))
    with pytest.raises(ScenarioError, match=r"tune\.validation_trials: 1 finalist is the "
                                            r"defaults alone"):
        tuning_sweep(sweep_path)


def _finalist(number: int, wins: list[bool]) -> Trial:
    rows = [{"status": "ok", "metrics": {"outcome": "success" if w else "deadlock",
                                         "fce_rms": 0.1}} for w in wins]
    return Trial(number, {}, objective(rows)[0], sum(wins), len(wins), 0.1)


def test_a_finalist_replaces_the_defaults_only_with_a_significant_lead() -> None:
    defaults = [True] * 45 + [False] * 5
    lucky = [True] * 50  # 5 more worlds, none lost: one-sided p = 2^-5 = 0.031
    narrow = [True] * 48 + [False] * 2  # 3 more worlds: p = 1/8
    worse = [False] * 10 + [True] * 40
    train = {0: 0.9, 1: 0.98, 2: 0.98, 3: 1.0}
    for f, expect in ((lucky, 1), (narrow, 0)):
        out = {0: defaults, 1: f, 3: worse}
        val = [_finalist(0, defaults), _finalist(1, f), _finalist(3, worse)]
        number, best, test = choose(val, out, train, 0.05)
        assert number == expect and best == 1 and test is not None and test.b01 == 0
    number, _, test = choose(val, out, train, 0.2)  # at alpha 0.2, p = 1/8 replaces them
    assert number == 1
    # the defaults best on validation: no test
    assert choose([_finalist(0, lucky), _finalist(3, worse)], {0: lucky, 3: worse}, train,
                  0.05) == (0, 0, None)
    # a lead of won minus lost worlds, not of totals on other worlds
    swapped = [False] * 5 + [True] * 45
    number, _, test = choose([_finalist(0, defaults), _finalist(2, [True] * 50)],
                             {0: swapped, 2: [True] * 50}, train, 0.05)
    assert number == 2 and test is not None and (test.b10, test.b01) == (5, 0)


def test_validation_repeat_scores_a_finalist_on_more_worlds_within_the_budget(
        tmp_path: Path) -> None:
    sweep_path = _mini(tmp_path, 4)
    body = read_toml(sweep_path)
    body["tune"]["trials"] = 6
    body["tune"]["validation_trials"], body["tune"]["validation_repeat"] = 2, 2
    sweep_path.write_text(_toml(body))
    sweep, spec = tuning_sweep(sweep_path)
    res = tune_variant(sweep, spec, "goto_slot+cbf", tmp_path / "a", ExecutorConfig("serial"),
                       tmp_path / "o")
    # the budget stays 6 trials x 2 runs: 2 training trials, 2 finalists on 4 validation worlds
    assert len(res.trials) == 2 and len(res.validated) == 2 and res.ran == 12
    chosen = res.validated[0]
    assert [t.runs for t in res.validated] == [4, 4] and res.best.number == chosen.number == 0
    base = [r for r in sweep.runs if r.variant_name == "goto_slot+cbf"]
    runs = validation_runs(base, "goto_slot+cbf", chosen, 2)
    # the first repeat is the seeds repeat = 1 gives; then the next ones, none twice
    assert [r.seed for r in runs] == [10000, 10001, 10002, 10003]
    assert [r.seed for r in validation_runs(base, "goto_slot+cbf", chosen)] == [10000, 10001]
    assert read_toml(res.path)["tuned"]["validation_seeds"] == "10000-10003"


def test_tune_names_an_unknown_variant(tmp_path: Path) -> None:
    sweep, spec = tuning_sweep(_mini(tmp_path, 1))
    with pytest.raises(DfcoaError, match=r"--variant: 'goto_slot\+cfb' is not a variant of "
                                         r"this sweep \(did you mean 'goto_slot\+cbf'\?\)"):
        tune_variant(sweep, spec, "goto_slot+cfb", tmp_path / "r")


def test_objective_orders_successes_before_the_tie_breaker() -> None:
    def row(ok: bool, fce: float) -> dict:
        return {"status": "ok", "metrics": {"outcome": "success" if ok else "collision",
                                            "fce_rms": fce}}
    more = objective([row(True, 9.0), row(True, 9.0), row(False, 9.0)])
    fewer = objective([row(True, 0.0), row(False, 0.0), row(False, 0.0)])
    assert more[1] == 2 and fewer[1] == 1 and more[0] > fewer[0]
    calm = objective([row(True, 0.1), row(False, 0.2)])
    rough = objective([row(True, 0.1), row(False, 0.8)])
    assert calm[0] > rough[0] and calm[2] == pytest.approx(0.2)
    assert objective([row(True, 0.0)])[0] == 1.0


def test_the_committed_tuning_sweep_loads() -> None:
    sweep, spec = tuning_sweep(HELDOUT.parent / "sweeps" / "tune.toml")
    assert sweep.spec.split == "train" and spec.trials >= 1
    assert len({r.scenario for r in sweep.runs}) == 5
    assert load_sweep(HELDOUT.parent / "sweeps" / "tune.toml").sha256 == sweep.sha256


def test_kept_workers_serve_every_sweep_of_the_block(tmp_path: Path) -> None:
    from dfcoa_opt.bench.executors import kept_workers
    from dfcoa_opt.bench.harness import run_sweep

    cfg = ExecutorConfig("process", 2)

    def pids(name: str) -> set[int]:
        sw = sweep_from_dict({"scenarios": [str(HELDOUT.parent / "example_empty.toml")],
                              "controllers": ["goto_slot"], "seeds": 4},
                             overrides={"t_max": 1.0})
        res = run_sweep(sw, tmp_path / name, cfg, progress=False)
        return {r["provenance"]["pid"] for r in res.store.rows()}

    with kept_workers(cfg):
        first, second = pids("a"), pids("b")
    assert len(first | second) <= 2  # the same two worker processes
    assert not pids("c") & (first | second)  # outside the block, a pool of its own
