"""Sweep files: controllers x scenarios x seeds x parameter overrides.

A sweep file (TOML)::

    name = "comparison"
    scenarios = ["../bench/*.toml"]        # files or globs, relative to this file
    controllers = ["*"]                    # ids; "*" = every registered controller
    seeds = 20                             # seeds first_seed .. first_seed + seeds - 1
    [grid]                                 # optional: Cartesian product of values
    "world.clutter.density" = [0.05, 0.1]
    "controllers.goto_slot.kp" = [0.5, 1.0]
    [[variants]]                           # optional: explicit override sets
    "team.n" = 6

Overrides are dotted scenario keys (``a.b.c``, ``a.b[2].c`` for arrays of
tables), applied to the scenario file's contents before validation, so a
controller parameter is ``controllers.<id>.<param>``, the same key a scenario
file uses. A ``controllers.<id>.*`` override only reaches runs of controller
``<id>``; runs that it does not reach are not duplicated. Each run's seed
replaces the scenario's ``seed``, so seeded parts of the scenario (random
clutter, start noise) change with it.

Every run gets a key ``<scenario>__<controller>__<overrides hash>__s<seed>``
that names its result files.
"""

from __future__ import annotations

import glob
import hashlib
import itertools
import json
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from dfcoa_opt.errors import DfcoaError, ScenarioError
from dfcoa_opt.params import build, param
from dfcoa_opt.sim.loader import load_scenario, read_toml
from dfcoa_opt.sim.scenario import Scenario

_UNSAFE = re.compile(r"[^A-Za-z0-9_.+-]+")


def safe_name(name: Any) -> str:
    """A file-name-safe form of a name: runs of other characters become ``_``."""
    return _UNSAFE.sub("_", str(name)) or "_"


@dataclass(frozen=True)
class SweepSpec:
    """A whole sweep file."""

    scenarios: tuple[str, ...] = param(doc="Scenario files or globs, relative to the sweep file.")
    name: str = param("", doc="Sweep name; default: the file name without .toml.")
    description: str = param("", doc="Free text.")
    controllers: tuple[str, ...] = param(("*",), doc="Controller ids; '*' = every registered "
                                                     "controller.")
    seeds: int = param(20, doc="Seeds per (scenario, controller, overrides).", ge=1)
    first_seed: int = param(0, doc="The first seed.", ge=0)
    grid: dict[str, Any] = param(default_factory=dict, doc="Dotted scenario key -> list of "
                                                           "values; runs take every combination.")
    variants: tuple[dict[str, Any], ...] = param((), doc="Explicit override sets (dotted key -> "
                                                         "value), combined with the grid.")


@dataclass(frozen=True)
class RunSpec:
    """One simulation of a sweep.

    Attributes:
        scenario_file: Absolute path of the scenario file.
        scenario: Scenario name.
        controller: Controller id.
        seed: Run seed (replaces the scenario's ``seed``).
        overrides: Canonical JSON of the dotted-key overrides (sorted keys).
    """

    scenario_file: str
    scenario: str
    controller: str
    seed: int
    overrides: str = "{}"  # canonical(...) form

    @property
    def overrides_dict(self) -> dict[str, Any]:
        """The overrides as a dict."""
        return json.loads(self.overrides)

    @property
    def overrides_hash(self) -> str:
        """``base`` without overrides, else the first 10 hex digits of their SHA-256."""
        if self.overrides == "{}":
            return "base"
        return hashlib.sha256(self.overrides.encode()).hexdigest()[:10]

    @property
    def key(self) -> str:
        """File-name-safe unique id of the run."""
        return (f"{safe_name(self.scenario)}__{safe_name(self.controller)}__"
                f"{self.overrides_hash}__s{self.seed}")


@dataclass(frozen=True)
class Sweep:
    """A validated, expanded sweep.

    Attributes:
        spec: The file contents.
        source: Path of the sweep file.
        sha256: SHA-256 of the file's bytes.
        text: The file's text.
        runs: Every run, in a fixed order (scenario, controller, overrides, seed).
    """

    spec: SweepSpec
    source: str
    sha256: str
    text: str
    runs: tuple[RunSpec, ...]

    @property
    def name(self) -> str:
        """Sweep name."""
        return self.spec.name


def _flatten(table: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested TOML tables -> dotted keys (``[grid.world] size = ...`` == ``"world.size"``)."""
    out: dict[str, Any] = {}
    for k, v in table.items():
        key = f"{prefix}{k}"
        if isinstance(v, Mapping):
            out.update(_flatten(v, key + "."))
        else:
            out[key] = v
    return out


def load_run_scenario(run: RunSpec) -> Scenario:
    """Load a run's scenario: the file, its seed replaced, its overrides applied."""
    return load_scenario(run.scenario_file, run.seed, run.overrides_dict)


def _combinations(spec: SweepSpec, src: str) -> list[dict[str, Any]]:
    grid = _flatten(spec.grid)
    for k, v in grid.items():
        if not isinstance(v, list) or not v:
            raise ScenarioError(src, f"grid.{k}", "must be a non-empty array of values")
    variants = [_flatten(v) for v in spec.variants] or [{}]
    points = [dict(zip(grid, combo, strict=True)) for combo in itertools.product(*grid.values())]
    return [{**v, **p} for v in variants for p in points]


def _controllers(spec: SweepSpec, src: str) -> list[str]:
    from dfcoa_opt.control.registry import available, controller_class
    from dfcoa_opt.errors import UnknownNameError

    known = available()
    out: list[str] = []
    for i, cid in enumerate(spec.controllers):
        if cid == "*":
            out += [c for c in known if c not in out]
            continue
        try:
            controller_class(cid)
        except UnknownNameError as exc:
            raise ScenarioError(src, f"controllers[{i}]", str(exc)) from None
        if cid not in out:
            out.append(cid)
    return out


def _scenario_files(spec: SweepSpec, src: str, base: Path) -> list[Path]:
    files: list[Path] = []
    for i, pattern in enumerate(spec.scenarios):
        hits = sorted(Path(p) for p in glob.glob(str(base / pattern)))
        if not hits:
            raise ScenarioError(src, f"scenarios[{i}]", f"'{pattern}' matches no file "
                                                        f"(relative to {base})")
        files += [h.resolve() for h in hits if h.resolve() not in files]
    return files


def canonical(overrides: Mapping[str, Any]) -> str:
    """Canonical JSON of an override set (sorted keys, no spaces): the hashed form."""
    return json.dumps(dict(overrides), sort_keys=True, separators=(",", ":"))


def _for_controller(overrides: Mapping[str, Any], cid: str) -> str:
    """Canonical JSON of the overrides that reach controller ``cid``."""
    parts = cid.split("+")  # "a+filter": both parts' tables reach it
    return canonical({k: v for k, v in overrides.items()
                      if not k.startswith("controllers.") or k.split(".")[1] in parts})


def load_sweep(path: str | Path, seeds: int | None = None,
               overrides: Mapping[str, Any] | None = None) -> Sweep:
    """Read, validate and expand a sweep file.

    Every scenario is loaded once per override set (with the first seed), so a
    bad scenario, override or controller parameter fails here, before any run.

    Args:
        path: The sweep ``.toml``.
        seeds: Replace the file's seed count (e.g. a quick smoke run).
        overrides: Dotted keys set in every run on top of the file's own
            (e.g. ``{"t_max": 5.0}`` for a reduced configuration).

    Raises:
        ScenarioError: One line naming the file, the key and the problem.
    """
    path = Path(path)
    src = str(path)
    data = read_toml(path)
    data.setdefault("name", path.stem)
    spec = build(SweepSpec, data, src)
    if not spec.scenarios:
        raise ScenarioError(src, "scenarios", "lists no scenario")
    raw = path.read_bytes()
    files = _scenario_files(spec, src, path.parent)
    ctrls = _controllers(spec, src)
    combos = [{**c, **(overrides or {})} for c in _combinations(spec, src)]
    names: dict[str, Path] = {}
    runs: list[RunSpec] = []
    n_seeds = spec.seeds if seeds is None else seeds
    for f in files:
        for combo in combos:
            probe = RunSpec(str(f), f.stem, "", spec.first_seed, canonical(combo))
            try:
                sc = load_run_scenario(probe)
            except DfcoaError as exc:
                hint = f" (with overrides {json.dumps(combo)})" if combo else ""
                raise ScenarioError(src, "scenarios", f"{exc}{hint}") from None
            if names.setdefault(sc.name, f) != f:
                raise ScenarioError(src, "scenarios", f"two scenarios are named '{sc.name}': "
                                                      f"{names[sc.name]} and {f}")
            for cid in ctrls:
                ov = _for_controller(combo, cid)
                for seed in range(spec.first_seed, spec.first_seed + n_seeds):
                    runs.append(RunSpec(str(f), sc.name, cid, seed, ov))
    unique = list(dict.fromkeys(runs))  # controller-specific keys can make duplicates
    return Sweep(spec, src, hashlib.sha256(raw).hexdigest(), raw.decode("utf-8"), tuple(unique))


def describe_runs(runs: Iterable[RunSpec]) -> str:
    """``12 runs: 2 scenarios x 3 controllers x 2 seeds`` style summary."""
    runs = list(runs)
    sc = {r.scenario for r in runs}
    ct = {r.controller for r in runs}
    sd = {r.seed for r in runs}
    ov = {r.overrides for r in runs}
    text = f"{len(runs)} runs: {len(sc)} scenarios x {len(ct)} controllers x {len(sd)} seeds"
    return text + (f" x {len(ov)} override sets" if len(ov) > 1 else "")
