"""Named variants and difficulty ladders of a sweep file.

A *variant* is one method configuration: a controller id and the parameter
overrides it runs with, under a readable name that every table, legend and file
name uses (never a hash). A sweep gets its variants from:

- ``controllers = [...]``: each id is a variant named by the id;
- ``[variants]``, a table of named variants (``name = { controller = ..., ... }``)::

      [variants.dfcoa_compensated]
      controller = "dfcoa"
      "controllers.dfcoa.compensate_tracking_offset" = true

- ``[grid]``: every variant runs with every combination of the grid's values;
  a grid key with several values that reaches a variant adds ``[key=value]`` to
  its name (the key's last part when that is unambiguous);
- ``[[variants]]`` (an array of override sets, the older form): every set runs
  with every controller, named like a grid point.

A *ladder* grades one scenario dimension from easy to hard. Each rung is a
value (the x axis of the ladder's figure) and the overrides that make it::

    [ladder]
    label = "clutter density"
    key = "world.clutter.density"          # one key per rung ...
    values = [0.02, 0.04, 0.08, 0.12]

    [[ladder.rungs]]                       # ... or rungs that set several keys
    value = 4.0
    "world.obstacles[0].max" = [11.5, 5.0]
    "world.obstacles[1].min" = [10.0, 9.0]

``[[ladder]]`` (an array) gives several ladders in one sweep, each on its own
``scenarios``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from dfcoa_opt.core.errors import ScenarioError, did_you_mean
from dfcoa_opt.scenario.overrides import flatten

#: Characters a variant name may hold (it becomes part of file names).
_NAME_CHARS = set("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_+-.=[],@")


@dataclass(frozen=True)
class Variant:
    """One method configuration of a sweep.

    Attributes:
        name: Readable unique name (tables, legends, file names).
        controller: Controller id (``"<controller>+<filter>"`` allowed).
        overrides: Dotted-key overrides of this variant (controller parameters or
            scenario keys), before the grid.
    """

    name: str
    controller: str
    overrides: tuple[tuple[str, Any], ...] = ()


@dataclass(frozen=True)
class Rung:
    """One step of a ladder: its value and the overrides that make it."""

    value: float
    overrides: tuple[tuple[str, Any], ...]


@dataclass(frozen=True)
class Ladder:
    """A difficulty ladder.

    Attributes:
        label: Axis label and the ladder's name in rows (``ladder``).
        rungs: The rungs, easy to hard as written.
        scenarios: Scenario files or globs (array form); empty: the sweep's scenarios.
        log_x: Draw the value axis on a log scale.
        variants: Names of the sweep's variants that climb it; empty: all of them.
    """

    label: str
    rungs: tuple[Rung, ...]
    scenarios: tuple[str, ...] = ()
    log_x: bool = False
    variants: tuple[str, ...] = ()


class _Table(dict):
    """A table inside an override's array (``"world.obstacles" = [{...}]``), made hashable.

    Its values are frozen (:func:`_freeze`) and it is never changed after it is
    made; it stays a dict, so JSON writes it as the table it was.
    """

    def __hash__(self) -> int:  # type: ignore[override]
        return hash(frozenset(self.items()))


def _freeze(value: Any) -> Any:
    """A hashable form of an override value: arrays become tuples, tables :class:`_Table`."""
    if isinstance(value, (list, tuple)):
        return tuple(_freeze(x) for x in value)
    if isinstance(value, Mapping):
        return _Table({k: _freeze(x) for k, x in value.items()})
    return value


def _items(mapping: Mapping[str, Any]) -> tuple[tuple[str, Any], ...]:
    """Sorted, hashable items of an override mapping (:func:`_freeze` of each value)."""
    return tuple(sorted((str(k), _freeze(v)) for k, v in mapping.items()))


def json_problem(value: Any) -> str | None:
    """Why a value cannot go in a result row (JSON); None if it can.

    A row records its run's overrides and rung, and JSON holds no NaN, no
    infinity and no TOML date or time.
    """
    if isinstance(value, float) and not math.isfinite(value):
        return (f"must be finite, got {value}: a result row is JSON, which holds no NaN or "
                "inf (for no limit, use a large number such as 1e9)")
    if isinstance(value, (list, tuple)):
        return next((p for p in map(json_problem, value) if p), None)
    if isinstance(value, Mapping):
        return next((p for p in map(json_problem, value.values()) if p), None)
    if value is None or isinstance(value, (str, int, float)):
        return None
    return (f"must be a number, string, boolean, array or table, got {type(value).__name__} "
            f"{value!r}: a result row is JSON")


def check_value(value: Any, src: str, key: str) -> None:
    """Refuse an override a result row cannot hold (:func:`json_problem`).

    Raises:
        ScenarioError: One line naming ``src`` and ``key``.
    """
    problem = json_problem(value)
    if problem:
        raise ScenarioError(src, key, problem)


def _check_name(name: str, src: str, key: str) -> None:
    if not name or not set(name) <= _NAME_CHARS:
        raise ScenarioError(src, key, f"variant name '{name}' must be non-empty and use only "
                                      "letters, digits and _ + - . = [ ] , @")


def named_variants(table: Mapping[str, Any], src: str) -> list[Variant]:
    """The ``[variants]`` table: name -> ``{controller = id, dotted key = value, ...}``.

    Args:
        table: The table as read.
        src: Sweep file for messages.

    Raises:
        ScenarioError: A variant that is not a table, lacks ``controller`` or has a bad name.
    """
    out = []
    for name, body in table.items():
        key = f"variants.{name}"
        _check_name(str(name), src, key)
        if not isinstance(body, Mapping):
            raise ScenarioError(src, key, "must be a table: { controller = \"<id>\", "
                                          "\"<dotted key>\" = value, ... }")
        body = dict(body)
        cid = body.pop("controller", None)
        if not isinstance(cid, str) or not cid:
            raise ScenarioError(src, f"{key}.controller", "is required (a controller id)")
        overrides = flatten(body)
        for k, x in overrides.items():
            check_value(x, src, f"{key}.{k}")
        out.append(Variant(str(name), cid, _items(overrides)))
    return out


def _short_keys(keys: Sequence[str]) -> dict[str, str]:
    """Each dotted key's last part, or the whole key where the last parts collide."""
    last = [k.rsplit(".", 1)[-1] for k in keys]
    return {k: (s if last.count(s) == 1 else k) for k, s in zip(keys, last, strict=True)}


def _value_text(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return f"{v:g}"  # 6 significant digits; two values that print alike are an error
    if isinstance(v, (int, str)):
        return str(v)
    return json.dumps(v, separators=(",", ""))


def suffix(point: Mapping[str, Any], varying: Sequence[str]) -> str:
    """``"[kp=0.5,density=0.08]"`` for the ``varying`` keys set in ``point``; ``""`` if none."""
    keys = [k for k in varying if k in point]
    if not keys:
        return ""
    short = _short_keys(list(varying))
    return "[" + ",".join(f"{short[k]}={_value_text(point[k])}" for k in keys) + "]"


def reaches(key: str, controller: str) -> bool:
    """Whether a dotted override reaches a controller (``controllers.<id>.*`` only its own)."""
    return not key.startswith("controllers.") or key.split(".")[1] in controller.split("+")


def parse_ladders(value: Any, src: str) -> list[Ladder]:
    """``[ladder]`` (one table) or ``[[ladder]]`` (an array of tables).

    Raises:
        ScenarioError: A ladder without values or rungs, with both, or with a bad rung.
    """
    if value is None:
        return []
    if isinstance(value, Mapping):
        return [_ladder(value, src, "ladder", single=True)]
    if isinstance(value, list) and value and all(isinstance(v, Mapping) for v in value):
        return [_ladder(v, src, f"ladder[{i}]", single=False)
                for i, v in enumerate(value)]
    raise ScenarioError(src, "ladder", "must be a table ([ladder]) or an array of tables "
                                       "([[ladder]])")


_LADDER_KEYS = ("label", "key", "values", "rungs", "scenarios", "log_x", "variants")


def _ladder(data: Mapping[str, Any], src: str, where: str,
            single: bool) -> Ladder:
    for k in data:
        if k not in _LADDER_KEYS:
            raise ScenarioError(src, f"{where}.{k}", "unknown key; a ladder has "
                                                     + ", ".join(_LADDER_KEYS))
    key, values, rungs = data.get("key"), data.get("values"), data.get("rungs")
    if (rungs is None) == (values is None):
        raise ScenarioError(src, where, "needs either key and values, or [[rungs]]")
    out: list[Rung] = []
    if values is not None:
        if not isinstance(key, str) or not key:
            raise ScenarioError(src, f"{where}.key", "is required with values (a dotted "
                                                     "scenario key)")
        if not isinstance(values, list) or not values:
            raise ScenarioError(src, f"{where}.values", "must be a non-empty array of numbers")
        for i, v in enumerate(values):
            out.append(Rung(_number(v, src, f"{where}.values[{i}]"), ((key, v),)))
    else:
        if not isinstance(rungs, list) or not rungs:
            raise ScenarioError(src, f"{where}.rungs", "must be a non-empty array of tables")
        for i, r in enumerate(rungs):
            if not isinstance(r, Mapping) or "value" not in r:
                raise ScenarioError(src, f"{where}.rungs[{i}].value", "is required (a number)")
            body = dict(r)
            v = _number(body.pop("value"), src, f"{where}.rungs[{i}].value")
            if not body:
                raise ScenarioError(src, f"{where}.rungs[{i}]", "sets no scenario key")
            overrides = flatten(body)
            for k, x in overrides.items():
                check_value(x, src, f"{where}.rungs[{i}].{k}")
            out.append(Rung(v, _items(overrides)))
    scenarios = _patterns(data.get("scenarios", []), src, f"{where}.scenarios")
    if single and scenarios:
        raise ScenarioError(src, f"{where}.scenarios", "only the array form [[ladder]] names "
                                                       "its own scenarios")
    if not single and not scenarios:
        raise ScenarioError(src, f"{where}.scenarios", "is required in [[ladder]]")
    if len({r.value for r in out}) != len(out):
        raise ScenarioError(src, where, "two rungs have the same value")
    label = data.get("label", key if isinstance(key, str) else "")
    if not isinstance(label, str) or not label:
        raise ScenarioError(src, f"{where}.label", "is required with rungs (the axis label)")
    names = data.get("variants", [])
    if not isinstance(names, list) or not all(isinstance(x, str) and x for x in names):
        raise ScenarioError(src, f"{where}.variants", "must be an array of variant names")
    log_x = data.get("log_x", False)
    if not isinstance(log_x, bool):
        raise ScenarioError(src, f"{where}.log_x", f"must be true or false, got {log_x!r}")
    return Ladder(label, tuple(out), scenarios, log_x, tuple(names))


def _patterns(value: Any, src: str, key: str) -> tuple[str, ...]:
    """A ladder's ``scenarios``: an array of file names or globs, as the sweep's own.

    Raises:
        ScenarioError: Naming ``key``: not an array, or an entry that is not a string.
    """
    if not isinstance(value, (list, tuple)):
        raise ScenarioError(src, key, f"must be an array, got {type(value).__name__} {value!r}")
    for i, x in enumerate(value):
        if not isinstance(x, str):
            raise ScenarioError(src, f"{key}[{i}]",
                                f"must be a string, got {type(x).__name__} {x!r}")
    return tuple(value)


def _number(v: Any, src: str, key: str) -> float:
    """A rung's value: a finite number (the x axis of the ladder, and a row's ``ladder_value``)."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ScenarioError(src, key, f"must be a number, got {v!r}")
    try:
        value = float(v)
    except OverflowError:
        raise ScenarioError(src, key, "is beyond the float range") from None
    if not math.isfinite(value):
        raise ScenarioError(src, key, f"must be a finite number, got {value}: a result row "
                                      "is JSON, which holds no NaN or inf")
    return value


def ladder_variants(ladders: Sequence[Ladder], variants: Sequence[Variant],
              src: str) -> dict[Ladder | None, list[Variant]]:
    """The variants of each ladder that names them (``[[ladder]] variants``)."""
    out: dict[Ladder | None, list[Variant]] = {}
    names = [v.name for v in variants]
    for i, lad in enumerate(ladders):
        if lad.variants:
            for name in lad.variants:
                if name not in names:
                    raise ScenarioError(src, f"ladder[{i}].variants", f"'{name}' is not a "
                                        "variant of this sweep" + did_you_mean(name, names))
            out[lad] = [v for v in variants if v.name in lad.variants]
    return out
