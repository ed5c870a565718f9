"""The code fingerprint of a row: the sources its run executes, by the layers of the code.

A row of the results store counts as done only if the code that made it is
the code of now. The fingerprint of a controller id hashes, without
docstrings and comments (:func:`executable_source`), the sources its runs
execute, found by a rule (the layer contract, :mod:`dfcoa_opt.core.layers`),
not by a list of files:

- **the core**, the same for every run: every module of the layers a run
  executes (:data:`~dfcoa_opt.core.layers.RUN_LAYERS`: core, world, planning,
  scenario, sim, metrics), the package root (which pins the SIMD cap), the
  worker's run path (:mod:`dfcoa_opt.bench.runner` and what it imports), and
  whatever those import, transitively (the controller interfaces and the
  registry, among others);
- **the controller's own code**: the modules its class (and its safety
  filter's, for ``"<controller>+<filter>"``) imports, transitively, in
  ``dfcoa_opt`` and ``comparisons`` (its package, and what it shares with
  others, e.g. ``comparisons/constraints/``).

Imports are read as :mod:`dfcoa_opt.core.runtime.kernel_cache` reads them,
inside functions too; importing a module counts its parent packages. The
layers above the run (environments, figures, reports, the rest of the
harness, the facade and the CLI) are in no fingerprint: editing a table or
the scheduler re-renders or resumes without re-simulating, and editing one
controller reruns only its rows (and those of the controllers that import
it, e.g. ``reshape`` after the ``cbf`` filter); editing the core reruns
everything.

Where the imports cannot be read, the fingerprint covers every fingerprinted
source: a controller whose own modules import by a name computed at run time
(:data:`DYNAMIC_IMPORTS`), a controller defined outside ``dfcoa_opt`` and
``comparisons`` (another package, a notebook) and an unknown id. The code of
controllers from other packages is not part of the fingerprint; use
``--rerun`` after changing one.
"""

from __future__ import annotations

import ast
import functools
import hashlib
import importlib.util
from dataclasses import dataclass
from pathlib import Path

from dfcoa_opt.core import layers
from dfcoa_opt.core.errors import DfcoaError
from dfcoa_opt.core.moved import moved_names
from dfcoa_opt.core.runtime.kernel_cache import import_closure, module_files, module_imports

#: The worker's run path: the module that runs a row, and every module it imports.
RUN_PATH = "dfcoa_opt.bench.runner"
#: Calls that import a module by a name computed at run time: a controller whose own
#: modules make one is fingerprinted over every source, as its imports cannot be read.
DYNAMIC_IMPORTS = frozenset({"__import__", "import_module", "spec_from_file_location",
                             "module_from_spec", "run_module", "run_path", "entry_points",
                             "exec", "eval"})


def _parse(text: str) -> ast.Module | None:
    """The syntax tree of a source; None if it does not parse."""
    try:
        return ast.parse(text)
    except (SyntaxError, ValueError):  # ValueError: null bytes
        return None


def _strip_docstrings(tree: ast.Module) -> bool:
    """Drop the docstrings of ``tree``, in place; whether it calls one of :data:`DYNAMIC_IMPORTS`.

    The one walk over the tree that :func:`executable_source` and the import
    scan of :func:`code_fingerprint` share.
    """
    dynamic = False
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            body = node.body
            if (body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant)
                    and isinstance(body[0].value.value, str)):
                node.body = body[1:] or [ast.Pass()]
        elif isinstance(node, ast.Call):
            called = getattr(node.func, "id", None) or getattr(node.func, "attr", None)
            dynamic = dynamic or called in DYNAMIC_IMPORTS
    return dynamic


def executable_source(text: str) -> str:
    """What of a Python source can change a run: its syntax tree without docstrings.

    Comments, blank lines, formatting and the docstrings of modules, classes and
    functions are dropped (no run reads ``__doc__``; only ``dfcoa list`` does), so
    editing them keeps every cached result. A source that does not parse is kept
    whole.
    """
    tree = _parse(text)
    if tree is None:
        return text
    _strip_docstrings(tree)
    return ast.dump(tree, annotate_fields=False)


@functools.lru_cache(maxsize=4096)
def _reduce(name: str, path: Path, text: str,
            known: frozenset[str]) -> tuple[str, bool, frozenset[str]]:
    """One source reduced: its executable source, dynamic imports and imported modules.

    Returns :func:`executable_source`, whether it calls one of :data:`DYNAMIC_IMPORTS`,
    and the known modules it imports (old names resolved). A source that does not parse
    is kept whole, and counts as importing by a computed name. Cached by the text:
    :func:`_sources` runs again only when the sources may have changed (tests that edit
    one file), and then only the edited files are parsed again.
    """
    tree = _parse(text)
    if tree is None:
        return text, True, frozenset()
    moved = moved_names()
    deps = frozenset(moved.get(m, m) for m in module_imports(name, path, tree, known))
    calls_dynamic = _strip_docstrings(tree)
    return ast.dump(tree, annotate_fields=False), calls_dynamic, deps


def _read_source(path: Path) -> str:
    """The text of a source file (the one place the fingerprint reads sources)."""
    return path.read_text(encoding="utf-8")


def _package_folder(name: str) -> Path:
    """The folder of an installed package, found without importing it."""
    spec = importlib.util.find_spec(name)
    if spec is None or spec.origin is None:
        raise DfcoaError(f"package {name} not found: the fingerprint reads its sources")
    return Path(spec.origin).parent


def is_run(module: str) -> bool:
    """Whether a module can be part of a run: a room at or below the metrics layer, or the root.

    The rest of the harness counts only where the run path imports it
    (:func:`fingerprint_sources`).
    """
    layer = layers.layer_of(module)
    return module == "dfcoa_opt" or (layer is not None
                                     and layer <= layers.layer_of("dfcoa_opt.metrics"))


@dataclass(frozen=True)
class _Sources:
    """The fingerprinted sources, read once per process.

    Attributes:
        hashed: Module -> (relative path, :func:`executable_source`), in hashing order.
        imports: Module -> the fingerprinted modules importing it runs: those its
            import statements name (old names of moved modules resolved) and its
            parent packages.
        dynamic: Modules that call one of :data:`DYNAMIC_IMPORTS`.
        core: Modules every run executes.
    """

    hashed: dict[str, tuple[str, str]]
    imports: dict[str, list[str]]
    dynamic: frozenset[str]
    core: frozenset[str]


@functools.lru_cache(maxsize=1)
def _sources() -> _Sources:
    """Read, reduce and parse every source of ``dfcoa_opt`` and ``comparisons``, then select."""
    files = module_files([_package_folder("dfcoa_opt"), _package_folder("comparisons")])
    moved = moved_names()
    known = frozenset(files) | frozenset(moved)
    code: dict[str, tuple[str, str]] = {}
    imports: dict[str, list[str]] = {}
    dynamic = set()
    for name, path in files.items():
        rel = name.replace(".", "/") + ("/__init__.py" if path.name == "__init__.py" else ".py")
        reduced, calls_dynamic, imported = _reduce(name, path, _read_source(path), known)
        code[name] = (rel, reduced)
        if calls_dynamic:
            dynamic.add(name)
        deps = set(imported)
        parts = name.split(".")
        deps.update(".".join(parts[:i]) for i in range(1, len(parts)))  # parent packages run
        imports[name] = sorted(deps & files.keys())
    harness = {n: [d for d in deps if is_run(d) or layers.within(d, "dfcoa_opt.bench")]
               for n, deps in imports.items()}  # the root's facade (api) is not a run path
    run_path = import_closure([RUN_PATH], harness) if RUN_PATH in files else set()
    keep = {n for n in files if is_run(n)} | run_path
    hashed = {n: code[n] for n in files if n in keep}
    imports = {n: [d for d in imports[n] if d in keep] for n in hashed}
    seeds = [n for n in hashed if n == "dfcoa_opt" or n in run_path
             or any(layers.within(n, room) for room in layers.RUN_LAYERS)]
    return _Sources(hashed, imports, frozenset(dynamic & keep),
                    frozenset(import_closure(seeds, imports)))


def _controller_modules(controller: str) -> set[str] | None:
    """The modules of the classes of a registry id (controller, and filter); None if unknown."""
    from dfcoa_opt.control import registry

    try:
        classes = registry.component_classes(controller)
    except DfcoaError:  # an unknown id, or a policy file gone or broken
        return None
    return {getattr(c, "__module__", "") for c in classes}


def fingerprint_sources(controller: str | None = None) -> list[str]:
    """The sources (``dfcoa_opt/...``, ``comparisons/...``) whose code the fingerprint covers.

    Args:
        controller: A registry id, ``"<controller>+<filter>"`` too; None: every
            fingerprinted source.

    Returns:
        Relative paths, in hashing order: the core and the import closure of the
        controller's (and filter's) module; every fingerprinted source when the
        controller is unknown, defined outside ``dfcoa_opt`` and ``comparisons``,
        or imports a module by a name computed at run time.
    """
    src = _sources()
    modules = _controller_modules(controller) if controller is not None else None
    if modules is None or not modules <= src.hashed.keys():
        return [rel for rel, _ in src.hashed.values()]
    closure = import_closure(modules, src.imports)
    if (closure - src.core) & src.dynamic:
        return [rel for rel, _ in src.hashed.values()]
    keep = src.core | closure
    return [rel for name, (rel, _) in src.hashed.items() if name in keep]


def core_sources() -> list[str]:
    """The sources every run executes (relative paths, in hashing order)."""
    src = _sources()
    return [rel for name, (rel, _) in src.hashed.items() if name in src.core]


@functools.cache
def code_fingerprint(controller: str | None = None) -> str:
    """SHA-256 (16 hex digits) over the sources a run of ``controller`` executes.

    The sources of :func:`fingerprint_sources`, each as its
    :func:`executable_source` (a docstring or comment edit keeps the cache).
    Cached per controller id: the sources are read once per process.

    Args:
        controller: A registry id, ``"<controller>+<filter>"`` too; None: every
            fingerprinted source.
    """
    src = _sources()
    wanted = set(fingerprint_sources(controller))
    h = hashlib.sha256()
    for rel, code in src.hashed.values():
        if rel in wanted:
            h.update(rel.encode())
            h.update(code.encode())
    return h.hexdigest()[:16]


def run_fingerprint(controller: str) -> str:
    """What a row's ``code`` records: :func:`code_fingerprint`, and the data its runs read.

    For a policy file (``policy:PATH``) the SHA-256 of its spec's and weights'
    bytes joins the code's (:func:`dfcoa_opt.control.registry.data_digest`, read
    anew at every call), so a changed file re-simulates its runs; any other id
    gives :func:`code_fingerprint` itself.
    """
    from dfcoa_opt.control.registry import data_digest

    code, data = code_fingerprint(controller), data_digest(controller)
    return hashlib.sha256(f"{code} {data}".encode()).hexdigest()[:16] if data else code
