"""Keep numba's on-disk kernel cache in step with every source a kernel depends on.

numba's ``cache=True`` reuses a compiled kernel as long as the kernel's *own*
source file is unchanged (numba 0.68 compares a hash of its contents). A kernel
that calls a compiled function of another module, or reads a constant from
one, has that code frozen into its cache entry: after editing the other
module, the kernel silently keeps the old code (``tests/test_kernel_cache.py``
shows it: a cached ``f`` calling ``g`` of another file still returns ``g``'s old
value after ``g`` is edited). Numbers from a stale kernel are wrong without any
error, so :func:`refresh` runs when ``dfcoa_opt`` is imported:

- every module of the given package roots whose source holds ``cache=True`` is
  a kernel module; its *stamp* hashes the contents of the module and of every
  module of the roots it imports, transitively (all ``import`` statements,
  module-level or inside functions);
- a kernel module whose stamp differs from the one recorded last time loses
  its cache files (``<module>.*.nbi`` / ``.nbc`` in the folder numba's own
  locators choose for it), so numba compiles it again on first use;
- the stamps and each file's imports are kept in ``__pycache__/kernel_deps.json``
  under the first root, so an import reads and hashes the sources (a few ms)
  and parses only the files that changed.

When the cache files cannot be removed, the stamps are not recorded, and the
next import tries again. A read-only install (no writable ``__pycache__`` under
the first root) is left alone: its sources change only by reinstalling.
"""

from __future__ import annotations

import ast
import hashlib
import json
import os
import warnings
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

from dfcoa_opt.core.atomic import atomic_write

#: What marks a kernel module: numba's on-disk cache is on in it.
KERNEL_MARK = b"cache=True"
#: Name of the state file in the first root's ``__pycache__``.
STATE_NAME = "kernel_deps.json"


def module_files(roots: Iterable[Path]) -> dict[str, Path]:
    """Module name -> source of every ``.py`` under the roots (``pkg/__init__.py``: ``pkg``)."""
    out: dict[str, Path] = {}
    for root in roots:
        for path in sorted(root.rglob("*.py")):
            parts = path.relative_to(root.parent).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = path
    return out


def imported_modules(source: bytes | str | ast.AST, known: Mapping[str, Path] | Iterable[str],
                     package: str = "") -> list[str]:
    """The ``known`` modules whose names a source can reach by its imports, sorted.

    ``from a.b import c`` counts ``a.b`` and, when it is a module, ``a.b.c``;
    ``import a.b`` counts ``a.b``. The parent package ``a`` runs too, but a
    kernel can only freeze names it reads, and those come from the modules
    counted (a package re-exporting a name imports its module, which the
    closure follows). Relative imports are resolved against ``package`` (the
    importing module's package). A source that does not parse imports nothing.
    ``source`` may also be the source's syntax tree, already parsed.
    """
    names = set(known)
    if isinstance(source, ast.AST):
        tree = source
    else:
        try:
            tree = ast.parse(source)
        except (SyntaxError, ValueError):  # ValueError: null bytes
            return []
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".") if package else []
                parts = parts[:len(parts) - (node.level - 1)]
                base = ".".join(parts + ([node.module] if node.module else []))
            if base:
                found.add(base)
                found.update(f"{base}.{alias.name}" for alias in node.names)
    return sorted(found & names)


def module_imports(name: str, path: Path, source: bytes | str | ast.AST,
                   known: Mapping[str, Path] | Iterable[str]) -> list[str]:
    """:func:`imported_modules` of the module ``name`` whose source file is ``path``.

    Relative imports are resolved against the package itself in a package's
    ``__init__.py``, against the parent package in any other module.
    """
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    return imported_modules(source, known, package)


def import_closure(starts: Iterable[str], imports: Mapping[str, Sequence[str]]) -> set[str]:
    """The ``starts`` and every module they import, transitively.

    Args:
        starts: Module names.
        imports: Module name -> the modules it imports (a module missing here
            imports nothing).
    """
    seen = set(starts)
    todo = list(seen)
    while todo:
        for dep in imports.get(todo.pop(), ()):
            if dep not in seen:
                seen.add(dep)
                todo.append(dep)
    return seen


def refresh(roots: Sequence[Path]) -> list[str]:
    """Drop numba's cache of every kernel module whose own or imported sources changed.

    Args:
        roots: Package folders (e.g. ``dfcoa_opt/`` and ``comparisons/``); imports
            between them count.

    Returns:
        The kernel modules whose cache files were removed (numba compiles them
        again), sorted; empty when nothing changed or removing failed.
    """
    files = module_files(roots)
    state_path = roots[0] / "__pycache__" / STATE_NAME
    try:
        state_path.parent.mkdir(exist_ok=True)
    except OSError:
        pass
    if not os.access(state_path.parent, os.W_OK):
        return []  # a read-only install: its sources change only by reinstalling
    try:
        state = json.loads(state_path.read_text())
        old_files, old_stamps = state["files"], state["stamps"]
    except (OSError, ValueError, KeyError, TypeError):
        old_files, old_stamps = {}, {}
    digests: dict[str, str] = {}
    imports: dict[str, list[str]] = {}
    kernels = []
    for name, path in files.items():
        try:
            data = path.read_bytes()
        except OSError as exc:
            warnings.warn(f"{path}: cannot read it to check numba's kernel cache ({exc}); "
                          "nothing was dropped: after editing a kernel's imports, delete "
                          "the package's __pycache__ folders", RuntimeWarning, stacklevel=2)
            return []
        digest = hashlib.sha256(data).hexdigest()
        digests[name] = digest
        old = old_files.get(name)
        if old and old[0] == digest:
            imports[name] = old[1]
        else:
            imports[name] = module_imports(name, path, data, files)
        if KERNEL_MARK in data:
            kernels.append(name)
    stamps = {}
    for name in kernels:
        h = hashlib.sha256()
        for dep in sorted(import_closure([name], imports)):
            h.update(f"{dep}\0{digests[dep]}\0".encode())
        stamps[name] = h.hexdigest()
    stale = sorted(n for n in kernels if old_stamps.get(n) != stamps[n])
    new_files = {n: [digests[n], imports[n]] for n in files}
    if not stale and new_files == old_files:
        return []
    try:  # remove first: a state saying "up to date" must never outlive a stale cache
        for name in stale:
            drop_numba_cache(files[name])
    except OSError:
        return []
    try:
        atomic_write(state_path, json.dumps({"files": new_files, "stamps": stamps}, indent=0))
    except OSError:
        pass  # the next import drops the same caches again: more compiling, never stale
    return stale


def _probe() -> None:
    """A function for numba's cache locators, which read a function's first line."""


def drop_numba_cache(source: Path) -> int:
    """Remove numba's cache files of the kernels defined in ``source``; returns how many.

    The folder is the one numba itself would use (``NUMBA_CACHE_DIR``, the
    source's ``__pycache__``, or the user-wide cache, first that is writable),
    found through its locator classes; with a numba whose internals differ, the
    ``__pycache__`` beside the source.
    """
    folders = [source.parent / "__pycache__"]
    try:
        from numba.core.caching import CacheImpl

        for cls in CacheImpl._locator_classes:
            locator = cls.from_function(_probe, str(source))
            if locator is not None:
                folders = [Path(locator.get_cache_path())]
                break
    except (ImportError, AttributeError, TypeError):
        pass
    n = 0
    for folder in folders:
        for pattern in (f"{source.stem}.*.nbi", f"{source.stem}.*.nbc"):
            for path in folder.glob(pattern):
                path.unlink(missing_ok=True)
                n += 1
    return n
