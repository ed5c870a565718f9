"""Strategies and mutations of real scenarios for the loader fuzz tests.

Used by ``tests/test_fuzz_loader.py`` (see its docstring for what is fuzzed and
why some legal but costly examples are skipped). The cost model and the schema's
key names are in :mod:`tests.fuzz_schema`; TOML text in :mod:`tests.fuzz_toml`.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import os
import types
import typing
from collections.abc import Callable
from pathlib import Path
from typing import Any, Literal, get_args, get_origin, get_type_hints

from hypothesis import currently_in_test_context
from hypothesis import event as _event
from hypothesis import strategies as st

from dfcoa_opt.core.errors import ScenarioError
from dfcoa_opt.scenario.scenario import Scenario
from dfcoa_opt.scenario.schema import ScenarioSpec

try:
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]

from tests.fuzz_schema import (
    CONTROLLER_PARAMS,
    ESTIMATOR_PARAMS,
    NAMES,
    PLANNER_PARAMS,
    ROOT,
    SCHEMA_KEYS,
    num,
)

# ----------------------------------------------------------------- strategies
HUGE_INTS = [2**31, 2**53 + 1, 2**63 - 1, 2**63, -(2**63), 2**64, 10**30, 10**400, -(10**400)]
SPECIAL_FLOATS = [math.nan, math.inf, -math.inf, 0.0, -0.0, 5e-324, 1e-300, -1e-9, 1e15,
                  1e300, 1.7976931348623157e308, -1.7976931348623157e308]
INTS = st.one_of(st.integers(-5, 40), st.sampled_from(HUGE_INTS), st.integers())
FLOATS = st.one_of(st.floats(-60, 60), st.sampled_from(SPECIAL_FLOATS), st.floats())
CHARS = st.one_of(st.characters(codec="utf-8"), st.sampled_from("\n\r\t\x00\x7f \"'\\.[]=#{},"))
TEXT = st.text(CHARS, max_size=12)
KEY = st.one_of(st.sampled_from(SCHEMA_KEYS), TEXT)
LEAF = st.one_of(INTS, FLOATS, TEXT, st.sampled_from(NAMES), st.booleans())
ANY = st.recursive(LEAF, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                 st.dictionaries(KEY, inner, max_size=4)),
                   max_leaves=20)
RANDOM_DICTS = st.dictionaries(KEY, ANY, max_size=8)

_STRATS: dict[Any, st.SearchStrategy[Any]] = {}


def typed(tp: Any) -> st.SearchStrategy[Any]:
    """Values mostly of the annotated type (numbers mostly in a plausible range)."""
    origin = get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        return typed(next(a for a in get_args(tp) if a is not type(None)))
    if tp is float:
        return st.one_of(st.floats(0.01, 60), st.floats(0.01, 60), FLOATS, st.integers(0, 40))
    if tp is int:
        return st.one_of(st.integers(0, 8), st.integers(0, 8), INTS)
    if tp is bool:
        return st.booleans()
    if tp is str:
        return st.one_of(st.sampled_from(NAMES), TEXT)
    if origin is Literal:
        return st.one_of(st.sampled_from([str(c) for c in get_args(tp)]), TEXT)
    if dataclasses.is_dataclass(tp):
        return schema_table(tp)
    if origin is tuple:
        args = get_args(tp)
        if len(args) == 2 and args[1] is Ellipsis:
            return st.lists(typed(args[0]), max_size=4)
        return st.tuples(*(typed(a) for a in args)).map(list)
    return ANY


def _field_strategy(cls: type, name: str, tp: Any) -> st.SearchStrategy[Any]:
    if cls is ScenarioSpec and name == "controllers":
        tables = {cid: schema_table(p) for cid, p in CONTROLLER_PARAMS.items()}
        return st.fixed_dictionaries({}, optional=tables)
    if name == "planner_options":
        return schema_table(PLANNER_PARAMS)
    if name == "options":
        return schema_table(ESTIMATOR_PARAMS)
    return typed(tp)


def schema_table(cls: type) -> st.SearchStrategy[dict[str, Any]]:
    """Dicts shaped like dataclass ``cls``: its keys, values mostly of the right type."""
    if cls not in _STRATS:
        hints = get_type_hints(cls)
        required, optional = {}, {}
        for f in dataclasses.fields(cls):
            value = _field_strategy(cls, f.name, hints[f.name])
            value = st.one_of(*[value] * 9, ANY)  # one value in ten is anything at all
            no_default = f.default is dataclasses.MISSING and (
                f.default_factory is dataclasses.MISSING)
            (required if no_default else optional)[f.name] = value
        extra = st.one_of(st.just({}), st.just({}), st.just({}),
                          st.dictionaries(KEY, ANY, min_size=1, max_size=1))
        _STRATS[cls] = st.builds(lambda a, b: {**b, **a},
                                 st.fixed_dictionaries(required, optional=optional), extra)
    return _STRATS[cls]


SHAPED_DICTS = st.deferred(lambda: schema_table(ScenarioSpec))  # short repr in reports

# --------------------------------------------------------------- valid bases
BASE_FILES = [ROOT / "scenarios" / p for p in (
    "example_empty.toml", "example_obstacles.toml", "dfcoa_s2.toml", "bench/clutter.toml",
    "bench/large_20.toml", "paper001/table1_crossing.toml", "paper004/vs_n5_dyn1.toml")]
BASE_FILES.append(ROOT / "tests" / "data" / "bench" / "tiny.toml")

#: A hand-made base for what no scenario file uses: map_ascii, mcl, astar options, ids, force.
ASCII_BASE = """\
name = "fuzz_ascii"
dt = 0.1
t_max = 10.0
seed = 3

[world]
resolution = 2
origin = [0.0, 0.0]
map_ascii = '''
##########
#........#
#..##....#
#........#
#........#
##########
'''

[[world.dynamic_obstacles]]
radius = 0.3
speed = 0.2
waypoints = [[2.0, 1.0], [4.0, 1.0]]
end = "loop"

[robots]
model = "double_integrator"

[team]
n = 2
ids = [7, 9]
placement = "explicit"
poses = [[1.0, 2.2, 0.0], [0.75, 0.75, 0.0]]

[formation]
shape = "polar"
offsets = [[0.5, 1.5], [0.5, -1.5]]

[leader]
start = [1.0, 1.0]
goal = [3.5, 1.5]          # its formation slots at the goal keep clear of the walls
heading = 0.0
planner = "astar"

[leader.planner_options]
inflate = 0.1
smooth = true

[localization]
mode = "mcl"

[localization.options]
particle_limits = [10, 100]

[[disturbances]]
robot = 9
t_start = 1.0
t_end = 2.0
value = [0.1, 0.0]
kind = "force"

[controllers.goto_slot]
kp = 2.0

[sensors]
comm_radius = inf
"""

#: name -> (parsed file, its source name, its folder, its text)
BASES: dict[str, tuple[dict[str, Any], str, Path, str]] = {
    p.stem: (tomllib.loads(p.read_text()), str(p), p.parent, p.read_text()) for p in BASE_FILES}
BASES["fuzz_ascii"] = (tomllib.loads(ASCII_BASE), "fuzz_ascii.toml", ROOT, ASCII_BASE)

NUMBER_FACTORS = [-1, 0, 2, 10, 1000, 0.5, 1e-9, 1e9, 1e300]
MUTANTS = st.one_of(
    st.sampled_from([math.nan, math.inf, -math.inf, 0, 0.0, -0.0, -1, -1.0, -1e-9, 1e-300,
                     5e-324, 1e15, 1e300, 1.7976931348623157e308, 2**31, 2**63 - 1, 2**63,
                     10**400, "", "x", "nan", True, False, [], {}, [0.0, 0.0], [[0.0, 0.0]],
                     [0.0, 0.0, 0.0, 0.0], {"x": 1}]),
    st.floats(-100, 100), st.integers(-10, 100), st.sampled_from(NAMES), TEXT, ANY)


def _nodes(node: Any, path: tuple[Any, ...] = ()) -> list[tuple[tuple[Any, ...], Any]]:
    """Every ``(path, value)`` of a parsed file, the root first; paths hold keys and indices."""
    out = [(path, node)]
    items = node.items() if isinstance(node, dict) else (
        enumerate(node) if isinstance(node, list) else ())
    for k, v in items:
        out.extend(_nodes(v, (*path, k)))
    return out


def _at(data: Any, path: tuple[Any, ...]) -> Any:
    for k in path:
        data = data[k]
    return data


def _unwrap(tp: Any) -> Any:
    if get_origin(tp) in (typing.Union, types.UnionType):
        return next(a for a in get_args(tp) if a is not type(None))
    return tp


def _schema_of(path: tuple[Any, ...]) -> type | None:
    """The dataclass that describes the table at ``path`` of a scenario, or None."""
    cls: Any = ScenarioSpec
    i = 0
    while i < len(path):
        key = path[i]
        if cls is ScenarioSpec and key == "controllers":
            cls = CONTROLLER_PARAMS.get(path[i + 1]) if i + 1 < len(path) else None
            i += 2
            continue
        if cls is None or key not in get_type_hints(cls):
            return None
        tp = _unwrap(get_type_hints(cls)[key])
        if key in ("planner_options", "options"):
            cls, i = (PLANNER_PARAMS if key == "planner_options" else ESTIMATOR_PARAMS), i + 1
        elif dataclasses.is_dataclass(tp):
            cls, i = tp, i + 1
        elif (get_origin(tp) is tuple and dataclasses.is_dataclass(get_args(tp)[0])
              and i + 1 < len(path) and isinstance(path[i + 1], int)):
            cls, i = get_args(tp)[0], i + 2
        else:
            return None
    return cls


def _keys_for(path: tuple[Any, ...]) -> list[str]:
    """The real keys of the table at ``path`` (controller ids for ``controllers``)."""
    if path == ("controllers",):
        return sorted(CONTROLLER_PARAMS)
    cls = _schema_of(path)
    return [f.name for f in dataclasses.fields(cls)] if cls is not None else []


def _value_for(path: tuple[Any, ...], key: Any) -> st.SearchStrategy[Any]:
    """Mutant values for ``key`` of the table at ``path``: plausible ones when the schema
    knows the key, hostile ones always."""
    if path == ("controllers",) and key in CONTROLLER_PARAMS:
        return st.one_of(MUTANTS, schema_table(CONTROLLER_PARAMS[key]))
    cls = _schema_of(path)
    if cls is None or key not in get_type_hints(cls):
        return MUTANTS
    return st.one_of(MUTANTS, _field_strategy(cls, key, get_type_hints(cls)[key]))


EDITS = ["replace", "replace", "delete", "add", "append", "scale"]


def mutate_tree(draw: Any, data: dict[str, Any],
                entry: Callable[[tuple[Any, ...]], st.SearchStrategy[tuple[Any, Any]]],
                value_for: Callable[[tuple[Any, ...], Any], st.SearchStrategy[Any]],
                fresh: Callable[[tuple[Any, ...]], st.SearchStrategy[Any]]) -> None:
    """One random edit of a parsed TOML tree in place (the edit is in Hypothesis's report).

    A value replaced, a key deleted, a key added to a table, an array grown, or a
    number scaled by one of :data:`NUMBER_FACTORS`.

    Args:
        draw: Hypothesis's draw.
        data: The tree.
        entry: A table's path -> the ``(key, value)`` an addition puts there.
        value_for: ``(path of the parent, key)`` -> a replacement value.
        fresh: An array's path -> a new element (besides copies of its own).
    """
    nodes = _nodes(data)
    op = draw(st.sampled_from(EDITS))
    lists = [p for p, v in nodes if isinstance(v, list)]
    numbers = [p for p, v in nodes if num(v) is not None and math.isfinite(num(v))]
    if op == "add":
        path = draw(st.sampled_from([p for p, v in nodes if isinstance(v, dict)]))
        key, value = draw(entry(path))
        _at(data, path)[key] = copy.deepcopy(value)
        return
    if op == "append" and lists:
        path = draw(st.sampled_from(lists))
        seq, new = _at(data, path), fresh(path)
        seq.append(copy.deepcopy(draw(st.one_of(st.sampled_from(seq), new) if seq else new)))
        return
    if op == "scale" and numbers:
        path = draw(st.sampled_from(numbers))
        _at(data, path[:-1])[path[-1]] = _at(data, path) * draw(st.sampled_from(NUMBER_FACTORS))
        return
    path = draw(st.sampled_from([p for p, _ in nodes[1:]]))
    parent, last = _at(data, path[:-1]), path[-1]
    if op == "delete":
        del parent[last]
    else:
        parent[last] = copy.deepcopy(draw(value_for(path[:-1], last)))


@st.composite
def _entry(draw: Any, path: tuple[Any, ...]) -> tuple[Any, Any]:
    """A key of the table at ``path`` of a scenario (a real one, or any) and its value."""
    real = _keys_for(path)
    key = draw(st.one_of(st.sampled_from(real), KEY) if real else KEY)
    return key, draw(_value_for(path, key))


def _mutate(draw: Any, data: dict[str, Any]) -> None:
    """One random edit of a scenario in place (:func:`mutate_tree`)."""
    mutate_tree(draw, data, _entry, _value_for, lambda path: MUTANTS)


@st.composite
def mutated_bases(draw: Any) -> tuple[str, dict[str, Any]]:
    """A valid base scenario (by name) with one to three random edits."""
    return edited(draw, {name: base[0] for name, base in BASES.items()}, _mutate, 1)


def edited(draw: Any, bases: dict[str, dict[str, Any]],
           mutate: Callable[[Any, dict[str, Any]], None],
           least: int) -> tuple[str, dict[str, Any]]:
    """A copy of one of ``bases`` (drawn by name) with ``least`` to three ``mutate`` edits."""
    name = draw(st.sampled_from(sorted(bases)))
    data = copy.deepcopy(bases[name])
    for _ in range(draw(st.integers(least, 3))):
        mutate(draw, data)
    return name, data


# ----------------------------------------------------------------- checks
def check_outcome(call: Any, source: str) -> Scenario | None:
    """Run the loader: a Scenario, or a ScenarioError on one line naming ``source``.

    Any other exception propagates and fails the test.
    """
    try:
        result = call()
    except ScenarioError as exc:
        msg = str(exc)
        section = exc.key.split(".")[0].split("[")[0]
        event(f"ScenarioError at {section if section in SCHEMA_KEYS else '<other>'}")
        assert "\n" not in msg and "\r" not in msg, f"message is not one line: {msg!r}"
        assert msg.startswith(f"{source}: "), f"message does not start with the file: {msg!r}"
        return None
    event("loaded")
    assert isinstance(result, Scenario)
    return result


def parses(text: str) -> dict[str, Any] | None:
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError:
        return None


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
    """The message of ``exc`` is one non-empty line."""
    msg = str(exc)
    assert msg and "\n" not in msg and "\r" not in msg, f"message is not one line: {msg!r}"
