"""Old module paths that keep importing for one release after a move.

When a module moves (``comparisons.lf_vo_core`` became
``comparisons.lf_vo.equations`` in 0.2), the package that held it calls
:func:`keep_old_paths` from its ``__init__`` with the old and new dotted
names. ``import comparisons.lf_vo_core`` (and ``from ... import ...``) then
returns the module at its new path, under a :class:`DeprecationWarning` that
names the new path, so code written against the old layout keeps running and
says what to change. No file is left at the old path.

The finder goes first in ``sys.meta_path``: when a whole package moves
(``dfcoa_opt.robots`` became ``dfcoa_opt.world.robots``), Python's own path
finder would otherwise find the old name of each submodule through the moved
package's ``__path__`` and load a second copy of it (two class identities,
two registrations). Every old submodule of a moved package is listed.

A *name* that moved out of a module (a function, a constant) is served by
the module's ``__getattr__`` with :func:`moved_attribute`.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
import types
import warnings
from collections.abc import Mapping, Sequence
from typing import Any


class _MovedFinder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds the old names of moved modules and loads them as their new modules."""

    def __init__(self, moves: Mapping[str, str], removal: str) -> None:
        self.moves = dict(moves)
        self.removal = removal

    def find_spec(self, fullname: str, path: Sequence[str] | None,
                  target: types.ModuleType | None = None) -> importlib.machinery.ModuleSpec | None:
        """A spec loaded by this finder for an old name; None for any other name."""
        if fullname not in self.moves:
            return None
        return importlib.machinery.ModuleSpec(fullname, self)

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> None:
        """Default module creation; :meth:`exec_module` replaces it."""
        return None

    def exec_module(self, module: types.ModuleType) -> None:
        """Put the new module in ``sys.modules`` under the old name (importlib returns it)."""
        old = module.__name__
        new = self.moves[old]
        warnings.warn(f"{old} moved to {new}; the old name goes in {self.removal}",
                      DeprecationWarning, stacklevel=2)
        sys.modules[old] = importlib.import_module(new)


def moved_names() -> dict[str, str]:
    """Every old dotted module name registered by :func:`keep_old_paths` -> its new name."""
    out: dict[str, str] = {}
    for finder in sys.meta_path:
        if isinstance(finder, _MovedFinder):
            out.update(finder.moves)
    return out


def keep_old_paths(moves: Mapping[str, str], removal: str) -> None:
    """Make each old dotted module name in ``moves`` import its new module.

    Args:
        moves: Old dotted name -> new dotted name.
        removal: The release that drops the old names (for the warning).
    """
    for finder in sys.meta_path:
        if isinstance(finder, _MovedFinder) and finder.moves.keys() & moves.keys():
            finder.moves.update(moves)
            return
    sys.meta_path.insert(0, _MovedFinder(moves, removal))


def moved_attribute(module: str, name: str, moves: Mapping[str, str], removal: str) -> Any:
    """A name that moved out of ``module``, from its new module, with a DeprecationWarning.

    For a module's ``__getattr__``::

        MOVED_NAMES = {"solve_time_stats": "dfcoa_opt.metrics.solver"}

        def __getattr__(name):
            return moved_attribute(__name__, name, MOVED_NAMES, "0.3")

    Args:
        module: The old module's name (``__name__``).
        name: The name asked for.
        moves: Moved name -> the dotted name of the module that holds it now.
        removal: The release that drops the old name (for the warning).

    Raises:
        AttributeError: ``name`` is not one of ``moves`` (as for any missing name).
    """
    if name not in moves:
        raise AttributeError(f"module {module!r} has no attribute {name!r}")
    new = moves[name]
    warnings.warn(f"{module}.{name} moved to {new}.{name}; the old name goes in {removal}",
                  DeprecationWarning, stacklevel=3)
    return getattr(importlib.import_module(new), name)
