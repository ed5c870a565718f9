"""Plugins: controller files and modules imported before controller ids are resolved.

A plugin is a Python file (``my_ctrl.py``) or an importable module name
(``my_pkg.controllers``) whose import registers controllers or filters with
:func:`dfcoa_opt.register`. The command line names them with ``--plugin``
(repeatable), a sweep file with ``plugins = [...]`` (paths relative to the sweep
file), Python with :func:`load_plugins`, and the environment with
``DFCOA_PLUGINS`` (entries separated by ``os.pathsep``, ``:`` on Linux), which the
registry reads when it first loads.

A file is imported once per process, under a module name made from its
resolved path, however often it is named. Every plugin loaded in a process is
loaded by the sweep workers too, before they build a controller
(:func:`loaded`), and a row's code identity includes each plugin file's bytes
(:func:`plugin_digest`), so editing the file re-simulates its runs.
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
import os
import sys
from collections.abc import Iterable
from pathlib import Path

from dfcoa_opt.core.errors import DfcoaError

#: The environment variable naming plugins (``os.pathsep``-separated).
ENV_VAR = "DFCOA_PLUGINS"

#: Loaded plugins, in load order: a file's resolved path or a module's name -> the module's
#: name in ``sys.modules``.
_LOADED: dict[str, str] = {}


def is_file_spec(spec: str) -> bool:
    """A file path (ends in ``.py`` or has a folder) rather than a module name."""
    return spec.endswith(".py") or "/" in spec or os.sep in spec


def load_plugin(spec: str, where: str = "--plugin") -> str:
    """Import one plugin (idempotent) and return its module's name.

    Args:
        spec: A ``.py`` file (relative to the working folder) or a module name.
        where: What named it, for errors (``--plugin``, ``FILE: plugins``).

    Raises:
        DfcoaError: One line naming ``where`` and the plugin: file or module not
            found, or its import raised (with the exception's first line).
    """
    if is_file_spec(spec):
        path = Path(spec).expanduser().resolve()
        key = str(path)
        if key in _LOADED:
            return _LOADED[key]
        if not path.is_file():
            raise DfcoaError(f"{where}: {spec}: plugin file not found")
        name = (f"dfcoa_plugin_{path.stem.replace('-', '_')}_"
                f"{hashlib.sha256(key.encode()).hexdigest()[:8]}")
        found = importlib.util.spec_from_file_location(name, path)
        if found is None or found.loader is None:
            raise DfcoaError(f"{where}: {spec}: not a Python file")
        module = importlib.util.module_from_spec(found)
        sys.modules[name] = module
        try:
            found.loader.exec_module(module)
        except DfcoaError:
            del sys.modules[name]
            raise
        except Exception as exc:  # noqa: BLE001 - the user's file: one line, not a traceback
            del sys.modules[name]
            raise DfcoaError(f"{where}: {spec}: importing it raised {type(exc).__name__}: "
                             f"{_first_line(exc)}") from None
    else:
        key = name = spec
        if key in _LOADED:
            return name
        try:
            importlib.import_module(spec)
        except Exception as exc:  # noqa: BLE001 - one line, not a traceback
            if (isinstance(exc, ModuleNotFoundError) and exc.name is not None
                    and spec.startswith(exc.name)):
                raise DfcoaError(f"{where}: {spec}: no such module or .py file") from None
            raise DfcoaError(f"{where}: {spec}: importing it raised {type(exc).__name__}: "
                             f"{_first_line(exc)}") from None
    _LOADED[key] = name
    return name


def load_plugins(specs: Iterable[str], where: str = "--plugin") -> list[str]:
    """Import plugins in order (:func:`load_plugin`); their module names."""
    return [load_plugin(str(s), where) for s in specs]


def from_env() -> list[str]:
    """The plugins named by ``DFCOA_PLUGINS`` (empty entries skipped)."""
    return [p for p in os.environ.get(ENV_VAR, "").split(os.pathsep) if p.strip()]


def loaded() -> tuple[str, ...]:
    """The plugins loaded in this process (resolved paths, module names), in load order."""
    return tuple(_LOADED)


def is_plugin_module(module: str) -> bool:
    """Whether ``module`` (a class's ``__module__``) came from a loaded plugin."""
    return any(module == m or module.startswith(m + ".") for m in _LOADED.values())


def plugin_digest(module: str) -> str:
    """SHA-256 (16 hex digits) of the plugin file that defined ``module``; "" for none.

    A module-name plugin (an installed package) has no file of its own here:
    "" as for entry points (``--rerun`` after changing it).
    """
    for key, name in _LOADED.items():
        if (module == name or module.startswith(name + ".")) and is_file_spec(key):
            return hashlib.sha256(Path(key).read_bytes()).hexdigest()[:16]
    return ""


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else "(no message)"
