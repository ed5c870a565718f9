"""The results store: one folder per sweep, one row file per run.

Layout::

    RESULTS/
      manifest.json     sweep name, file, SHA-256, code fingerprint of each controller,
                        the run keys, variants, baseline and ladders
      sweep.toml        copy of the sweep file
      rows/<key>.json   one row per run (see dfcoa_opt.bench.runner)
      logs/<key>.npz    the run's log
      results.csv       the rows of the current sweep, flattened

Every file is written atomically (:mod:`dfcoa_opt.core.atomic`), the log before its
row, so a row file exists only for a run whose log is complete. A sweep killed
at any moment (even by SIGKILL) therefore resumes without losing or
duplicating a row: the rerun skips every run that has a row.

A row counts as done only if it was produced by the same code, the same
scenario file and the same overrides: each row records ``code`` (the
fingerprint of its controller, :func:`run_fingerprint`: :func:`code_fingerprint`
and, for a policy file ``policy:PATH``, the bytes of its spec and weights),
``scenario_sha256`` and ``overrides``; other rows are run again.

The fingerprint of a controller hashes, without docstrings and comments
(:func:`executable_source`), the sources its runs execute:

- the core, the same for every run: every ``dfcoa_opt`` source (simulator,
  world, robots, planners, localization, scenario loading, metrics, the run
  path of the harness, the registry and the controller interfaces), but the
  CLI, reports, figures and the rest of the harness (:data:`NOT_RUN`) and the
  modules of :data:`CONTROL_PACKAGE` that only controllers import;
- the modules the controller's class (and its safety filter's, for
  ``"<controller>+<filter>"``) imports, transitively, in ``dfcoa_opt`` and
  ``comparisons`` (the imports read as :mod:`dfcoa_opt.core.runtime.kernel_cache` reads them;
  importing a module counts its parent packages too).

So editing one controller reruns that controller's runs (and those of the
controllers importing it, e.g. ``reshape`` after the ``cbf`` filter), and
editing the core reruns everything. (The registry imports every built-in
controller module to register it, but a run computes only with its own
controller's classes.) Where the imports cannot be read, the fingerprint
covers every source: for a controller whose closure imports a module by a
name computed at run time (``importlib``), for a controller defined outside
``dfcoa_opt`` and ``comparisons`` (entry points, notebooks) and for an
unknown id. The code of controllers from other packages is not part of the
fingerprint; use ``--rerun`` after changing one.
"""

from __future__ import annotations

import ast
import csv
import datetime as _dt
import functools
import hashlib
import io
import json
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from dfcoa_opt.bench.runner import Outcome
from dfcoa_opt.bench.sweep.expand import RunSpec, Sweep
from dfcoa_opt.core.atomic import atomic_write, remove_partials
from dfcoa_opt.core.errors import DfcoaError
from dfcoa_opt.core.moved import moved_names
from dfcoa_opt.core.runtime.kernel_cache import import_closure, module_files, module_imports

#: Row fields written as CSV columns before the metrics.
CSV_FIELDS = ("key", "scenario", "variant", "controller", "seed", "ladder", "ladder_value",
              "overrides", "status", "error", "digest")


#: Sources a run never executes: the CLI, reports and figures, and the harness that schedules
#: and stores runs (all of ``dfcoa_opt/bench/`` but :data:`RUN_SOURCES`). They are left out of
#: :func:`code_fingerprint`, so editing a table, a figure or the scheduler re-renders or
#: resumes without re-simulating; ``tests/test_bench.py`` checks that no run imports them.
#: (``dfcoa_opt/core/runtime/provenance.py`` is fingerprinted: the runner records numpy's SIMD level.)
NOT_RUN = ("dfcoa_opt/__main__.py", "dfcoa_opt/cli/__init__.py", "dfcoa_opt/cli/text.py",
           "dfcoa_opt/bench/figures.py", "dfcoa_opt/viz/plotting.py", "dfcoa_opt/viz/animation.py",
           "dfcoa_opt/scenario/reference.py", "dfcoa_opt/bench/")
#: The harness sources a run does execute (loading the run's scenario, summarising it).
RUN_SOURCES = ("dfcoa_opt/bench/__init__.py", "dfcoa_opt/bench/runner.py",
               "dfcoa_opt/bench/sweep/expand.py", "dfcoa_opt/bench/sweep/specs.py",
               "dfcoa_opt/bench/sweep/factors.py", "dfcoa_opt/bench/sweep/variants.py")


#: The package of the built-in controllers: those of its modules that no other ``dfcoa_opt``
#: module imports (``goto_slot``, ``dfcoa``, ``vfh``, ...) count only for the controllers that
#: import them; the rest (registry, interfaces, adapters) is core.
CONTROL_PACKAGE = "dfcoa_opt.control"
#: Calls that import a module by a name computed at run time: a controller whose closure makes
#: one is fingerprinted over every source, as its imports cannot be read.
DYNAMIC_IMPORTS = frozenset({"__import__", "import_module", "spec_from_file_location",
                             "module_from_spec", "run_module", "run_path", "entry_points",
                             "exec", "eval"})


def outside_fingerprint(relative: str) -> bool:
    """Whether a source (``dfcoa_opt/...``) is left out of the fingerprint (:data:`NOT_RUN`)."""
    if relative in RUN_SOURCES:
        return False
    return any(relative == p or (p.endswith("/") and relative.startswith(p)) for p in NOT_RUN)


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


def _within(module: str, package: str) -> bool:
    """Whether ``module`` is ``package`` or one of its submodules."""
    return module == package or module.startswith(package + ".")


def _read_source(path: Path) -> str:
    """The text of a source file (the one place the fingerprint reads sources)."""
    return path.read_text(encoding="utf-8")


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
    """Read, reduce and parse every fingerprinted source of ``dfcoa_opt`` and ``comparisons``."""
    import comparisons
    import dfcoa_opt

    files = module_files([Path(dfcoa_opt.__file__).parent, Path(comparisons.__file__).parent])
    moved = moved_names()
    known = set(files) | set(moved)
    hashed: dict[str, tuple[str, str]] = {}
    imports: dict[str, list[str]] = {}
    dynamic = set()
    for name, path in files.items():
        rel = name.replace(".", "/") + ("/__init__.py" if path.name == "__init__.py" else ".py")
        if outside_fingerprint(rel):
            continue
        text = _read_source(path)
        tree = _parse(text)
        if tree is None:  # as executable_source: kept whole; its imports cannot be read
            hashed[name] = (rel, text)
            dynamic.add(name)
            deps: set[str] = set()
        else:
            deps = {moved.get(m, m) for m in module_imports(name, path, tree, known)}
            if _strip_docstrings(tree):
                dynamic.add(name)
            hashed[name] = (rel, ast.dump(tree, annotate_fields=False))
        parts = name.split(".")
        deps.update(".".join(parts[:i]) for i in range(1, len(parts)))  # parent packages run
        imports[name] = sorted(deps)
    imports = {n: [d for d in deps if d in hashed] for n, deps in imports.items()}
    # every dfcoa_opt module outside the control package, and whatever it imports
    seeds = [n for n in hashed if _within(n, "dfcoa_opt") and not _within(n, CONTROL_PACKAGE)]
    return _Sources(hashed, imports, frozenset(dynamic), frozenset(import_closure(seeds, imports)))


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


def file_sha256(path: str) -> str:
    """First 16 hex digits of the SHA-256 of a file's bytes (rows record scenario files so)."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]


def display_path(path: str) -> str:
    """``path`` relative to the working folder when inside it (no machine paths in reports)."""
    p = Path(path).resolve()
    try:
        return p.relative_to(Path.cwd().resolve()).as_posix()
    except ValueError:
        return p.as_posix()


class ResultsStore:
    """A results folder.

    Args:
        root: The folder (created if missing). Temporary files left by a
            killed writer are removed on opening.
    """

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)
        self.rows_dir = self.root / "rows"
        self.logs_dir = self.root / "logs"
        for d in (self.root, self.rows_dir, self.logs_dir):
            if d.exists() and not d.is_dir():
                raise DfcoaError(f"{d}: exists and is not a folder")
            d.mkdir(parents=True, exist_ok=True)
            remove_partials(d)

    def row_path(self, key: str) -> Path:
        """Path of a run's row file."""
        return self.rows_dir / f"{key}.json"

    def read_row(self, key: str) -> dict[str, Any] | None:
        """The stored row of ``key``; None if absent or unreadable (it is then rerun)."""
        try:
            return json.loads(self.row_path(key).read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return None

    def is_done(self, run: RunSpec) -> bool:
        """A row exists for ``run`` from this code, this scenario file and these overrides.

        This code: the row's ``code`` is the fingerprint of ``run``'s controller
        (:func:`run_fingerprint`: its code, and a policy file's bytes).
        """
        row = self.read_row(run.key)
        return (row is not None and row.get("code") == run_fingerprint(run.controller)
                and row.get("scenario_sha256") == file_sha256(run.scenario_file)
                and row.get("overrides") == run.overrides_dict)

    def pending(self, runs: Iterable[RunSpec], rerun: bool = False) -> list[RunSpec]:
        """The runs to execute: all with ``rerun``, else those not done."""
        runs = list(runs)
        return runs if rerun else [r for r in runs if not self.is_done(r)]

    def adopt(self, run: RunSpec, others: Sequence[ResultsStore]) -> bool:
        """Take ``run``'s finished result from another store that has it; True if taken.

        A row there counts when it is done for ``run`` by :meth:`is_done`'s test (same
        code, scenario file and overrides), under the same key, controller and seed,
        with status ``ok``: the simulation is then the same, bit for bit. Its log is
        copied, and the row gets ``run``'s identity (variant, ladder) and
        ``provenance.reused_from`` (the other store's folder name).
        """
        for other in others:
            if other.root.resolve() == self.root.resolve() or not other.is_done(run):
                continue
            row = other.read_row(run.key)
            if (row is None or row.get("status") != "ok" or row.get("controller") != run.controller
                    or row.get("seed") != run.seed or not row.get("log")):
                continue
            try:
                log = (other.root / row["log"]).read_bytes()
            except OSError:
                continue
            row.update(key=run.key, scenario=run.scenario, scenario_file=run.scenario_file,
                       overrides=run.overrides_dict, overrides_hash=run.overrides_hash,
                       variant=run.variant_name, ladder=run.ladder,
                       ladder_value=run.ladder_value, log=f"logs/{run.key}.npz")
            row["provenance"] = {**(row.get("provenance") or {}), "reused_from": other.root.name}
            self.write(Outcome(row, log))
            return True
        return False

    def write(self, outcome: Outcome) -> Path:
        """Store one finished run: its log first, then its row (both atomic).

        The row gets ``code``, the fingerprint of its controller (:func:`run_fingerprint`),
        and ``scenario_sha256``.
        """
        row = dict(outcome.row)
        row["code"] = run_fingerprint(row["controller"])
        row["scenario_sha256"] = file_sha256(row["scenario_file"])
        # a row that is not strict JSON raises here, before its log is written
        text = json.dumps(row, indent=1, sort_keys=True, allow_nan=False) + "\n"
        if outcome.npz is not None:
            atomic_write(self.root / row["log"], outcome.npz)
        return atomic_write(self.row_path(row["key"]), text)

    def write_manifest(self, sweep: Sweep) -> None:
        """Record the sweep (file copy, hash, run keys).

        ``code`` maps each controller id of the sweep to its :func:`run_fingerprint`.
        The manifest is made (strict JSON: no NaN or inf) before either file is
        written, so a manifest that cannot be written leaves both as they were.
        :func:`~dfcoa_opt.bench.harness.run_sweep` calls it once a run has finished.
        """
        code = {c: run_fingerprint(c) for c in sorted({r.controller for r in sweep.runs})}
        manifest = {
            "name": sweep.name, "sweep_file": display_path(sweep.source),
            "sweep_sha256": sweep.sha256, "code": code,
            "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
            "keys": [r.key for r in sweep.runs], **sweep.describe(),
        }
        text = json.dumps(manifest, indent=1, allow_nan=False) + "\n"
        atomic_write(self.root / "sweep.toml", sweep.text)
        atomic_write(self.root / "manifest.json", text)

    def manifest(self) -> dict[str, Any]:
        """The manifest (empty dict if there is none)."""
        try:
            return json.loads((self.root / "manifest.json").read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return {}

    def rows(self, keys: Sequence[str] | None = None) -> list[dict[str, Any]]:
        """Rows of ``keys`` (default: the manifest's), in that order; missing ones skipped."""
        keys = self.manifest().get("keys", []) if keys is None else keys
        return [r for r in (self.read_row(k) for k in keys) if r is not None]

    def write_csv(self) -> Path:
        """Write ``results.csv``: the current sweep's rows, metrics flattened."""
        rows = self.rows()
        metric_keys: list[str] = []
        for r in rows:
            metric_keys += [k for k in (r.get("metrics") or {}) if k not in metric_keys]
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow([*CSV_FIELDS, "wall_time", *metric_keys])
        for r in rows:
            m = r.get("metrics") or {}
            base = [json.dumps(r["overrides"], sort_keys=True) if f == "overrides"
                    else r.get(f) for f in CSV_FIELDS]
            w.writerow(["" if v is None else v for v in
                        [*base, r.get("provenance", {}).get("wall_time"),
                         *(m.get(k) for k in metric_keys)]])
        return atomic_write(self.root / "results.csv", buf.getvalue())
