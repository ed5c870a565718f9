"""Dotted keys of a scenario file: reading the file, setting keys, flattening tables.

A scenario or sweep key is written dotted (``world.clutter.density``,
``world.obstacles[0].radius`` for an array of tables, ``controllers.<id>.<param>``).
:func:`read_toml` reads a file with one-line errors, :func:`apply_overrides` sets
dotted keys in its contents before validation, and :func:`flatten` turns nested
tables back into dotted keys (a sweep's ``[grid]``, variants and ladder rungs).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from dfcoa_opt.core.errors import ScenarioError

_INDEX = re.compile(r"^([A-Za-z_][A-Za-z0-9_]*)\[(\d+)\]$")

try:
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]


def read_toml(path: str | Path) -> dict[str, Any]:
    """Read a TOML file, turning every failure into a one-line :class:`ScenarioError`."""
    path = Path(path)
    src = str(path)
    try:
        text = path.read_bytes().decode("utf-8")
    except FileNotFoundError:
        raise ScenarioError(src, "", "file not found") from None
    except IsADirectoryError:
        raise ScenarioError(src, "", "is a directory, expected a .toml file") from None
    except PermissionError:
        raise ScenarioError(src, "", "permission denied") from None
    except UnicodeDecodeError as exc:
        raise ScenarioError(src, "", f"is not UTF-8 text ({exc.reason} at byte {exc.start})"
                            ) from None
    if not text.strip():
        raise ScenarioError(src, "", "file is empty")
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(src, "", f"not valid TOML: {exc}") from None
    except RecursionError:  # tomllib parses nested arrays and inline tables recursively
        raise ScenarioError(src, "", "arrays or inline tables nested too deeply to read "
                                     "(hundreds of levels)") from None


def apply_overrides(data: dict[str, Any], overrides: Mapping[str, Any],
                    source: str = "<overrides>") -> dict[str, Any]:
    """Set dotted keys in a scenario dict (in place); returns ``data``.

    Args:
        data: Parsed scenario file.
        overrides: ``{"world.clutter.density": 0.1, "world.obstacles[0].radius": 1.0}``.
        source: Name used in error messages.

    Raises:
        ScenarioError: A path runs through a value that is not a table or an
            array of tables, or an index is out of range.
    """
    for dotted, value in overrides.items():
        node: Any = data
        parts = dotted.split(".")
        for i, part in enumerate(parts):
            last = i == len(parts) - 1
            m = _INDEX.match(part)
            name, idx = (m.group(1), int(m.group(2))) if m else (part, None)
            if not isinstance(node, dict):
                raise ScenarioError(source, dotted, f"'{'.'.join(parts[:i])}' is not a table")
            if idx is None:
                if last:
                    node[name] = value
                else:
                    node = node.setdefault(name, {})
                continue
            seq = node.get(name)
            if not isinstance(seq, list) or idx >= len(seq):
                size = len(seq) if isinstance(seq, list) else 0
                raise ScenarioError(source, dotted, f"index {idx} out of range ({name} has "
                                                    f"{size} entries)")
            if last:
                seq[idx] = value
            else:
                node = seq[idx]
    return data


def flatten(table: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested TOML tables -> dotted keys (``[grid.world] size = ...`` == ``"world.size"``).

    Args:
        table: The table as read.
        prefix: Dotted path of ``table`` (ending in ``.``), prepended to its keys.

    Returns:
        Dotted key -> value (arrays, and the tables inside them, kept as they are).
    """
    out: dict[str, Any] = {}
    for k, v in table.items():
        key = f"{prefix}{k}"
        if isinstance(v, Mapping):
            out.update(flatten(v, key + "."))
        else:
            out[key] = v
    return out
