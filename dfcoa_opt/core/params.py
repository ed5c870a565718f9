"""Typed, validated construction of frozen dataclasses from plain dicts (TOML).

Every dataclass field may carry metadata made by :func:`param`: a docstring, a
unit and bounds. :func:`build` walks a dict against the dataclass, and each
problem is raised as one :class:`~dfcoa_opt.core.errors.ScenarioError` that names the
file, the dotted key path and the problem (unknown keys get a "did you mean"
hint). The same code validates scenario files, sweep files and per-controller
parameter overrides, and :func:`describe` renders the key reference.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import types
import typing
from collections.abc import Mapping
from typing import Any, Literal, TypeVar, get_args, get_origin, get_type_hints

from dfcoa_opt.core.errors import ScenarioError, did_you_mean

T = TypeVar("T")
_MISSING = dataclasses.MISSING


def param(default: Any = _MISSING, *, doc: str, unit: str = "", ge: float | None = None,
          gt: float | None = None, le: float | None = None, lt: float | None = None,
          finite: bool = True, default_factory: Any = _MISSING,
          tune: tuple[Any, Any] | None = None, scale: str = "linear",
          robot_index: bool = False) -> Any:
    """A dataclass field with documentation and validation metadata.

    Args:
        default: Default value; omit for a required key.
        doc: One-sentence description shown in the key reference.
        unit: SI unit, e.g. ``"m"`` or ``"rad/s"``; empty when dimensionless.
        ge: Inclusive lower bound (numbers, and every number inside tuples).
        gt: Exclusive lower bound.
        le: Inclusive upper bound.
        lt: Exclusive upper bound.
        finite: Reject NaN and infinities (default). ``False`` still rejects NaN.
        default_factory: Factory for mutable defaults.
        tune: ``(low, high)``: the range ``dfcoa tune`` searches for this key (a
            float or int field), or ``(False, True)`` for a boolean one (:func:`tunables`).
        scale: ``"linear"`` or ``"log"`` (low > 0): how the range is searched.
        robot_index: The value is a robot index: it must name one of the scenario's
            ``team.n`` robots (:func:`check_robot_indices`).

    Raises:
        ValueError: A tuning range out of order, or a log scale that reaches 0.
    """
    if tune is not None:
        if scale not in ("linear", "log") or not tune[0] < tune[1]:
            raise ValueError(f"tune={tune!r}, scale={scale!r}: need low < high and a linear or "
                             "log scale")
        if scale == "log" and not tune[0] > 0:
            raise ValueError(f"tune={tune!r}: a log scale needs low > 0")
    meta = {"doc": doc, "unit": unit, "ge": ge, "gt": gt, "le": le, "lt": lt, "finite": finite,
            "tune": tune, "scale": scale, "robot_index": robot_index}
    if default_factory is not _MISSING:
        return dataclasses.field(default_factory=default_factory, metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


def _typename(tp: Any) -> str:
    """Plain-words name of a type annotation (for messages and the key reference)."""
    origin = get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        inner = [a for a in get_args(tp) if a is not type(None)]
        return _typename(inner[0]) + " (optional)"
    if tp is float:
        return "number"
    if tp is int:
        return "integer"
    if tp is bool:
        return "boolean"
    if tp is str:
        return "string"
    if origin is Literal:
        return "one of " + ", ".join(repr(a) for a in get_args(tp))
    if dataclasses.is_dataclass(tp) or origin in (dict, Mapping):
        return "table"
    if origin is tuple:
        args = get_args(tp)
        if len(args) == 2 and args[1] is Ellipsis:
            return f"array of ({_typename(args[0])})"
        return f"array of {len(args)} {_typename(args[0])}s"
    return str(tp)


_INT64_MAX = 2**63 - 1  # the TOML spec's integer range (tomllib accepts more)
#: Largest magnitude of a finite number (a float key): products and squares of two
#: such numbers stay far inside the float range (1.8e308), and nothing physical in
#: SI units here comes near it (lengths stop at 1e6 m:
#: :data:`dfcoa_opt.scenario.budget.MAX_EXTENT`).
MAX_MAGNITUDE = 1e9
#: Smallest value of a key that must be strictly positive (``gt=0``): quotients by it
#: stay finite, and a 5e-324 that underflows to 0 in the first division is refused.
MIN_POSITIVE = 1e-9


def _check_number(x: float, meta: Mapping[str, Any], src: str, key: str,
                  shown: Any = None) -> None:
    """``x`` against the field's bounds; ``shown`` is the value as given (an int stays one)."""
    shown = x if shown is None else shown
    if math.isnan(x):
        raise ScenarioError(src, key, "must be a number, got NaN")
    if meta.get("finite", True) and math.isinf(x):
        raise ScenarioError(src, key, f"must be finite, got {x}")
    for name, ok, word in (("ge", lambda b: x >= b, ">="), ("gt", lambda b: x > b, ">"),
                           ("le", lambda b: x <= b, "<="), ("lt", lambda b: x < b, "<")):
        bound = meta.get(name)
        if bound is not None and not ok(bound):
            raise ScenarioError(src, key, f"must be {word} {bound}, got {shown}")


def _check_magnitude(x: float, meta: Mapping[str, Any], src: str, key: str) -> None:
    """A float within :data:`MAX_MAGNITUDE`; a positive one (``gt=0``) from :data:`MIN_POSITIVE`.

    Infinities, where a key allows them, pass.
    """
    if math.isfinite(x) and abs(x) > MAX_MAGNITUDE:
        raise ScenarioError(src, key, f"must lie within +-{MAX_MAGNITUDE:g} (the range of "
                                      f"every number here), got {x:g}")
    if meta.get("gt") == 0 and x < MIN_POSITIVE:
        raise ScenarioError(src, key, f"must be >= {MIN_POSITIVE:g} (the smallest positive "
                                      f"number here), got {x:g}")


def _convert(value: Any, tp: Any, meta: Mapping[str, Any], src: str, key: str) -> Any:
    """Convert/validate one value against a type annotation."""
    origin = get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in get_args(tp) if a is not type(None)]
        if value is None:
            return None
        return _convert(value, args[0], meta, src, key)
    if tp is Any:
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ScenarioError(src, key,
                                f"must be a number, got {type(value).__name__} {value!r}")
        try:
            value = float(value)
        except OverflowError:
            raise ScenarioError(src, key, f"is beyond the float range, got an integer of "
                                          f"{len(str(abs(value)))} digits") from None
        _check_number(value, meta, src, key)
        _check_magnitude(value, meta, src, key)
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ScenarioError(src, key,
                                f"must be an integer, got {type(value).__name__} {value!r}")
        if abs(value) > _INT64_MAX:
            raise ScenarioError(src, key, f"must fit in 64 bits (TOML integers do), got "
                                          f"{len(str(abs(value)))} digits")
        _check_number(float(value), meta, src, key, value)
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise ScenarioError(src, key, f"must be true or false, got {value!r}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ScenarioError(src, key,
                                f"must be a string, got {type(value).__name__} {value!r}")
        return value
    if origin is Literal:
        choices = get_args(tp)
        if value not in choices:
            hint = did_you_mean(str(value), [str(c) for c in choices])
            raise ScenarioError(src, key, f"must be one of {', '.join(map(repr, choices))}, "
                                          f"got {value!r}{hint}")
        return value
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, Mapping):
            raise ScenarioError(src, key, f"must be a table, got {type(value).__name__}")
        return build(tp, value, src, key)
    if origin in (dict, Mapping):
        if not isinstance(value, Mapping):
            raise ScenarioError(src, key, f"must be a table, got {type(value).__name__}")
        vt = get_args(tp)[1] if get_args(tp) else Any
        return {str(k): _convert(v, vt, meta, src, f"{key}.{k}") for k, v in value.items()}
    if origin is tuple:
        args = get_args(tp)
        if not isinstance(value, (list, tuple)):
            raise ScenarioError(src, key,
                                f"must be an array, got {type(value).__name__} {value!r}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(v, args[0], meta, src, f"{key}[{i}]")
                         for i, v in enumerate(value))
        if len(value) != len(args):
            raise ScenarioError(src, key, f"must have {len(args)} elements, got {len(value)}")
        return tuple(_convert(v, a, meta, src, f"{key}[{i}]")
                     for i, (v, a) in enumerate(zip(value, args, strict=True)))
    raise TypeError(f"unsupported annotation {tp!r} at {key}")  # programming error


def _dataclass_of(tp: Any) -> type | None:
    """The dataclass a field's annotation holds (itself, or inside ``X | None``), else None."""
    if get_origin(tp) in (typing.Union, types.UnionType):
        found = [a for a in get_args(tp) if dataclasses.is_dataclass(a)]
        return found[0] if found else None
    return tp if isinstance(tp, type) and dataclasses.is_dataclass(tp) else None


@functools.cache
def _hints(cls: type) -> dict[str, Any]:
    """``typing.get_type_hints(cls)``, evaluated once a class (read it, never change it).

    Evaluating the string annotations again on every build was most of a
    scenario load's time: 1365 calls for 30 loads.
    """
    return get_type_hints(cls)


def _unknown_keys(cls: type, data: Any, prefix: str) -> typing.Iterator[tuple[str, str]]:
    """Every key of ``data`` (and of its nested tables) that ``cls`` does not have.

    Yields ``(dotted key, did-you-mean hint)``, in the file's order, so that a
    file's unknown keys are reported together, not one per attempt.
    """
    if not isinstance(data, Mapping):
        return
    hints = _hints(cls)
    fields = {f.name for f in dataclasses.fields(cls) if f.init}
    for k, v in data.items():
        key = f"{prefix}.{k}" if prefix else str(k)
        if k not in fields:
            yield key, did_you_mean(str(k), fields)
            continue
        tp = hints[k]
        inner = _dataclass_of(tp)
        if inner is not None:
            yield from _unknown_keys(inner, v, key)
        elif get_origin(tp) in (tuple, list) and isinstance(v, list):
            args = [a for a in get_args(tp) if a is not Ellipsis]
            element = _dataclass_of(args[0]) if len(args) == 1 else None
            if element is not None:
                for i, item in enumerate(v):
                    yield from _unknown_keys(element, item, f"{key}[{i}]")


def build(cls: type[T], data: Mapping[str, Any], src: str, prefix: str = "") -> T:
    """Build dataclass ``cls`` from ``data``, validating every key.

    Args:
        cls: A dataclass whose fields use :func:`param` metadata.
        data: The mapping read from the file.
        src: File name used in error messages.
        prefix: Dotted key path of ``data`` inside the file.

    Raises:
        ScenarioError: On an unknown key, a missing required key, a wrong type,
            NaN/inf or a value out of bounds.
    """
    hints = _hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    unknown = list(_unknown_keys(cls, data, prefix))
    if unknown:
        first, *rest = unknown
        also = "; also unknown: " + ", ".join(f"{k}{hint}" for k, hint in rest) if rest else ""
        raise ScenarioError(src, first[0], f"unknown key{first[1]}{also}")
    kwargs: dict[str, Any] = {}
    for k, v in data.items():
        key = f"{prefix}.{k}" if prefix else str(k)
        kwargs[k] = _convert(v, hints[k], fields[k].metadata, src, key)
    for name, f in fields.items():
        if name not in kwargs and f.default is _MISSING and f.default_factory is _MISSING:
            key = f"{prefix}.{name}" if prefix else name
            raise ScenarioError(src, key, f"is required ({_typename(hints[name])})")
    try:
        obj = cls(**kwargs)
    except (ValueError, TypeError) as exc:
        raise ScenarioError(src, prefix, str(exc)) from None
    check = getattr(obj, "check", None)
    if callable(check):
        check(src, prefix)
    return obj


def check_robot_indices(params: Any, n: int, src: str, prefix: str) -> None:
    """Every ``robot_index`` field of a built ``Params`` names one of the team's ``n`` robots.

    Raises:
        ScenarioError: Naming ``prefix.<field>``: an index ``>= n``.
    """
    for f in dataclasses.fields(params):
        index = getattr(params, f.name)
        if f.metadata.get("robot_index") and index >= n:
            raise ScenarioError(src, f"{prefix}.{f.name}", f"is robot {index}, but the team "
                                                           f"has {n} robot(s) (0..{n - 1}; team.n)")


def build_options(cls: type | None, options: Mapping[str, Any], src: str, key: str,
                  owner: str) -> Any:
    """Options table of a pluggable part (planner, estimator) built against its ``Params``.

    Args:
        cls: The part's ``Params`` dataclass, or None when it takes no options.
        options: The table from the file.
        src: File name for messages.
        key: Key path of the table, e.g. ``leader.planner_options``.
        owner: What takes the options, e.g. ``planner 'astar'``.

    Returns:
        The built dataclass, or None for a part without options.

    Raises:
        ScenarioError: Options given to a part without ``Params``, or a bad key.
    """
    if cls is None:
        if options:
            raise ScenarioError(src, key, f"{owner} takes no options")
        return None
    return build(cls, dict(options), src, key)


def describe(cls: type, prefix: str = "") -> list[tuple[str, str, str, str, str]]:
    """Key reference of a dataclass: rows ``(key, type, default, unit, doc)``.

    Nested dataclasses are expanded; arrays of tables use ``key[]``.
    """
    rows: list[tuple[str, str, str, str, str]] = []
    hints = _hints(cls)
    for f in dataclasses.fields(cls):
        tp = hints[f.name]
        key = f"{prefix}.{f.name}" if prefix else f.name
        inner = get_args(tp)[0] if get_origin(tp) is tuple and get_args(tp) else None
        if dataclasses.is_dataclass(tp):
            rows.extend(describe(tp, key))
            continue
        if inner is not None and dataclasses.is_dataclass(inner):
            rows.append((f"{key}[]", "array of tables", "[]", "", f.metadata.get("doc", "")))
            rows.extend(describe(inner, f"{key}[]"))
            continue
        if f.default is not _MISSING:
            default = repr(f.default)
        elif f.default_factory is not _MISSING:
            default = repr(f.default_factory())
        else:
            default = "required"
        doc = f.metadata.get("doc", "")
        bounds = bounds_text(f.metadata)
        rows.append((key, _typename(tp), default, f.metadata.get("unit", ""),
                     f"{doc} Range: {bounds}." if bounds else doc))
    return rows


def bounds_text(meta: Mapping[str, Any]) -> str:
    """A field's bounds in words, ``">= 1, <= 100000"`` (empty without bounds)."""
    signs = (("ge", ">="), ("gt", ">"), ("le", "<="), ("lt", "<"))
    return ", ".join(f"{sign} {meta[k]:g}" for k, sign in signs if meta.get(k) is not None)


@dataclasses.dataclass(frozen=True)
class Tunable:
    """A parameter that ``dfcoa tune`` searches (declared by ``param(tune=...)``).

    Attributes:
        key: Dotted key below the table that holds it (``k1``, ``vfh.target_weight``).
        low: Smallest value searched.
        high: Largest value searched.
        scale: ``linear`` or ``log``.
        kind: ``float``, ``int`` or ``bool`` (``bool``: the two values, no scale).
        default: The field's default.
        unit: Its unit.
    """

    key: str
    low: Any
    high: Any
    scale: str
    kind: str
    default: Any
    unit: str = ""


def tunables(cls: type, prefix: str = "") -> list[Tunable]:
    """The tunable fields of a ``Params`` dataclass, nested tables included, in field order."""
    out: list[Tunable] = []
    hints = _hints(cls)
    for f in dataclasses.fields(cls):
        key = f"{prefix}{f.name}"
        tp = hints[f.name]
        if dataclasses.is_dataclass(tp):
            out += tunables(tp, key + ".")
            continue
        rng = f.metadata.get("tune")
        if rng is None:
            continue
        args = [a for a in get_args(tp) if a is not type(None)] or [tp]
        kind = {bool: "bool", int: "int", float: "float"}[args[0] if get_origin(tp) else tp]
        default = f.default if f.default is not _MISSING else None
        out.append(Tunable(key, rng[0], rng[1], f.metadata.get("scale", "linear"), kind,
                           default, f.metadata.get("unit", "")))
    return out
