"""A failed sweep changes nothing; long names get short file names; huge sweeps fail at once.

Each failing ``dfcoa bench`` below runs into a results folder that a first,
successful bench has filled, and must leave every file of it byte-identical.
"""

from __future__ import annotations

import functools
import hashlib
import json
import re
import signal
import time
from pathlib import Path

import pytest

from dfcoa_opt.bench import harness
from dfcoa_opt.bench.executors import ExecutorConfig
from dfcoa_opt.bench.lifecycle import SweepInterrupted
from dfcoa_opt.bench.results.store import ResultsStore
from dfcoa_opt.bench.sweep import (
    KEY_MAX,
    MAX_RUNS,
    MAX_SEEDS,
    NAME_MAX,
    RunSpec,
    load_sweep,
    safe_name,
    shorten,
)
from dfcoa_opt.bench.sweep import expand as sweep_mod
from dfcoa_opt.cli import main
from dfcoa_opt.core.errors import ScenarioError
from dfcoa_opt.scenario.loader import load_scenario

ROOT = Path(__file__).resolve().parents[1]
TINY = Path(__file__).parent / "data" / "bench" / "tiny.toml"
BAD_SCENARIO = Path(__file__).parent / "data" / "bad_scenarios" / "circle_missing_radius.toml"
HEAD = f'name = "atomic"\nscenarios = ["{TINY.as_posix()}"]\n'
OK = HEAD + 'controllers = ["goto_slot"]\nseeds = 1\n'


def _snapshot(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder``: relative path -> bytes."""
    return {p.relative_to(folder).as_posix(): p.read_bytes()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def _bench(sweep: Path, out: Path, *extra: str) -> int:
    return main(["bench", str(sweep), "--out", str(out), "--executor", "serial",
                 "--no-progress", *extra])


@pytest.fixture
def filled(tmp_path: Path) -> Path:
    """A results folder after one successful bench (1 run)."""
    ok = tmp_path / "ok.toml"
    ok.write_text(OK)
    out = tmp_path / "out"
    assert _bench(ok, out) == 0
    assert (out / "manifest.json").is_file() and (out / "results.csv").is_file()
    return out


# sweep text, extra CLI arguments, fragments of the one error line
FAILURES = {
    "ladder_value_inf": (
        OK + f'[[ladder]]\nscenarios = ["{TINY.as_posix()}"]\nkey = "sensors.comm_radius"\n'
             "values = [5.0, 8.0, inf]\n", (),
        ["ladder[0].values[2]", "must be a finite number, got inf"]),
    "ladder_log_x_not_a_boolean": (
        OK + '[ladder]\nkey = "sensors.comm_radius"\nvalues = [5.0, 8.0]\nlog_x = "no"\n', (),
        ["ladder.log_x", "must be true or false, got 'no'"]),
    "ladder_value_nan": (
        OK + '[ladder]\nkey = "sensors.comm_radius"\nvalues = [5.0, nan]\n', (),
        ["ladder.values[1]", "must be a finite number, got nan"]),
    "ladder_rung_value_inf": (
        OK + '[ladder]\nlabel = "reach"\n[[ladder.rungs]]\nvalue = inf\n'
             '"sensors.comm_radius" = 5.0\n', (),
        ["ladder.rungs[0].value", "finite"]),
    "ladder_rung_override_inf": (
        OK + '[ladder]\nlabel = "reach"\n[[ladder.rungs]]\nvalue = 1.0\n'
             '"sensors.comm_radius" = inf\n', (),
        ["ladder.rungs[0].sensors.comm_radius", "must be finite, got inf"]),
    "variant_override_inf": (
        HEAD + 'seeds = 1\n[variants.far]\ncontroller = "goto_slot"\n'
               '"sensors.comm_radius" = inf\n', (),
        ["variants.far.sensors.comm_radius", "must be finite, got inf"]),
    "grid_value_date": (
        OK + '[grid]\nt_max = [1979-05-27]\n', (), ["grid.t_max[0]", "date"]),
    "set_override_inf": (OK, ("--set", "sensors.comm_radius=inf"),
                         ["--set: sensors.comm_radius: must be finite"]),
    "seeds_huge": (
        HEAD + 'controllers = ["goto_slot"]\nseeds = 100000000\n', (),
        ["seeds: must be <= 100000"]),
    "runs_over_the_bound": (
        HEAD + f'controllers = ["goto_slot"]\nseeds = {MAX_SEEDS}\n[grid]\n'
               '"controllers.goto_slot.kp" = [0.5, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10]\n', (),
        ["1,100,000 runs", f"more than the {MAX_RUNS:,}"]),
    "max_seeds_over_the_bound": (
        HEAD + 'controllers = ["goto_slot"]\nseeds = 10\nmax_seeds = 100000\n[grid]\n'
               '"controllers.goto_slot.kp" = [0.5, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10]\n', (),
        ["1,100,000 runs", "max_seeds"]),
    "scenario_fails_to_load": (
        f'name = "atomic"\nscenarios = ["{BAD_SCENARIO.as_posix()}"]\n'
        'controllers = ["goto_slot"]\nseeds = 1\n', (),
        [str(BAD_SCENARIO), "radius"]),
    "unknown_controller": (
        HEAD + 'controllers = ["goto_slott"]\nseeds = 1\n', (),
        ["controllers[0]: unknown controller 'goto_slott'"]),
    # a ladder's scenarios: an array of strings, as the sweep's own
    "ladder_scenarios_a_number": (
        OK + '[[ladder]]\nscenarios = 3.0\nkey = "sensors.comm_radius"\nvalues = [5.0]\n', (),
        ["ladder[0].scenarios: must be an array, got float 3.0"]),
    "ladder_scenarios_false": (
        OK + '[ladder]\nkey = "sensors.comm_radius"\nvalues = [5.0]\nscenarios = false\n', (),
        ["ladder.scenarios: must be an array, got bool False"]),
    "ladder_scenarios_entry_a_number": (
        OK + '[[ladder]]\nscenarios = [1]\nkey = "sensors.comm_radius"\nvalues = [5.0]\n', (),
        ["ladder[0].scenarios[0]: must be a string, got int 1"]),
    # a table inside an array: refused by the scenario where its key takes no such value,
    # in a ladder rung as in a grid or a variant
    "ladder_rung_table_in_array": (
        OK + '[ladder]\nlabel = "lag"\n[[ladder.rungs]]\nvalue = 1.0\n'
             '"comms.latency" = [{}]\n', (),
        ["comms.latency: must be a number, got list [{}]"]),
    "grid_table_in_array": (
        OK + '[grid]\n"comms.latency" = [[{}]]\n', (),
        ["comms.latency: must be a number, got list [{}]"]),
    "variant_table_in_array": (
        HEAD + 'seeds = 1\n[variants.lagging]\ncontroller = "goto_slot"\n'
               '"comms.latency" = [{}]\n', (),
        ["comms.latency: must be a number, got list [{}]"]),
    # a sweep of no run at all
    "no_controller": (
        HEAD + "controllers = []\nseeds = 1\n", (),
        ["controllers: lists no controller (and the sweep names no variant)"]),
    "no_controller_with_override_sets": (
        HEAD + 'controllers = []\nseeds = 1\n[[variants]]\n"sensors.comm_radius" = 5.0\n', (),
        ["controllers: lists no controller"]),
    "no_scenario": (
        'scenarios = []\ncontrollers = ["goto_slot"]\nseeds = 1\n', (),
        ["scenarios: lists no scenario"]),
    # plugins and variant files that cannot be loaded: the sweep file, the key, the problem
    "plugin_module_missing": (
        OK + 'plugins = ["no_such_module_for_dfcoa"]\n', (),
        ["plugins[0]: no_such_module_for_dfcoa: no such module or .py file"]),
    "plugin_file_missing": (
        OK + 'plugins = ["gone.py"]\n', (),
        ["plugins[0]: ", "gone.py: plugin file not found"]),
    "variant_file_not_toml": (
        OK + 'variant_files = ["broken.toml"]\n', (),
        ["variant_files[0]: ", "broken.toml: not valid TOML"]),
    "variant_file_a_folder": (
        OK + 'variant_files = ["tuned/*"]\n', (),
        ["variant_files[0]: ", "folder.toml: is a directory"]),
    "variant_file_without_variants": (
        OK + 'variant_files = ["tuned.toml", "novariants.toml"]\n', (),
        ["variant_files[1]: ", "novariants.toml: variants: is required"]),
}

#: Files beside the sweep of a FAILURES case (a folder for None).
BESIDE = {
    "variant_file_not_toml": {"broken.toml": "[variants.x\ncontroller = 1\n"},
    "variant_file_a_folder": {"tuned/": None, "tuned/folder.toml/": None},
    "variant_file_without_variants": {
        "tuned.toml": '[variants.tuned]\ncontroller = "goto_slot"\n',
        "novariants.toml": '[tuned]\nvariant = "goto_slot"\n'},
}


@pytest.mark.parametrize("case", list(FAILURES))
def test_a_failed_bench_leaves_the_results_folder_byte_identical(case, filled, tmp_path,
                                                                 capsys):
    """Exit 2, one stderr line naming the sweep file (or the option) and the key; no file
    of the folder written, touched or added; the bounds refuse in well under a second."""
    text, extra, fragments = FAILURES[case]
    for name, body in BESIDE.get(case, {}).items():
        if body is None:
            (tmp_path / name).mkdir()
        else:
            (tmp_path / name).write_text(body)
    sweep = tmp_path / f"{case}.toml"
    sweep.write_text(text)
    before = _snapshot(filled)
    capsys.readouterr()
    t0 = time.perf_counter()
    assert _bench(sweep, filled, *extra) == 2
    elapsed = time.perf_counter() - t0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert all(f in err[0] for f in fragments), err[0]
    if not case.startswith("set_"):
        assert str(sweep) in err[0], err[0]
    assert _snapshot(filled) == before
    if case in ("seeds_huge", "runs_over_the_bound", "max_seeds_over_the_bound"):
        assert elapsed < 1.0, f"{case}: refused after {elapsed:.2f} s"


def test_a_300_character_label_runs_with_a_short_stable_file_name(filled, tmp_path, capsys):
    """A long ladder label is legitimate: the run's key (its file names) is shortened with a
    hash, the label itself is kept whole, and the same sweep resumes under the same key."""
    label = "x" * 300
    sweep = tmp_path / "label.toml"
    sweep.write_text(OK + f'[ladder]\nlabel = "{label}"\nkey = "leader.speed"\n'
                          "values = [0.4]\n")
    assert _bench(sweep, filled) == 0
    rows = sorted(p.name for p in (filled / "rows").glob("*.json"))
    assert len(rows) == 2 and "tiny__goto_slot__s0.json" in rows
    new = next(r for r in rows if r != "tiny__goto_slot__s0.json")
    key = new.removesuffix(".json")
    assert len(key) <= KEY_MAX and re.fullmatch(r"tiny__goto_slot__x+-[0-9a-f]{8}_0\.4__s0", key)
    assert (filled / "logs" / f"{key}.npz").is_file()
    manifest = json.loads((filled / "manifest.json").read_text())
    assert manifest["keys"] == [key] and manifest["ladders"][0]["label"] == label
    row = json.loads((filled / "rows" / new).read_text())
    assert row["ladder"] == label and row["status"] == "ok"
    capsys.readouterr()
    assert _bench(sweep, filled) == 0  # the same name again: nothing to run
    assert "ran 0 (0 failed), 1 already done" in capsys.readouterr().out


def test_a_250_character_scenario_name_runs(tmp_path):
    scen = tmp_path / "long.toml"
    scen.write_text(f'name = "{"s" * 250}"\n' + TINY.read_text())
    sweep = tmp_path / "sweep.toml"
    sweep.write_text(f'scenarios = ["{scen.as_posix()}"]\ncontrollers = ["goto_slot"]\n'
                     "seeds = 2\n")
    res = harness.run_sweep(sweep, tmp_path / "out", ExecutorConfig("serial"), progress=False)
    assert res.ran == 2 and res.failed == 0
    keys = [r.key for r in res.sweep.runs]
    assert len(set(keys)) == 2 and all(len(k) <= KEY_MAX for k in keys)
    assert keys[0].removesuffix("__s0") == keys[1].removesuffix("__s1")  # one prefix per cell


def test_a_failure_before_the_first_run_finishes_writes_no_manifest_or_csv(filled, tmp_path,
                                                                          monkeypatch):
    """Validated, but storing the first run fails (disk full, say): the folder is unchanged;
    the manifest, the sweep file's copy and results.csv follow finished runs only."""
    sweep = tmp_path / "more.toml"
    sweep.write_text(OK.replace("seeds = 1", "seeds = 2"))
    before = _snapshot(filled)

    def full(self, outcome):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(ResultsStore, "write", full)
    with pytest.raises(OSError, match="No space"):
        harness.run_sweep(sweep, filled, ExecutorConfig("serial"), progress=False)
    assert _snapshot(filled) == before


def test_ctrl_c_just_after_the_first_row_is_stored_still_lists_it(tmp_path, monkeypatch):
    """SIGINT that lands between storing a row and writing the manifest (a race the
    subprocess signal tests hit now and then): the row, the manifest that lists it and
    results.csv are all written, and the sweep stops with SweepInterrupted."""
    sweep = tmp_path / "two.toml"
    sweep.write_text(OK.replace("seeds = 1", "seeds = 2"))
    out = tmp_path / "out"
    stored = ResultsStore.write

    def write_then_ctrl_c(self, outcome):
        path = stored(self, outcome)
        signal.raise_signal(signal.SIGINT)
        return path

    monkeypatch.setattr(ResultsStore, "write", write_then_ctrl_c)
    with pytest.raises(SweepInterrupted) as info:
        harness.run_sweep(sweep, out, ExecutorConfig("serial"), progress=False)
    assert (info.value.saved, info.value.total) == (1, 2)
    keys = json.loads((out / "manifest.json").read_text())["keys"]
    assert len(keys) == 2 and len(list((out / "rows").glob("*.json"))) == 1
    assert len((out / "results.csv").read_text().splitlines()) == 2  # header and the row


def test_a_row_that_is_not_json_writes_neither_row_nor_log(tmp_path):
    """``ResultsStore.write`` makes the row's text before it writes the log."""
    from dfcoa_opt.bench.runner import Outcome

    store = ResultsStore(tmp_path / "out")
    before = _snapshot(store.root)
    row = {"key": "k", "controller": "goto_slot", "scenario_file": str(TINY),
           "log": "logs/k.npz", "metrics": {"x": float("inf")}}
    with pytest.raises(ValueError):
        store.write(Outcome(row, b"npz bytes"))
    assert _snapshot(store.root) == before


# -- names -------------------------------------------------------------------------------------

def test_short_names_pass_through_and_long_ones_are_short_stable_and_distinct():
    for name in ("tiny", "goto_slot[kp=0.5,n=2]", "a" * NAME_MAX, "clutter density (1/m^2)"):
        assert safe_name(name) == re.sub(r"[^A-Za-z0-9_.+-]+", "_", name).strip("_")
    assert len(safe_name("a" * NAME_MAX)) == NAME_MAX
    long_a, long_b = "a" * 300, "a" * 299 + "b"
    for name in (long_a, long_b, "aé" * 200, "x y" * 200):
        short = safe_name(name)
        assert len(short) == NAME_MAX and safe_name(name) == short
        assert re.fullmatch(r"[A-Za-z0-9_.+-]+-[0-9a-f]{8}", short)
        digest = hashlib.sha256(name.encode()).hexdigest()[:8]
        assert short.endswith("-" + digest)
    assert safe_name(long_a) != safe_name(long_b)
    assert shorten("abc", 3) == "abc" and len(shorten("abcd" * 10, 20)) == 20
    run = RunSpec(str(TINY), "s" * 250, "goto_slot", 12, variant="v" * 250, ladder="l" * 250,
                  ladder_value=0.5)
    assert len(run.key) <= KEY_MAX and run.key.endswith("__s12")
    assert RunSpec(str(TINY), "tiny", "goto_slot", 3).key == "tiny__goto_slot__s3"


#: Every shipped sweep: (runs, first 16 hex digits of the SHA-256 of its run keys, in order),
#: computed before run keys could be shortened. Update on purpose when a sweep file changes
#: or a controller is registered (the sweeps of every controller, "*", gain its runs).
SHIPPED_KEYS = {
    "beyond.toml": (105, "51d84c6e0cdcfa78"),
    "comms_s1.toml": (2250, "fe24d1ac960fe0a4"),
    "comparison.toml": (2100, "41cab901d9df8473"),
    "dfcoa_paper.toml": (120, "a4de7b96832d7513"),
    "examples.toml": (26, "b61a413df6add34e"),
    "heldout.toml": (2100, "b85df9c4bbf1384e"),
    "ladders.toml": (2640, "386e9ca5915c23b0"),
    "paper001_consensus.toml": (10, "24f5aa3f9a7898cd"),
    "paper001_ivo.toml": (3, "a79afc7537e4cf67"),
    "paper002.toml": (15, "f925567500844ea4"),
    "paper004.toml": (160, "49423eb492ebffc1"),
    "paper004_baseline.toml": (40, "6acf963ea88e2207"),
    "reshape.toml": (4, "ec79703ad6634dc0"),
    "tune.toml": (375, "dc70f77ee8f39b22"),
}


def test_every_shipped_sweep_keeps_its_run_keys(monkeypatch):
    """Results folders and the paper figures name runs by key: none of them changes.

    Each scenario file is loaded once (its name is all a key needs), not once per
    override set, to keep the test fast.
    """
    @functools.cache
    def scenario(path: str, seed: int):
        return load_scenario(path, seed)

    monkeypatch.setattr(sweep_mod, "load_run_scenario",
                        lambda run: scenario(run.scenario_file, run.seed))
    files = sorted((ROOT / "scenarios" / "sweeps").glob("*.toml"))
    assert {f.name for f in files} == set(SHIPPED_KEYS)
    for f in files:
        keys = [r.key for r in load_sweep(f).runs]
        digest = hashlib.sha256("\n".join(keys).encode()).hexdigest()[:16]
        assert (len(keys), digest) == SHIPPED_KEYS[f.name], f.name
        assert max(map(len, keys)) < NAME_MAX  # short names: passed through unchanged


def test_seed_counts_are_bounded_in_every_form(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text(OK + '[variant_seeds]\n"goto*" = 100001\n')
    with pytest.raises(ScenarioError, match=r"variant_seeds.*100000"):
        load_sweep(path)
    path.write_text(OK)
    with pytest.raises(ScenarioError, match="between 1 and 100,000"):
        load_sweep(path, seeds=MAX_SEEDS + 1)
