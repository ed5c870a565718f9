"""Sweep inputs that once escaped as tracebacks or ran nothing; the split of the sweep module.

The one-line messages of a failing ``dfcoa bench`` (and its unchanged results
folder) are checked in ``tests/test_sweep_atomic.py`` (FAILURES); these tests
check what a table of messages cannot: a value that is valid after all, a read
error that needs a patched file system, the dict form, and the module layout.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from dfcoa_opt.bench.sweep import expand as sweep_mod
from dfcoa_opt.bench.sweep import load_sweep, sweep_from_dict
from dfcoa_opt.core.errors import ScenarioError

TINY = Path(__file__).parent / "data" / "bench" / "tiny.toml"
HEAD = f'scenarios = ["{TINY.as_posix()}"]\ncontrollers = ["goto_slot"]\nseeds = 1\n'
MOVED = '[{type = "circle", center = [6.0, 1.0], radius = 0.4}]'


def test_a_rung_may_set_an_array_of_tables(tmp_path: Path) -> None:
    """``"world.obstacles" = [{...}]`` is a valid override (it replaces the obstacles), in a
    ladder rung as in a grid or a variant; the ladder holding it is hashable."""
    path = tmp_path / "s.toml"
    path.write_text(HEAD + f'[ladder]\nlabel = "layout"\n[[ladder.rungs]]\nvalue = 1.0\n'
                           f'"world.obstacles" = {MOVED}\n'
                           '[[ladder.rungs]]\nvalue = 2.0\n"world.obstacles" = []\n')
    sweep = load_sweep(path)
    assert [r.key for r in sweep.runs] == ["tiny__goto_slot__layout_1__s0",
                                           "tiny__goto_slot__layout_2__s0"]
    assert sweep.runs[0].overrides_dict == {
        "world.obstacles": [{"type": "circle", "center": [6.0, 1.0], "radius": 0.4}]}
    assert sweep.runs[1].overrides_dict == {"world.obstacles": []}
    (ladder,) = sweep.ladders
    assert hash(ladder) == hash(load_sweep(path).ladders[0])
    assert {ladder: 1}[load_sweep(path).ladders[0]] == 1

    path.write_text(HEAD + f'[grid]\n"world.obstacles" = [{MOVED}, []]\n'
                           f'[variants.moved]\ncontroller = "goto_slot"\n'
                           f'"world.obstacles" = {MOVED}\n')
    sweep = load_sweep(path)
    assert len(sweep.runs) == 4 and {hash(v) for v in sweep.variants}


def test_an_unreadable_variant_file_names_the_sweep_and_the_key(tmp_path: Path,
                                                                 monkeypatch) -> None:
    tuned = tmp_path / "tuned.toml"
    tuned.write_text('[variants.t]\ncontroller = "goto_slot"\n')
    path = tmp_path / "s.toml"
    path.write_text(HEAD + 'variant_files = ["tuned.toml"]\n')
    assert [v.name for v in load_sweep(path).variants] == ["goto_slot", "t"]
    read = Path.read_bytes

    def no_access(self: Path) -> bytes:
        if self.name == "tuned.toml":
            raise PermissionError(13, "Permission denied")
        return read(self)

    monkeypatch.setattr(Path, "read_bytes", no_access)
    with pytest.raises(ScenarioError) as info:
        load_sweep(path)
    assert str(info.value) == f"{path}: variant_files[0]: {tuned}: permission denied"


def test_a_plugin_whose_import_raises_names_the_sweep_and_the_key(tmp_path: Path) -> None:
    (tmp_path / "broken.py").write_text("1 / 0\n")
    path = tmp_path / "s.toml"
    path.write_text(HEAD + 'plugins = ["broken.py"]\n')
    with pytest.raises(ScenarioError) as info:
        load_sweep(path)
    assert str(info.value) == (f"{path}: plugins[0]: {tmp_path / 'broken.py'}: importing it "
                               "raised ZeroDivisionError: division by zero")
    assert info.value.key == "plugins[0]"


def test_the_dict_form_refuses_a_sweep_of_no_run() -> None:
    with pytest.raises(ScenarioError, match=r"^<dict>: controllers: lists no controller"):
        sweep_from_dict({"scenarios": [str(TINY)], "controllers": [], "seeds": 1})
    with pytest.raises(ScenarioError, match=r"^<dict>: ladder\[0\]\.scenarios: must be an "
                                            r"array, got str 'tiny\.toml'"):
        sweep_from_dict({"scenarios": [str(TINY)], "controllers": ["goto_slot"], "seeds": 1,
                         "ladder": [{"scenarios": "tiny.toml", "key": "t_max",
                                     "values": [2.0]}]})


#: Every public name that other modules, tests and scripts import from the sweep module.
PUBLIC = ("DICT_SOURCE", "KEY_MAX", "MAX_RUNS", "MAX_SEEDS", "NAME_MAX", "RunSpec", "Sweep",
          "SweepSpec", "canonical", "check_split", "describe_runs", "expand_sweep",
          "load_run_scenario", "load_sweep", "safe_name", "shorten", "sweep_from_dict")


def test_the_sweep_package_exports_every_public_name_of_its_parts() -> None:
    import dfcoa_opt.bench.sweep as door
    from dfcoa_opt.bench.sweep import specs

    assert set(PUBLIC) <= set(door.__all__)
    for name in door.__all__:
        obj = getattr(door, name)
        for part in (specs, sweep_mod):
            if hasattr(part, name):
                assert getattr(part, name) is obj, name


def test_patching_load_run_scenario_of_the_sweep_module_reaches_the_expansion(
        tmp_path: Path, monkeypatch) -> None:
    """The tests that cache scenario loads patch ``bench.sweep.expand.load_run_scenario``."""
    seen = []
    real = sweep_mod.load_run_scenario

    def load(run):
        seen.append(run.scenario_file)
        return real(run)

    monkeypatch.setattr(sweep_mod, "load_run_scenario", load)
    path = tmp_path / "s.toml"
    path.write_text(HEAD)
    assert len(load_sweep(path).runs) == 1 and seen == [str(TINY.resolve())]
