"""Hypothesis fuzzing of the scenario loader (:mod:`dfcoa_opt.scenario.loader`).

Whatever a scenario dict or file holds, the loader returns a
:class:`~dfcoa_opt.scenario.scenario.Scenario` or raises
:class:`~dfcoa_opt.core.errors.ScenarioError` whose text is one line starting with
``"<file>: "``; no other exception may escape (the CLI prints a ScenarioError
as it is and exits with code 2, anything else is a traceback).

Inputs: random nested dicts (generic, and shaped like the schema so the fuzzer
gets past the first key), mutations of real valid scenarios, random TOML text
and bytes, and random dicts serialised to valid TOML.

Bounded cost. Some legal values make the loader build huge worlds: a map of
``size * resolution`` cells, ``team.n`` robots on a v/line/grid, a clutter
field of many tiny discs, an improved-A* ``window`` of many cells. Examples
that would build such a world *and* could take long are skipped with
``assume`` (:func:`tests.fuzz_schema.too_costly`): more than ``CELL_CAP`` cells, more than
``N_CAP`` robots, more than ``DISC_CAP`` expected clutter discs (or
``DISC_CELLS_CAP`` discs x cells), a window of more than ``WINDOW_CAP``
cells. Values so absurd that numpy refuses them at once (``>= FAST_FAIL``, or
overflowing to inf) are *not* skipped: the loader must turn them into a
ScenarioError. The skipped middle band is legal but slow (the loader bounds a map
to 1e8 cells and a team to 1e5 robots, far above what a test can build).
As a safety net for a shared machine, the module caps the process's
address space at its current size + 4 GiB while it runs, so an allocation
the cost model misses fails with MemoryError (a test failure) instead of
waking the OOM killer.

Randomness: ``make test`` runs every hypothesis test derandomized (the
``repro`` profile of ``tests/conftest.py``), so a result is reproducible;
``DFCOA_HYPOTHESIS=explore`` searches new inputs on every run (see
``docs/robustness.md``).
"""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from dfcoa_opt.scenario.loader import load_scenario, scenario_from_dict
from dfcoa_opt.scenario.scenario import Scenario
from tests.fuzz_schema import too_costly
from tests.fuzz_strategies import (
    BASES,
    RANDOM_DICTS,
    SHAPED_DICTS,
    check_outcome,
    mutated_bases,
    parses,
)
from tests.fuzz_toml import TOML_TEXTS, to_toml

# an overflow or invalid value inside the loader is a bug even when it raises nothing
pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")

@pytest.fixture(scope="module", autouse=True)
def _address_space_cap():
    """Cap the address space at its current size + 4 GiB while this module runs."""
    try:
        import resource

        status = Path("/proc/self/status").read_text()
    except (ImportError, OSError):
        yield
        return
    vm = next((int(ln.split()[1]) * 1024 for ln in status.splitlines()
               if ln.startswith("VmSize:")), None)
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    if vm is None or soft != resource.RLIM_INFINITY:
        yield
        return
    cap = vm + 4 * 2**30
    if hard != resource.RLIM_INFINITY:
        cap = min(cap, hard)
    resource.setrlimit(resource.RLIMIT_AS, (cap, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))


@pytest.fixture(scope="module")
def fuzz_file(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("fuzz_loader") / "fuzz.toml"


# ------------------------------------------------------------------- tests
@pytest.mark.parametrize("name", sorted(BASES))
def test_bases_load(name: str):
    """Every base of the mutation tests is valid, so mutations start from a loading scenario."""
    data, source, folder, _ = BASES[name]
    assert isinstance(scenario_from_dict(copy.deepcopy(data), source, folder), Scenario)
    assert not too_costly(data)


@settings(max_examples=200, deadline=None)
@given(data=RANDOM_DICTS)
def test_random_nested_dicts(data: dict[str, Any]):
    """Random nested dicts (keys: random text or schema key names; leaves: any TOML scalar,
    huge ints, nan/inf) give a Scenario or a one-line ScenarioError naming the source."""
    assume(not too_costly(data))
    check_outcome(lambda: scenario_from_dict(data, "fuzz.toml"), "fuzz.toml")


@settings(max_examples=200, deadline=None)
@given(data=SHAPED_DICTS)
def test_schema_shaped_dicts(data: dict[str, Any]):
    """Dicts shaped like the schema (every section, every key, values mostly of the right
    type, one in ten anything) give a Scenario or a one-line ScenarioError."""
    assume(not too_costly(data))
    check_outcome(lambda: scenario_from_dict(data, "fuzz.toml"), "fuzz.toml")


@settings(max_examples=2500, deadline=None)
@given(case=mutated_bases())
def test_mutated_valid_scenarios(case: tuple[str, dict[str, Any]]):
    """Valid scenarios with one to three random edits (a value replaced by a wrong type, nan,
    inf, a negative, zero, huge or empty value; a key deleted; an unknown or misplaced key
    added; an array grown; a number scaled) give a Scenario or a one-line ScenarioError
    naming the file."""
    name, data = case
    assume(not too_costly(data))
    _, source, folder, _ = BASES[name]
    check_outcome(lambda: scenario_from_dict(data, source, folder), source)


@settings(max_examples=250, deadline=None)
@given(text=TOML_TEXTS)
def test_random_toml_text(fuzz_file: Path, text: str):
    """Random text (free text, TOML-like lines, valid files with edited lines) written to a
    file: load_scenario gives a Scenario or a one-line ScenarioError naming the file."""
    parsed = parses(text)
    assume(parsed is None or not too_costly(parsed))
    fuzz_file.write_text(text, encoding="utf-8")
    check_outcome(lambda: load_scenario(fuzz_file), str(fuzz_file))


@settings(max_examples=100, deadline=None)
@given(blob=st.one_of(st.binary(max_size=200),
                      st.sampled_from([b[3] for b in BASES.values()]).map(str.encode).flatmap(
                          lambda b: st.integers(0, len(b)).map(lambda i: b[:i] + b"\xff"))))
def test_random_bytes(fuzz_file: Path, blob: bytes):
    """Random bytes (and valid files cut short by an invalid UTF-8 byte) written to a file:
    only a one-line ScenarioError naming the file, or a Scenario."""
    parsed = parses(blob.decode("utf-8", errors="replace"))
    assume(parsed is None or not too_costly(parsed))
    fuzz_file.write_bytes(blob)
    check_outcome(lambda: load_scenario(fuzz_file), str(fuzz_file))


@settings(max_examples=150, deadline=None)
@given(data=st.one_of(RANDOM_DICTS, SHAPED_DICTS, mutated_bases().map(lambda c: c[1])))
def test_serialised_dicts_as_toml(fuzz_file: Path, data: dict[str, Any]):
    """Random, schema-shaped and mutated dicts written as valid TOML and loaded from the file:
    a Scenario or a one-line ScenarioError naming the file."""
    text = to_toml(data)
    assert parses(text) is not None, "the test's TOML writer made invalid TOML"
    assume(not too_costly(data))
    fuzz_file.write_text(text, encoding="utf-8")
    check_outcome(lambda: load_scenario(fuzz_file), str(fuzz_file))
