"""Hypothesis fuzzing beyond the loader: mutated scenarios are run, mutated sweeps expanded.

``tests/test_fuzz_loader.py`` checks that whatever a scenario file holds, the
loader gives a Scenario or a one-line ScenarioError. This module checks what
comes next, on the same kind of input:

- **A legal file runs its first steps without a traceback, NaN, or a memory
  blow-up.** A shipped scenario (a base of the loader fuzz tests) with one to
  three hostile edits (:func:`tests.fuzz_strategies.mutated_bases`), or with one
  to three dotted keys set to values mostly of their type, the drawn
  controller's parameters among them (:func:`tests.fuzz_sweeps.overridden_bases`),
  is loaded; if it loads, it is run with a controller drawn from
  :data:`RUN_CONTROLLERS` (every registered one) for at most :data:`STEPS` steps
  of its ``dt`` (``t_max`` capped on the loaded spec) and a drawn seed. The run
  returns a log whose time, pose, estimate, velocity, twist, command, leader and
  slot arrays are all finite and whose metrics (:func:`dfcoa_opt.metrics.summary`)
  have an outcome of :data:`dfcoa_opt.outcome.OUTCOMES`; or it raises a
  :class:`~dfcoa_opt.errors.DfcoaError` (a ScenarioError for a bad controller
  parameter or a seed whose world does not load, ``RunFailed`` /
  ``ControllerError`` for a run that fails cleanly) whose message is one line.
  ``nmpc`` runs with ``compiled = false`` (casadi's interpreter, the same
  numbers): each new horizon would otherwise compile C code, for up to two
  minutes, into the user's cache.
- **A mutated sweep file expands, or fails on one line.** A sweep of
  ``scenarios/sweeps/`` with one to three edits (:func:`tests.fuzz_sweeps.mutated_sweeps`),
  given as a dict (``sweep_from_dict``) or written as a TOML file (``load_sweep``),
  expands to at most ``MAX_RUNS`` runs with unique keys of at most ``KEY_MAX``
  characters whose identities can be written as JSON, or raises a ScenarioError on
  one line that names the sweep (or the file at fault); the sweep machinery
  takes less than :data:`SWEEP_SECONDS` for it.
- **A mutated small sweep benches, or changes nothing.** A shipped sweep cut down
  to a few ``goto_slot`` runs on ``tests/data/bench/tiny.toml``
  (:func:`tests.fuzz_sweeps.small_sweeps`), edited, is run with ``dfcoa bench``
  into a folder that a first, good bench filled: exit 0 with a row for every
  run, no run failed by an exception other than a DfcoaError and the first
  bench's row kept; or exit 2 with one stderr line and the folder byte-identical.

Any other exception, a ``RuntimeWarning`` (the bases run with every controller,
and their metrics are computed, without one), or a non-finite number in the log
fails.

Bounded cost. Examples the loader fuzz tests skip as too costly to load
(:func:`tests.fuzz_schema.too_costly`) are skipped here too, and so are scenarios
that load but would be slow to step (:func:`too_slow_to_run`: more than
:data:`ROBOT_CAP` robots, :data:`BEAM_CAP` LiDAR beams x robots,
:data:`PARTICLE_CAP` MCL particles x robots, or an nmpc of more than
:data:`NMPC_CAP` robots x horizon). A run has a ``deadline`` of
:data:`RUN_DEADLINE`. A sweep's scenario loads are cached across examples (the
loader is fuzzed on its own); the time bound counts the rest of the expansion.
The address space is capped at its size + 4 GiB (the fixture of the loader fuzz
tests), so a missed allocation fails with MemoryError instead of waking the OOM
killer.

Sizes: 150 run examples, 150 sweep expansions and 30 benches (about 60 s on one
core); ``DFCOA_FUZZ_EXAMPLES=N`` makes that N, N and N/5. ``make test`` runs
them derandomized (``tests/conftest.py``); ``DFCOA_HYPOTHESIS=explore`` draws
fresh inputs.
"""

from __future__ import annotations

import copy
import dataclasses
import io
import json
import math
import os
import shutil
import time
from collections import OrderedDict
from contextlib import contextmanager, redirect_stderr, redirect_stdout
from datetime import timedelta
from pathlib import Path
from typing import Any
from unittest import mock

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, currently_in_test_context, given, settings
from hypothesis import event as _event
from hypothesis import strategies as st

from dfcoa_opt import metrics
from dfcoa_opt.bench import sweep as sweep_mod
from dfcoa_opt.bench.sweep import KEY_MAX, MAX_RUNS, Sweep, load_sweep, sweep_from_dict
from dfcoa_opt.cli import main
from dfcoa_opt.control.registry import build_controller
from dfcoa_opt.errors import DfcoaError, ScenarioError
from dfcoa_opt.outcome import OUTCOMES
from dfcoa_opt.sim.loader import apply_overrides, scenario_from_dict
from dfcoa_opt.sim.scenario import Scenario
from dfcoa_opt.sim.simulator import Simulator
from tests.fuzz_schema import num, too_costly
from tests.fuzz_strategies import BASES, check_outcome, mutated_bases
from tests.fuzz_sweeps import (
    SWEEP_BASES,
    SWEEPS_DIR,
    TINY,
    mirror,
    overridden_bases,
    small_sweeps,
    snapshot,
)
from tests.fuzz_sweeps import mutated_sweeps as mutated_sweep_dicts
from tests.fuzz_toml import to_toml
from tests.test_fuzz_loader import _address_space_cap  # noqa: F401 - the same memory cap

pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")


def examples(default: int) -> int:
    """``default`` examples, or ``DFCOA_FUZZ_EXAMPLES`` scaled from the 150 of the big tests."""
    raw = os.environ.get("DFCOA_FUZZ_EXAMPLES", "").strip()
    if not raw:
        return default
    if not raw.isdigit() or int(raw) < 1:
        raise ValueError(f"DFCOA_FUZZ_EXAMPLES must be a positive integer, got {raw!r}")
    return max(1, round(int(raw) * default / 150))


def event(text: str) -> None:
    """Hypothesis's ``event`` (its statistics), a no-op outside a hypothesis test."""
    if currently_in_test_context():
        _event(text)


def one_line(exc: BaseException) -> None:
    msg = str(exc)
    assert msg and "\n" not in msg and "\r" not in msg, f"message is not one line: {msg!r}"


# ------------------------------------------------------------- scenario runs
#: Controllers drawn for a run: every registered one (each steps 20 times in < 0.1 s on
#: the bases once compiled; nmpc in 0.3 s, 5 s for its first, compiling run).
RUN_CONTROLLERS = ["goto_slot", "goto_slot+cbf", "goto_slot+orca", "dfcoa", "orca_nav",
                   "virtual_spring", "virtual_spring_basic", "consensus", "consensus_ivo",
                   "lf_vo", "reshape", "learned", "learned_ppo", "nmpc"]
SEEDS = [None, 0, 1, 7, 2**31 - 1]
STEPS = 20
RUN_DEADLINE = timedelta(seconds=20)
ROBOT_CAP = 200
BEAM_CAP = 200_000
PARTICLE_CAP = 200_000
#: nmpc: robots x horizon (20 robots x 10 stages: 0.7 s for 20 steps; x 100: 116 s)
NMPC_CAP = 250
#: Arrays of a log that must be finite.
FINITE = ("t", "pose", "pose_est", "velocity", "twist", "command", "leader", "slots")


def too_slow_to_run(scenario: Scenario, controller: str) -> bool:
    """Whether stepping the loaded scenario could take long (see the module docstring)."""
    spec = scenario.spec
    if controller == "nmpc":
        horizon = num(spec.controllers.get("nmpc", {}).get("horizon", 10)) or 10
        if spec.team.n * horizon > NMPC_CAP:
            return True
    n = spec.team.n
    beams = spec.sensors.lidar.beams if spec.sensors.lidar.enabled else 0
    particles = 0.0
    if spec.localization.mode == "mcl":
        particles = float((spec.localization.options or {}).get("particle_limits",
                                                                (0, 5000))[-1])
    return n > ROBOT_CAP or n * beams > BEAM_CAP or n * particles > PARTICLE_CAP


def capped(scenario: Scenario, seed: int | None) -> Scenario:
    """The scenario for ``seed`` with ``t_max`` at most :data:`STEPS` steps of its ``dt``."""
    if seed is not None:
        scenario = scenario.for_seed(seed)
    spec = scenario.spec
    t_max = min(spec.t_max, STEPS * spec.dt)
    return dataclasses.replace(scenario, spec=dataclasses.replace(spec, t_max=t_max))


def check_run(scenario: Scenario, controller: str, seed: int | None) -> None:
    """Run the first steps: a finite log with a valid outcome, or a one-line DfcoaError."""
    try:
        sc = capped(scenario, seed)
        tables = dict(sc.spec.controllers)
        if controller == "nmpc":  # casadi's interpreter: a new horizon compiles C for minutes
            tables["nmpc"] = {**tables.get("nmpc", {}), "compiled": False}
        ctrl = build_controller(controller, tables, sc.source)
        log = Simulator(sc, ctrl, seed).run()
    except DfcoaError as exc:
        one_line(exc)
        event(f"run: {type(exc).__name__}")
        return
    assert 1 <= log.n_steps <= STEPS + 1
    for name in FINITE:
        values = getattr(log, name)
        bad = np.argwhere(~np.isfinite(values))
        assert not len(bad), f"log.{name} is not finite at {bad[:3].tolist()}"
    outcome = metrics.summary(log, sc.spec.metrics)["outcome"]
    assert outcome in OUTCOMES, outcome
    event(f"run: {outcome}")


@pytest.fixture(scope="module")
def warm(one_numba_thread):
    """Every controller compiled (numba) and built once, outside the deadline."""
    scenario = scenario_from_dict(copy.deepcopy(BASES["tiny"][0]), str(TINY), TINY.parent)
    for controller in RUN_CONTROLLERS:
        check_run(scenario, controller, None)


def test_every_controller_runs_every_base(warm):
    """The bases run with every controller: the property holds before any edit."""
    for name, (data, source, folder, _) in sorted(BASES.items()):
        scenario = scenario_from_dict(copy.deepcopy(data), source, folder)
        assert not any(too_slow_to_run(scenario, c) for c in RUN_CONTROLLERS), name
        for controller in RUN_CONTROLLERS:
            check_run(scenario, controller, 0)


@st.composite
def run_cases(draw: Any) -> tuple[str, str, dict[str, Any], int | None]:
    """``(controller, base name, mutated data, seed)``: the data from
    :func:`~tests.fuzz_strategies.mutated_bases` (hostile edits) or
    :func:`~tests.fuzz_sweeps.overridden_bases` (dotted keys set mostly to values of their
    type, the controller's parameters among them)."""
    controller = draw(st.sampled_from(RUN_CONTROLLERS))
    if draw(st.booleans()):
        name, data = draw(mutated_bases())
    else:
        name, data, overrides = draw(overridden_bases(controller))
        try:
            apply_overrides(data, overrides, "<overrides>")
        except ScenarioError:
            assume(False)
    return controller, name, data, draw(st.sampled_from(SEEDS))


@settings(max_examples=examples(150), deadline=RUN_DEADLINE,
          suppress_health_check=[HealthCheck.filter_too_much, HealthCheck.too_slow])
@given(case=run_cases())
def test_mutated_scenarios_run_their_first_steps(warm, case: tuple[str, str, dict[str, Any],
                                                                   int | None]):
    """A mutated shipped scenario that loads runs its first steps: a finite log with a valid
    outcome, or a one-line DfcoaError (see the module docstring)."""
    controller, name, data, seed = case
    assume(not too_costly(data))
    _, source, folder, _ = BASES[name]
    scenario = check_outcome(lambda: scenario_from_dict(data, source, folder), source)
    assume(scenario is not None)
    assume(not too_slow_to_run(scenario, controller))
    check_run(scenario, controller, seed)


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

    def load(run: sweep_mod.RunSpec) -> Scenario:
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
