"""The result cache keys on each controller's own code (bench.results.fingerprint).

Edits are simulated by changing what the fingerprint reads for a source file
(``fingerprint._read_source``); the sources on disk are never touched.
"""

from __future__ import annotations

import ast
import itertools
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

import comparisons
import dfcoa_opt
from dfcoa_opt.bench.executors import ExecutorConfig
from dfcoa_opt.bench.harness import run_sweep
from dfcoa_opt.bench.results import fingerprint, store
from dfcoa_opt.bench.sweep import load_sweep
from dfcoa_opt.control import registry
from dfcoa_opt.core.runtime.kernel_cache import module_files

TINY = Path(__file__).parent / "data" / "bench" / "tiny.toml"
IDS = ("goto_slot", "lf_vo", "dfcoa", "orca_nav", "goto_slot+cbf", "reshape")
LF_VO_KERNEL = "comparisons/lf_vo/kernel.py"
CBF_FILTER = "comparisons/cbf/filter.py"
BATCH = "dfcoa_opt/sim/batch.py"
GOTO_SLOT = "dfcoa_opt/control/goto_slot.py"

Edit = Callable[[str, Callable[[str], str]], None]


def _forget() -> None:
    fingerprint._sources.cache_clear()
    fingerprint.code_fingerprint.cache_clear()


@pytest.fixture
def edit(monkeypatch) -> Iterator[Edit]:
    """``edit(relative_path, change)``: the fingerprint now reads ``change(text)`` for that file.

    Each file is read from disk once per test, so the fingerprints before and
    after an edit see the same sources otherwise.
    """
    changes: dict[str, Callable[[str], str]] = {}
    disk: dict[Path, str] = {}
    read = fingerprint._read_source

    def patched(path: Path) -> str:
        if path not in disk:
            disk[path] = read(path)
        text = disk[path]
        for rel, change in changes.items():
            if Path(path).as_posix().endswith("/" + rel):
                return change(text)
        return text

    def apply(rel: str, change: Callable[[str], str]) -> None:
        assert rel in fingerprint.fingerprint_sources(), rel  # a real, fingerprinted source
        changes[rel] = change
        _forget()

    monkeypatch.setattr(fingerprint, "_read_source", patched)
    _forget()
    yield apply
    _forget()


def code_edit(text: str) -> str:
    """A change of what the module does."""
    return text + "\n_EDITED_FOR_A_TEST = 1\n"


def docstring_edit(text: str) -> str:
    """Reworded docstrings, new comments and blank lines: nothing a run executes."""
    tree = ast.parse(text)
    assert ast.get_docstring(tree) is not None  # the edit below does change the text
    lines = text.splitlines(keepends=True)
    for node in ast.walk(tree):
        if not isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef)):
            continue
        if ast.get_docstring(node):
            first = node.body[0].lineno - 1
            lines[first] = lines[first].replace('"""', '"""Reworded. ', 1)
    out = "# a new comment\n\n" + "".join(lines).replace("\n\n\n", "\n\n\n# another\n")
    assert out != text
    return out


def fingerprints(ids=IDS) -> dict[str, str]:
    return {c: fingerprint.code_fingerprint(c) for c in ids}


def changed(before: dict[str, str], after: dict[str, str]) -> set[str]:
    return {c for c in before if before[c] != after[c]}


# -- what each fingerprint covers ------------------------------------------------------------

def test_each_controller_has_its_own_fingerprint(edit):
    fps = fingerprints()
    for a, b in itertools.combinations(IDS, 2):
        assert fps[a] != fps[b], (a, b)
    # ids of one module (parameter presets of one class) share their code
    assert (fingerprint.code_fingerprint("consensus")
            == fingerprint.code_fingerprint("consensus_ivo"))
    assert fps["goto_slot"] != fingerprint.code_fingerprint()  # not everything any more


def test_the_sources_of_each_fingerprint():
    src = {c: set(fingerprint.fingerprint_sources(c)) for c in IDS}
    everything = set(fingerprint.fingerprint_sources())
    core = set.intersection(*src.values())
    # the simulator, the run path of the harness, scenario loading, planners and
    # localization, the registry and the controller interfaces: every run
    assert {BATCH, "dfcoa_opt/sim/simulator.py", "dfcoa_opt/bench/runner.py",
            "dfcoa_opt/scenario/loader.py", "dfcoa_opt/planning/astar.py",
            "dfcoa_opt/sim/localization/mcl/filter.py",
            "dfcoa_opt/control/registry.py", "dfcoa_opt/control/base.py"} <= core
    assert not any(s.startswith("comparisons/") for s in core)
    # the rest of dfcoa_opt is core too: only controller modules of dfcoa_opt/control/ differ
    controls = {"dfcoa_opt/control/goto_slot.py", "dfcoa_opt/control/dfcoa/__init__.py",
                "dfcoa_opt/control/dfcoa/controller.py",
                "dfcoa_opt/control/dfcoa/histogram.py", "dfcoa_opt/control/dfcoa/vfh_star.py",
                "dfcoa_opt/control/dfcoa/formation_law.py"}
    own = {s for s in everything if s.startswith("dfcoa_opt/")}
    assert controls <= own - core and all(s.startswith("dfcoa_opt/control/") for s in own - core)
    assert src["goto_slot"] - core == {GOTO_SLOT}
    assert src["dfcoa"] - core == controls - {GOTO_SLOT}
    lf_vo = src["lf_vo"] - core
    assert {"comparisons/__init__.py", "comparisons/lf_vo/__init__.py",
            "comparisons/lf_vo/controller.py", LF_VO_KERNEL} <= lf_vo
    assert all(s.startswith("comparisons/lf_vo/") for s in lf_vo - {"comparisons/__init__.py"})
    # a filter's closure joins its controller's; reshape imports the cbf filter
    cbf = src["goto_slot+cbf"] - src["goto_slot"]
    assert CBF_FILTER in cbf and cbf <= src["reshape"]
    assert CBF_FILTER in src["reshape"] and CBF_FILTER not in src["orca_nav"]
    assert "comparisons/orca/filter.py" in set(fingerprint.fingerprint_sources("consensus"))


def test_controllers_whose_imports_cannot_be_read_cover_every_source(monkeypatch):
    everything = fingerprint.fingerprint_sources()
    assert fingerprint.fingerprint_sources("no_such_controller") == everything

    class Outside:  # as from an entry point or a notebook: its imports are not read
        Params = registry.controller_class("goto_slot").Params

    registry.available()
    monkeypatch.setitem(registry.CONTROLLERS._table, "test_outside", Outside)
    assert fingerprint.fingerprint_sources("test_outside") == everything
    assert fingerprint.fingerprint_sources("test_outside+cbf") == everything


def test_the_layers_above_the_run_are_in_no_fingerprint():
    """The rule is the layer contract: what runs is the run layers, the root and the run path."""
    everything = set(fingerprint.fingerprint_sources())
    for rel in ("dfcoa_opt/bench/report/tables.py", "dfcoa_opt/bench/figures.py",
                "dfcoa_opt/bench/harness.py", "dfcoa_opt/bench/results/store.py",
                "dfcoa_opt/viz/plotting.py", "dfcoa_opt/envs/core.py", "dfcoa_opt/api.py",
                "dfcoa_opt/cli/__init__.py", "comparisons/learned/train.py"):
        assert rel not in everything, rel
    for rel in ("dfcoa_opt/__init__.py", "dfcoa_opt/bench/runner.py",
                "dfcoa_opt/bench/sweep/expand.py", "dfcoa_opt/metrics/summary.py",
                "dfcoa_opt/sim/stall.py", "dfcoa_opt/core/registry.py"):
        assert rel in fingerprint.core_sources(), rel


def test_editing_a_report_reruns_nothing(edit, monkeypatch):
    """A module above the run path changes no fingerprint, even where it is read."""
    before, everything = fingerprints(), fingerprint.code_fingerprint()
    read = fingerprint._read_source
    monkeypatch.setattr(fingerprint, "_read_source", lambda p: (
        read(p) + "\n_EDITED = 1\n" if Path(p).as_posix().endswith("bench/report/tables.py")
        else read(p)))
    fingerprint._sources.cache_clear()
    fingerprint.code_fingerprint.cache_clear()
    assert fingerprints() == before and fingerprint.code_fingerprint() == everything


# -- edits -----------------------------------------------------------------------------------

def test_editing_lf_vo_changes_only_lf_vo(edit):
    before = fingerprints()
    edit(LF_VO_KERNEL, code_edit)
    assert changed(before, fingerprints()) == {"lf_vo"}


def test_editing_the_cbf_filter_changes_its_users_only(edit):
    before = fingerprints()
    edit(CBF_FILTER, code_edit)
    assert changed(before, fingerprints()) == {"goto_slot+cbf", "reshape"}


def test_editing_a_dfcoa_opt_control_module(edit):
    before = fingerprints()
    edit("dfcoa_opt/control/dfcoa/histogram.py", code_edit)
    assert changed(before, fingerprints()) == {"dfcoa"}
    edit(GOTO_SLOT, code_edit)
    assert changed(before, fingerprints()) == {"dfcoa", "goto_slot", "goto_slot+cbf"}


def test_editing_the_simulator_changes_every_fingerprint(edit):
    before = fingerprints()
    edit(BATCH, code_edit)
    assert changed(before, fingerprints()) == set(IDS)


def test_docstring_and_comment_edits_change_nothing(edit):
    before = fingerprints()
    everything = fingerprint.code_fingerprint()
    for rel in (LF_VO_KERNEL, CBF_FILTER, BATCH, GOTO_SLOT,
                "dfcoa_opt/control/dfcoa/controller.py"):
        edit(rel, docstring_edit)
    assert fingerprints() == before
    assert fingerprint.code_fingerprint() == everything


def test_an_import_by_an_old_module_name_is_followed(edit):
    """``comparisons.lf_vo_core`` moved to ``comparisons.lf_vo.equations`` (core.moved)."""
    edit(GOTO_SLOT, lambda t: t + "\n\ndef _old():\n    from comparisons.lf_vo_core import x\n")
    assert "comparisons/lf_vo/equations.py" in fingerprint.fingerprint_sources("goto_slot")
    before = fingerprints()
    edit("comparisons/lf_vo/equations.py", code_edit)
    assert changed(before, fingerprints()) == {"goto_slot", "goto_slot+cbf", "lf_vo"}


def test_a_controller_importing_by_a_computed_name_covers_every_source(edit):
    loader = ("\n\ndef _load(name):\n    import importlib\n\n"
              "    return importlib.import_module(name)\n")
    edit(LF_VO_KERNEL, lambda t: t + loader)
    assert fingerprint.fingerprint_sources("lf_vo") == fingerprint.fingerprint_sources()
    assert fingerprint.fingerprint_sources("goto_slot") != fingerprint.fingerprint_sources()


def test_the_core_names_no_controller_module():
    """An ``importlib`` import by name of a controller module from the core is invisible to the
    import graph. The registry names none (the built-ins are entry points); the only names
    are the policy package's (built from files), ``find_spec("comparisons")`` and the new homes
    of the old module paths (loaded only when an old path is imported)."""
    src = fingerprint._sources()
    files = module_files([Path(dfcoa_opt.__file__).parent, Path(comparisons.__file__).parent])
    controller_side = set(src.hashed) - src.core
    named = set()
    for name in src.core:
        tree = ast.parse(files[name].read_text(encoding="utf-8"))
        named |= {n.value for n in ast.walk(tree) if isinstance(n, ast.Constant)
                  and isinstance(n.value, str) and n.value in controller_side}
    assert named <= {registry.POLICY_MODULE, "comparisons", *dfcoa_opt.MOVED.values()}


# -- the store --------------------------------------------------------------------------------

def test_pending_lists_exactly_the_runs_of_the_edited_controller(tmp_path, edit):
    sweep = tmp_path / "sweep.toml"
    sweep.write_text(f'scenarios = ["{TINY.as_posix()}"]\n'
                     'controllers = ["goto_slot", "lf_vo", "goto_slot+cbf"]\nseeds = 2\n'
                     '[grid]\nt_max = [0.5]\n')
    res = run_sweep(sweep, tmp_path / "out", ExecutorConfig("serial"), progress=False)
    assert res.failed == 0 and res.ran == 6
    runs = load_sweep(sweep).runs
    assert res.store.pending(runs) == []
    assert res.store.manifest()["code"] == {c: fingerprint.code_fingerprint(c)
                                            for c in ("goto_slot", "goto_slot+cbf", "lf_vo")}

    edit(LF_VO_KERNEL, docstring_edit)
    assert res.store.pending(runs) == []
    edit(LF_VO_KERNEL, code_edit)
    pending = res.store.pending(runs)
    assert pending == [r for r in runs if r.controller == "lf_vo"] and len(pending) == 2
    # another store adopts the rows still valid, and only those
    other = store.ResultsStore(tmp_path / "other")
    assert [other.adopt(r, [res.store]) for r in runs] == [r.controller != "lf_vo" for r in runs]
    edit(CBF_FILTER, code_edit)
    assert {r.controller for r in res.store.pending(runs)} == {"lf_vo", "goto_slot+cbf"}
    # resuming reruns them, under their new fingerprints
    again = run_sweep(sweep, tmp_path / "out", ExecutorConfig("serial"), progress=False)
    assert (again.ran, again.skipped) == (4, 2)
    assert again.store.pending(runs) == []
