"""Hypothesis fuzzing of sweep files: mutated sweeps are expanded and benched.

- **A mutated sweep file expands, or fails on one line.** A sweep of
  ``scenarios/sweeps/`` with one to three edits (:func:`tests.fuzz_sweeps.mutated_sweeps`),
  given as a dict (``sweep_from_dict``) or written as a TOML file (``load_sweep``),
  expands to at least one and at most ``MAX_RUNS`` runs with unique keys of at
  most ``KEY_MAX`` characters whose identities can be written as JSON, or raises
  a ScenarioError on one line that names the sweep (or the file at fault); the
  sweep machinery takes less than :data:`SWEEP_SECONDS` for it.
- **A mutated small sweep benches, or changes nothing.** A shipped sweep cut down
  to a few ``goto_slot`` runs on ``tests/data/bench/tiny.toml``
  (:func:`tests.fuzz_sweeps.small_sweeps`), edited, is run with ``dfcoa bench``
  into a folder that a first, good bench filled: exit 0 with a row for every
  run, no run failed by an exception other than a DfcoaError and the first
  bench's row kept; or exit 2 with one stderr line and the folder byte-identical.

Any other exception or a ``RuntimeWarning`` fails. A sweep's scenario loads are
cached across examples (the loader is fuzzed on its own); the time bound counts
the rest of the expansion. The address space is capped as in
``tests/test_fuzz_loader.py``.

Sizes: 150 sweep expansions and 30 benches (about 30 s on one core);
``DFCOA_FUZZ_EXAMPLES=N`` makes that N and N/5. ``make test`` runs them
derandomized (``tests/conftest.py``); ``DFCOA_HYPOTHESIS=explore`` draws fresh
inputs.
"""

from __future__ import annotations

import dataclasses
import io
import json
import math
import shutil
import time
from collections import OrderedDict
from contextlib import contextmanager, redirect_stderr, redirect_stdout
from pathlib import Path
from typing import Any
from unittest import mock

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from dfcoa_opt.bench.sweep import KEY_MAX, MAX_RUNS, RunSpec, Sweep, load_sweep, sweep_from_dict
from dfcoa_opt.bench.sweep import expand as sweep_mod
from dfcoa_opt.cli import main
from dfcoa_opt.core.errors import DfcoaError, ScenarioError
from dfcoa_opt.scenario.scenario import Scenario
from tests.fuzz_strategies import event, examples, one_line
from tests.fuzz_sweeps import SWEEP_BASES, SWEEPS_DIR, TINY, mirror, small_sweeps, snapshot
from tests.fuzz_sweeps import mutated_sweeps as mutated_sweep_dicts
from tests.fuzz_toml import to_toml
from tests.test_fuzz_loader import _address_space_cap  # noqa: F401 - the same memory cap

pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")


# ------------------------------------------------------------ sweep expansion
SWEEP_SECONDS = 5.0
_LOADS: OrderedDict[tuple[str, int, str], Any] = OrderedDict()
_LOADS_MAX = 300


@contextmanager
def cached_loads():
    """Scenario loads of the sweep module cached across examples (LRU); yields a timer.

    A load is a function of the file, the seed and the overrides. The timer's
    ``seconds`` adds up the time spent in loads that were not cached.
    """
    timer = {"seconds": 0.0}
    real = sweep_mod.load_run_scenario

    def load(run: RunSpec) -> Scenario:
        key = (run.scenario_file, run.seed, run.overrides)
        if key in _LOADS:
            _LOADS.move_to_end(key)
            hit = _LOADS[key]
            if isinstance(hit, DfcoaError):
                raise hit
            return hit
        t0 = time.perf_counter()
        try:
            result = real(run)
        except DfcoaError as exc:
            result = exc
        finally:
            timer["seconds"] += time.perf_counter() - t0
        _LOADS[key] = result
        if len(_LOADS) > _LOADS_MAX:
            _LOADS.popitem(last=False)
        if isinstance(result, DfcoaError):
            raise result
        return result

    with mock.patch.object(sweep_mod, "load_run_scenario", load):
        yield timer


def check_sweep(call: Any, source: str) -> Sweep | None:
    """Expand a sweep: a bounded Sweep whose rows can be written, or a one-line ScenarioError."""
    with cached_loads() as timer:
        t0 = time.perf_counter()
        try:
            sweep = call()
        except DfcoaError as exc:
            one_line(exc)
            where = str(exc).split(": ")[0]
            assert str(exc).startswith(f"{source}: ") or Path(where).exists(), (
                f"the message names neither the sweep nor a file: {exc}")
            assert isinstance(exc, ScenarioError), f"not a ScenarioError: {exc!r}"
            event(f"sweep: ScenarioError at {exc.key.split('.')[0].split('[')[0] or '<file>'}")
            sweep = None
        elapsed = time.perf_counter() - t0 - timer["seconds"]
    event(f"sweep: {next(b for b in (0.1, 0.5, 1.0, 2.0, math.inf) if elapsed < b)} s or less "
          "besides its scenario loads")
    assert elapsed < SWEEP_SECONDS, f"the sweep took {elapsed:.1f} s besides its scenario loads"
    if sweep is None:
        return None
    assert isinstance(sweep, Sweep) and 0 < len(sweep.runs) <= MAX_RUNS
    event("sweep: expanded")
    keys = [r.key for r in sweep.runs]
    assert len(set(keys)) == len(keys), "two runs share a key"
    assert max(map(len, keys)) <= KEY_MAX
    for run in {dataclasses.replace(r, seed=0) for r in sweep.runs}:
        json.dumps([run.overrides_dict, run.ladder_value, run.variant_name], allow_nan=False)
    return sweep


@pytest.fixture(scope="module")
def sweep_folder(tmp_path_factory) -> Path:
    """Where a mutated sweep is written: a ``sweeps/`` beside links to the scenarios."""
    return mirror(tmp_path_factory.mktemp("fuzz_sweeps"))


def test_every_shipped_sweep_expands(sweep_folder: Path):
    """The bases of the sweep mutations expand, as dicts and as files written by the test."""
    for name, data in sorted(SWEEP_BASES.items()):
        assert check_sweep(lambda d=data: sweep_from_dict(d, SWEEPS_DIR), "<dict>") is not None
        path = sweep_folder / f"{name}.toml"
        path.write_text(to_toml(data), encoding="utf-8")
        assert check_sweep(lambda p=path: load_sweep(p), str(path)) is not None, name


@settings(max_examples=examples(150), deadline=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(case=mutated_sweep_dicts(), as_file=st.booleans())
def test_mutated_sweeps_expand_or_fail_on_one_line(sweep_folder: Path,
                                                   case: tuple[str, dict[str, Any]],
                                                   as_file: bool):
    """A mutated shipped sweep, as a dict or a written file, expands within bounds or raises
    a one-line DfcoaError; nothing else escapes, and it is quick (see the module docstring)."""
    name, data = case
    if not as_file:
        check_sweep(lambda: sweep_from_dict(data, SWEEPS_DIR), "<dict>")
        return
    path = sweep_folder / f"{name}.toml"
    path.write_text(to_toml(data), encoding="utf-8")
    check_sweep(lambda: load_sweep(path), str(path))


# ------------------------------------------------------------------ benches
BENCH_RUNS = 6


def bench(sweep: Path, out: Path) -> tuple[int, list[str], str]:
    """``dfcoa bench`` in this process: exit code, stderr lines, stdout."""
    stdout, stderr = io.StringIO(), io.StringIO()
    with redirect_stdout(stdout), redirect_stderr(stderr):
        code = main(["bench", str(sweep), "--out", str(out), "--executor", "serial",
                     "--no-progress"])
    return code, stderr.getvalue().splitlines(), stdout.getvalue()


@pytest.fixture(scope="module")
def filled(tmp_path_factory) -> Path:
    """A results folder after one good bench (1 run of goto_slot on tiny.toml)."""
    work = tmp_path_factory.mktemp("fuzz_bench_ok")
    ok = work / "ok.toml"
    ok.write_text(f'name = "ok"\nscenarios = ["{TINY.as_posix()}"]\n'
                  'controllers = ["goto_slot"]\nseeds = 1\n')
    code, err, _ = bench(ok, work / "out")
    assert code == 0, err
    return work / "out"


def _runs_of(path: Path) -> int:
    """The runs of a sweep file (-1 when it does not expand)."""
    try:
        return len(load_sweep(path).runs)
    except DfcoaError:
        return -1


@settings(max_examples=examples(30), deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
@given(case=small_sweeps())
def test_small_mutated_sweeps_bench_or_change_nothing(filled: Path, tmp_path_factory,
                                                      case: tuple[str, dict[str, Any]]):
    """A cut-down shipped sweep, edited, run by ``dfcoa bench`` into a filled folder: exit 0
    with every run's row, or exit 2 with one line and the folder byte-identical."""
    name, data = case
    work = tmp_path_factory.mktemp("fuzz_bench")
    try:
        sweep = work / f"{name}.toml"
        sweep.write_text(to_toml(data), encoding="utf-8")
        count = _runs_of(sweep)
        assert count != 0, "a sweep expanded to no run"
        assume(count <= BENCH_RUNS)
        shutil.copytree(filled, work / "out", symlinks=True)
        check_bench(sweep, work / "out")
    finally:
        shutil.rmtree(work, ignore_errors=True)


def check_bench(sweep: Path, out: Path) -> None:
    """``dfcoa bench`` of ``sweep`` into ``out``: exit 0 with every row, or 2 and no change."""
    before = snapshot(out)
    code, err, stdout = bench(sweep, out)
    assert code in (0, 2), (code, err)
    if code == 2:
        event("bench: exit 2")
        assert len(err) == 1 and err[0].startswith("dfcoa: error: "), err
        assert snapshot(out) == before, "a failed bench changed the results folder"
        return
    event("bench: exit 0")
    assert "report: dfcoa report" in stdout
    after = snapshot(out)
    rows = {k: json.loads(v) for k, v in after.items() if k.startswith("rows/")}
    runs = {r.key: r for r in load_sweep(sweep).runs}
    for key in runs:
        row = rows.get(f"rows/{key}.json")
        assert row is not None, f"no row for {key}"
        assert "traceback" not in row.get("provenance", {}), row["error"]
        if row["status"] == "failed":
            event("bench: a failed run")
            assert row["error"] and "\n" not in row["error"]
    # the first bench's run is kept unless the new sweep runs its key with other overrides
    old = json.loads(before["rows/tiny__goto_slot__s0.json"])
    new = runs.get(old["key"])
    if new is None or (new.controller, new.overrides_dict) == (old["controller"],
                                                              old["overrides"]):
        for k in ("rows/tiny__goto_slot__s0.json", "logs/tiny__goto_slot__s0.npz"):
            assert after.get(k) == before[k], f"{k} was rewritten"
