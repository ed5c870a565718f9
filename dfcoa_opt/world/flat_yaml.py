"""The flat YAML of ROS map_server files: one ``key: value`` a line, read without a library.

map_server's YAML files (nav2's ``map_saver`` writes them) are flat: scalars and
lists of numbers, one key a line. This reader accepts that subset and refuses
everything else with a one-line :class:`~dfcoa_opt.core.errors.ScenarioError` that
names the file and the key (or the line), so no YAML library is needed.
"""

from __future__ import annotations

import math
import re
from typing import Any

from dfcoa_opt.core.errors import ScenarioError

_KEY = re.compile(r"^([A-Za-z_][A-Za-z0-9_]*)[ \t]*:(?:[ \t]+(.*))?$")
_INT = re.compile(r"^[-+]?[0-9]+$")
_FLOAT = re.compile(r"^[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?$")
_SPECIAL = {".inf": math.inf, "+.inf": math.inf, "-.inf": -math.inf, ".nan": math.nan}


def parse_flat_yaml(text: str, source: str) -> dict[str, Any]:
    """Parse the flat YAML subset of map_server files: one ``key: value`` a line.

    Accepted: comments (``#`` at the start or after a space), blank lines, one
    leading ``---``, plain or quoted scalars, and flow lists ``[a, b, c]`` of
    scalars. Plain scalars become ints, floats (``.inf``/``.nan`` too),
    ``True``/``False`` (``true``/``false`` in any case) or strings; quoted ones
    stay strings.

    Args:
        text: The file's contents.
        source: The file's name, for error messages.

    Raises:
        ScenarioError: Nesting, block scalars, anchors, tags, a second document, a
            duplicate key or a malformed line; the key (or ``line N``) is named.
    """
    out: dict[str, Any] = {}
    started = False
    for number, raw in enumerate(text.splitlines(), 1):
        line = _strip_comment(raw, source, number).rstrip()
        if not line:
            continue
        where = f"line {number}"
        if line == "---" and not (out or started):
            started = True  # the start of the (only) document
            continue
        if line in ("---", "..."):
            raise ScenarioError(source, where, f"'{line}': one YAML document is supported, "
                                               "with at most a leading '---'")
        if line[0] in " \t-":
            raise ScenarioError(source, where, "nested values and lists of lines are not "
                                               "supported: a map_server YAML is flat key: value "
                                               "lines")
        m = _KEY.match(line)
        if m is None:
            raise ScenarioError(source, where, f"expected 'key: value', got {line.strip()!r}")
        key, value = m.group(1), (m.group(2) or "").strip()
        if key in out:
            raise ScenarioError(source, key, f"duplicate key ({where})")
        if not value:
            raise ScenarioError(source, key, f"has no value ({where}); nested maps are not "
                                             "supported")
        out[key] = _value(value, source, key)
    return out


def _strip_comment(line: str, source: str, number: int) -> str:
    """``line`` without its ``# comment`` (a ``#`` inside quotes is text)."""
    quote = ""
    for i, c in enumerate(line):
        if quote:
            quote = "" if c == quote else quote
        elif c in "\"'":
            quote = c
        elif c == "#" and (i == 0 or line[i - 1] in " \t"):
            return line[:i]
    if quote:
        raise ScenarioError(source, f"line {number}", "unterminated quoted string")
    return line


def _value(text: str, source: str, key: str) -> Any:
    """A value: a flow list ``[a, b]`` or a scalar."""
    if text.startswith("["):
        if not text.endswith("]"):
            raise ScenarioError(source, key, f"unterminated list {text!r}")
        inner = text[1:-1].strip()
        items = [s.strip() for s in inner.split(",")] if inner else []
        if any(not s or s[0] in "[{" for s in items):
            raise ScenarioError(source, key, f"expected a flat list of numbers, got {text!r}")
        return [_scalar(s, source, key) for s in items]
    return _scalar(text, source, key)


def _scalar(text: str, source: str, key: str) -> Any:
    """A plain or quoted scalar."""
    if text[0] in "\"'":
        if len(text) < 2 or text[-1] != text[0] or text[0] in text[1:-1]:
            raise ScenarioError(source, key, f"unsupported quoting in {text!r}")
        return text[1:-1]
    if text[0] in "{&*!|>%@`":
        raise ScenarioError(source, key, f"unsupported YAML {text!r} (flow maps, anchors, "
                                         "aliases, tags and block scalars are not supported)")
    if ": " in text or text.endswith(":"):
        raise ScenarioError(source, key, f"unexpected ':' in {text!r} (quote the value, or "
                                         "nested maps are not supported)")
    if _INT.match(text):
        return int(text)
    if _FLOAT.match(text):
        return float(text)
    if text.lower() in _SPECIAL:
        return _SPECIAL[text.lower()]
    if text.lower() in ("true", "false"):
        return text.lower() == "true"
    return text
