"""TOML text for the loader fuzz tests: a small writer and random (edited) files.

:func:`to_toml` writes the random dicts of :mod:`tests.fuzz_strategies` as valid
TOML (``tomli_w`` is not a dependency); ``TOML_TEXTS`` draws free text,
TOML-like lines, and valid scenario files with lines inserted, deleted or cut.
"""

from __future__ import annotations

import math
from typing import Any

from hypothesis import strategies as st

from tests.fuzz_schema import ARRAY_PATHS, NAMES, SCHEMA_KEYS, TABLE_PATHS
from tests.fuzz_strategies import BASES, CHARS, FLOATS, INTS, TEXT


def toml_string(s: str) -> str:
    """A TOML basic string (control characters and DEL escaped)."""
    out = []
    for ch in s:
        if ch in '"\\':
            out.append("\\" + ch)
        elif ord(ch) < 0x20 or ord(ch) == 0x7F:
            out.append(f"\\u{ord(ch):04X}")
        else:
            out.append(ch)
    return '"' + "".join(out) + '"'


def toml_value(v: Any) -> str:
    """A TOML value on one line (inline tables and arrays)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        return ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
    if isinstance(v, str):
        return toml_string(v)
    if isinstance(v, list):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{toml_string(k)} = {toml_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(f"no TOML for {type(v).__name__}")


def to_toml(data: dict[str, Any]) -> str:
    """A whole TOML document: one ``"key" = value`` line per top-level key."""
    return "".join(f"{toml_string(k)} = {toml_value(v)}\n" for k, v in data.items())


TOML_LITERALS = st.one_of(
    INTS.map(str), FLOATS.map(toml_value), TEXT.map(toml_string), st.sampled_from(NAMES).map(
        toml_string),
    st.sampled_from(["true", "false", "[]", "{}", "[1.0, 2.0]", "[[1.0, 2.0], [3.0, 4.0]]",
                     "1e999", "0x10", "0o7", "1_000", "1979-05-27", "07:32:00", "'lit'",
                     '"""a\nb"""', "'''\n#.\n.#\n'''", "nan", "-inf", "+inf", "-0", "[1, [2]]",
                     '{x = 1}', "", "= 1", "[,]"]))
TOML_LINES = st.one_of(
    st.sampled_from(TABLE_PATHS).map(lambda p: f"[{p}]"),
    st.sampled_from(ARRAY_PATHS).map(lambda p: f"[[{p}]]"),
    st.tuples(st.one_of(st.sampled_from(SCHEMA_KEYS), TEXT.map(toml_string)),
              TOML_LITERALS).map(lambda kv: f"{kv[0]} = {kv[1]}"),
    TEXT)


@st.composite
def edited_texts(draw: Any) -> str:
    """The text of a valid base with one to three lines inserted, deleted, replaced or cut."""
    lines = BASES[draw(st.sampled_from(sorted(BASES)))][3].splitlines()
    for _ in range(draw(st.integers(1, 3))):
        i = draw(st.integers(0, len(lines)))
        op = draw(st.sampled_from(["replace", "insert", "delete", "truncate"]))
        if op == "insert":
            lines.insert(i, draw(TOML_LINES))
        elif i < len(lines):
            if op == "replace":
                lines[i] = draw(TOML_LINES)
            elif op == "delete":
                del lines[i]
            else:
                lines[i] = lines[i][:draw(st.integers(0, len(lines[i])))]
    return "\n".join(lines) + "\n"


TOML_TEXTS = st.one_of(st.text(CHARS, max_size=200),
                       st.lists(TOML_LINES, max_size=25).map("\n".join), edited_texts())
