"""Hypothesis fuzzing beyond the loader: mutated scenarios are run.

``tests/test_fuzz_loader.py`` checks that whatever a scenario file holds, the
loader gives a Scenario or a one-line ScenarioError. This module checks what
comes next, on the same kind of input (``tests/test_fuzz_sweeps.py`` does the
same for sweep files):

**A legal file runs its first steps without a traceback, NaN, or a memory
blow-up.** A shipped scenario (a base of the loader fuzz tests) with one to
three hostile edits (:func:`tests.fuzz_strategies.mutated_bases`), or with one
to three dotted keys set to values mostly of their type, the drawn
controller's parameters among them (:func:`tests.fuzz_sweeps.overridden_bases`),
is loaded; if it loads, it is run with a controller drawn from
:data:`RUN_CONTROLLERS` (every registered one) for at most :data:`STEPS` steps
of its ``dt`` (``t_max`` capped on the loaded spec) and a drawn seed. The run
returns a log whose time, pose, estimate, velocity, twist, command, leader and
slot arrays are all finite and whose metrics (:func:`dfcoa_opt.metrics.summary`)
have an outcome of :data:`dfcoa_opt.metrics.outcome.OUTCOMES`; or it raises a
:class:`~dfcoa_opt.core.errors.DfcoaError` (a ScenarioError for a bad controller
parameter or a seed whose world does not load, ``RunFailed`` /
``ControllerError`` for a run that fails cleanly) whose message is one line.
``nmpc`` runs with ``compiled = false`` (casadi's interpreter, the same
numbers): each new horizon would otherwise compile C code, for up to two
minutes, into the user's cache.

Any other exception, a ``RuntimeWarning`` (the bases run with every controller,
and their metrics are computed, without one), or a non-finite number in the log
fails.

Bounded cost. Examples the loader fuzz tests skip as too costly to load
(:func:`tests.fuzz_schema.too_costly`) are skipped here too, and so are scenarios
that load but would be slow to step (:func:`too_slow_to_run`: more than
:data:`ROBOT_CAP` robots, :data:`BEAM_CAP` LiDAR beams x robots,
:data:`PARTICLE_CAP` MCL particles x robots, or an nmpc of more than
:data:`NMPC_CAP` robots x horizon). A run has a ``deadline`` of
:data:`RUN_DEADLINE`. The address space is capped at its size + 4 GiB (the
fixture of the loader fuzz tests), so a missed allocation fails with
MemoryError instead of waking the OOM killer.

Sizes: 150 run examples (about 30 s on one core); ``DFCOA_FUZZ_EXAMPLES=N``
makes that N. ``make test`` runs them derandomized (``tests/conftest.py``);
``DFCOA_HYPOTHESIS=explore`` draws fresh inputs.
"""

from __future__ import annotations

import copy
import dataclasses
from datetime import timedelta
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from dfcoa_opt import metrics
from dfcoa_opt.control.registry import build_controller
from dfcoa_opt.core.errors import DfcoaError, ScenarioError
from dfcoa_opt.metrics.outcome import OUTCOMES
from dfcoa_opt.scenario.loader import apply_overrides, reseed, scenario_from_dict
from dfcoa_opt.scenario.scenario import Scenario
from dfcoa_opt.sim.simulator import Simulator
from tests.fuzz_schema import num, too_costly
from tests.fuzz_strategies import (
    BASES,
    check_outcome,
    event,
    examples,
    mutated_bases,
    one_line,
)
from tests.fuzz_sweeps import TINY, overridden_bases
from tests.test_fuzz_loader import _address_space_cap  # noqa: F401 - the same memory cap

pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")


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
        scenario = reseed(scenario, seed)
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
