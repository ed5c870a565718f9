"""Mutations of the shipped sweep files for the fuzz tests of runs and sweeps.

- ``SWEEP_BASES``: every sweep of ``scenarios/sweeps/`` as parsed (``tomllib``).
- :func:`mutated_sweeps`: a shipped sweep with one to three edits at random
  nested paths: a value replaced (wrong type, NaN, inf, 1e308, a huge or
  negative int, a 300-character string, an empty list or table, an unknown
  controller, a glob), a key deleted, a real or unknown key added (sweep keys,
  ladder and rung keys, dotted scenario keys with values of their type), an
  array grown, a number scaled.
- :func:`overridden_bases`: a loader fuzz base with one to three dotted scenario
  keys set to values mostly of their type, as a sweep would set them.
- :func:`small_sweeps`: the same edits on a shipped sweep first cut down to a
  few runs (``tests/data/bench/tiny.toml``, ``goto_slot``, one seed, two values
  per grid key and ladder), for the tests that run ``dfcoa bench``.
- :func:`mirror`: a folder laid out like ``scenarios/`` (symlinks) where a
  mutated sweep can be written as a file and still find its scenarios.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from pathlib import Path
from typing import Any, get_args, get_origin, get_type_hints

from hypothesis import strategies as st

from dfcoa_opt.bench.sweep import MAX_SEEDS, SweepSpec
from dfcoa_opt.control.registry import available
from dfcoa_opt.scenario.schema import ScenarioSpec
from tests.fuzz_schema import CONTROLLER_PARAMS, ROOT
from tests.fuzz_strategies import ANY, KEY, TEXT, _unwrap, edited, mutate_tree, typed

try:
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]

SWEEPS_DIR = ROOT / "scenarios" / "sweeps"
TINY = ROOT / "tests" / "data" / "bench" / "tiny.toml"

#: name -> parsed sweep file
SWEEP_BASES: dict[str, dict[str, Any]] = {
    p.stem: tomllib.loads(p.read_text(encoding="utf-8"))
    for p in sorted(SWEEPS_DIR.glob("*.toml"))}


# ------------------------------------------------------------------- keys
def _dotted(cls: type, prefix: str, out: dict[str, Any]) -> None:
    """Every leaf key of a schema dataclass as a dotted override key -> its type."""
    hints = get_type_hints(cls)
    for f in dataclasses.fields(cls):
        tp = _unwrap(hints[f.name])
        key = f"{prefix}{f.name}"
        if dataclasses.is_dataclass(tp):
            _dotted(tp, key + ".", out)
        elif (get_origin(tp) is tuple and get_args(tp)
              and dataclasses.is_dataclass(get_args(tp)[0])):
            _dotted(get_args(tp)[0], f"{key}[0].", out)
        elif not (cls is ScenarioSpec and f.name == "controllers"):
            out[key] = tp


#: Dotted scenario keys (what a grid, a rung or a variant sets) -> their type.
OVERRIDE_TYPES: dict[str, Any] = {}
_dotted(ScenarioSpec, "", OVERRIDE_TYPES)
for _cid, _params in CONTROLLER_PARAMS.items():
    _dotted(_params, f"controllers.{_cid}.", OVERRIDE_TYPES)
OVERRIDE_KEYS = sorted(OVERRIDE_TYPES)

LADDER_KEYS = ["label", "key", "values", "rungs", "scenarios", "log_x", "variants", "value"]
SWEEP_KEYS = sorted({f.name for f in dataclasses.fields(SweepSpec)} | {"controller"}
                    | set(LADDER_KEYS))
CONTROLLERS = sorted(available())
GLOBS = ["*", "../*.toml", "../example_*.toml", "../bench/tiny_missing.toml", "../bench",
         "../dfcoa_s1.toml", "tuned/*.toml", "/", "", "x" * 300, "../paper001/*.toml"]

# ------------------------------------------------------------------- values
BIG = [10**5, MAX_SEEDS + 1, 10**6, 10**8, 2**63 - 1, 2**63, 10**30]
SWEEP_MUTANTS = st.one_of(
    st.sampled_from([math.nan, math.inf, -math.inf, 1e308, -1e308, 1.7976931348623157e308,
                     5e-324, 0, 0.0, -0.0, -1, 1, 2, 3, *BIG, "", "x" * 300, "*", True, False,
                     [], {}, [[]], [{}], [math.nan], [math.inf], [1e308], [10**8], [""],
                     ["x" * 300], ["*"], ["goto_slot"], ["goto_slott"], ["nmpc+cbf"],
                     {"controller": "goto_slot"}, {"controller": "goto_slott"},
                     {"controller": ""}, {"key": "team.n", "values": [2, 3]},
                     {"label": "x", "rungs": []}, {"value": 1.0}]),
    st.sampled_from(GLOBS), st.sampled_from(GLOBS).map(lambda g: [g]),
    st.sampled_from(CONTROLLERS), st.sampled_from(SWEEP_KEYS), st.sampled_from(OVERRIDE_KEYS),
    st.integers(-3, 50), st.floats(-10, 10), TEXT, ANY)
#: What a plugin list may name: nothing that exists (no module is imported by the fuzzer).
PLUGIN_MUTANTS = st.sampled_from(["dfcoa_fuzz_no_such_module", "no_such_plugin.py", "", "..",
                                  "/", "x" * 300, "a.b.c.d", ".hidden", 1, math.nan, [], {}])
SWEEP_KEY = st.one_of(st.sampled_from(SWEEP_KEYS), st.sampled_from(OVERRIDE_KEYS), KEY)


def override_values(key: Any) -> st.SearchStrategy[Any]:
    """One value for a dotted scenario key: of its type (mostly), or anything."""
    tp = OVERRIDE_TYPES.get(key) if isinstance(key, str) else None
    return st.one_of(typed(tp), SWEEP_MUTANTS) if tp is not None else SWEEP_MUTANTS


@st.composite
def _entry(draw: Any, path: tuple[Any, ...]) -> tuple[Any, Any]:
    """A key and value to add to the table at ``path`` of a sweep."""
    if path and path[0] == "plugins":
        return draw(SWEEP_KEY), draw(PLUGIN_MUTANTS)
    in_overrides = any(p in ("grid", "variants", "rungs") for p in path if isinstance(p, str))
    key = draw(st.one_of(st.sampled_from(OVERRIDE_KEYS), SWEEP_KEY) if in_overrides
               else SWEEP_KEY)
    if key == "plugins":
        return key, draw(_value_for(path, key))
    if path == ("grid",):
        return key, draw(st.one_of(st.lists(override_values(key), max_size=3), SWEEP_MUTANTS))
    return key, draw(override_values(key))


def _value_for(path: tuple[Any, ...], key: Any) -> st.SearchStrategy[Any]:
    """Mutant values for ``key`` of the table or array at ``path``."""
    if "plugins" in path or key == "plugins":
        return st.one_of(PLUGIN_MUTANTS, PLUGIN_MUTANTS.map(lambda p: [p]))
    dotted = key if isinstance(key, str) else (path[-1] if path else None)
    if path == ("grid",):
        return st.one_of(st.lists(override_values(dotted), max_size=3), SWEEP_MUTANTS)
    return override_values(dotted)


def mutate_sweep(draw: Any, data: dict[str, Any]) -> None:
    """One random edit of a sweep dict in place (:func:`~tests.fuzz_strategies.mutate_tree`)."""
    mutate_tree(draw, data, _entry, _value_for,
                lambda path: _value_for(path, path[-1] if path else None))


@st.composite
def mutated_sweeps(draw: Any) -> tuple[str, dict[str, Any]]:
    """A shipped sweep (by name) with one to three random edits."""
    return edited(draw, SWEEP_BASES, mutate_sweep, 1)


# ------------------------------------------------- scenarios with overrides
@st.composite
def overridden_bases(draw: Any, controller: str = "") -> tuple[str, dict[str, Any],
                                                                dict[str, Any]]:
    """A loader fuzz base (:data:`tests.fuzz_strategies.BASES`) with one to three dotted keys
    set, as a sweep's grid, rung or variant sets them: mostly values of the key's type
    (plausible numbers), sometimes anything; the parameters of ``controller``'s parts
    (``"goto_slot+cbf"``: goto_slot's and cbf's) are drawn as often as the other keys.

    Returns ``(base name, data, overrides)``; the overrides are not applied yet
    (:func:`~dfcoa_opt.scenario.loader.apply_overrides` refuses an index beyond an array).
    """
    from tests.fuzz_strategies import BASES

    name = draw(st.sampled_from(sorted(BASES)))
    data = copy.deepcopy(BASES[name][0])
    own = [k for k in OVERRIDE_KEYS
           if k.startswith(tuple(f"controllers.{p}." for p in controller.split("+") if p))]
    keys = st.one_of(st.sampled_from(own), st.sampled_from(OVERRIDE_KEYS)) if own else (
        st.sampled_from(OVERRIDE_KEYS))
    overrides = draw(st.dictionaries(keys, st.just(None), min_size=1, max_size=3))
    return name, data, {k: draw(override_values(k)) for k in overrides}


# ----------------------------------------------------------- small sweeps
def _first(seq: Any, k: int) -> Any:
    return seq[:k] if isinstance(seq, list) else seq


def small(data: dict[str, Any]) -> dict[str, Any]:
    """A shipped sweep cut down to a few runs of ``goto_slot`` on ``tiny.toml`` (a copy).

    Its scenarios (and each ``[[ladder]]``'s) become ``tiny.toml``, its controllers
    ``goto_slot``, one seed from 0; ``max_seeds``, ``variant_seeds``, ``variant_files``,
    ``split`` and ``[tune]`` go; one named variant, two values per grid key and two
    rungs per ladder (the first ladder of an array) stay.
    """
    out = copy.deepcopy(data)
    for key in ("max_seeds", "max_half_width", "decide_at", "variant_seeds", "variant_files",
                "split", "first_seed", "tune", "plugins"):
        out.pop(key, None)
    out["scenarios"] = [TINY.as_posix()]
    out["controllers"] = ["goto_slot"]
    out["seeds"] = 1
    if isinstance(out.get("variants"), dict):
        out["variants"] = dict(list(out["variants"].items())[:1])
    grid = out.get("grid")
    if isinstance(grid, dict):
        out["grid"] = {k: _first(v, 2) for k, v in grid.items()}
    ladders = out.get("ladder")
    if isinstance(ladders, list):
        ladders = out["ladder"] = ladders[:1]
    for lad in ladders if isinstance(ladders, list) else [ladders] if ladders else []:
        if isinstance(lad, dict):
            for key in ("values", "rungs"):
                if key in lad:
                    lad[key] = _first(lad[key], 2)
            lad.pop("variants", None)
            if isinstance(ladders, list):
                lad["scenarios"] = [TINY.as_posix()]
    names = {"goto_slot", *(out.get("variants") or {})}
    if out.get("baseline") not in names:
        out.pop("baseline", None)
    return out


SMALL_BASES = {name: small(data) for name, data in SWEEP_BASES.items()}


@st.composite
def small_sweeps(draw: Any) -> tuple[str, dict[str, Any]]:
    """A cut-down shipped sweep (:func:`small`) with zero to three random edits."""
    return edited(draw, SMALL_BASES, mutate_sweep, 0)


# ----------------------------------------------------------------- files
def mirror(folder: Path) -> Path:
    """``folder`` laid out like ``scenarios/``: a symlink to each entry, ``sweeps/`` real.

    A sweep written to the returned ``folder/sweeps`` resolves its relative
    patterns (``../bench/*.toml``, ``tuned/*.toml``) to the shipped files.
    """
    scen = ROOT / "scenarios"
    for entry in scen.iterdir():
        if entry.name != "sweeps":
            (folder / entry.name).symlink_to(entry, target_is_directory=entry.is_dir())
    sweeps = folder / "sweeps"
    sweeps.mkdir()
    (sweeps / "tuned").symlink_to(SWEEPS_DIR / "tuned", target_is_directory=True)
    return sweeps


def snapshot(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder``: relative path -> bytes (``tests/test_sweep_atomic.py``)."""
    return {p.relative_to(folder).as_posix(): p.read_bytes()
            for p in sorted(folder.rglob("*")) if p.is_file()}
