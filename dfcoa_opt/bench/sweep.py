"""Sweep files: scenarios x variants x seeds, with parameter grids and difficulty ladders.

A sweep file (TOML)::

    name = "comparison"
    scenarios = ["../bench/*.toml"]        # files or globs, relative to this file
    controllers = ["*"]                    # ids; "*" = every registered controller
    seeds = 20                             # seeds first_seed .. first_seed + seeds - 1
    baseline = "dfcoa"                     # optional: the variant the others are compared to
    [variants.dfcoa_compensated]           # optional: named method configurations
    controller = "dfcoa"
    "controllers.dfcoa.compensate_tracking_offset" = true
    [grid]                                 # optional: Cartesian product of values
    "world.clutter.density" = [0.05, 0.1]
    [ladder]                               # optional: a difficulty ladder
    key = "world.clutter.density"
    values = [0.02, 0.04, 0.08]

Variants, grids and ladders: :mod:`dfcoa_opt.bench.variants`. Overrides are
dotted scenario keys (``a.b.c``, ``a.b[2].c`` for arrays of tables), applied to
the scenario file's contents before validation, so a controller parameter is
``controllers.<id>.<param>``, the same key a scenario file uses. A
``controllers.<id>.*`` override only reaches runs of controller ``<id>``; runs
that it does not reach are not duplicated. Each run's seed replaces the
scenario's ``seed``, so seeded parts of the scenario (random clutter, start
noise) change with it.

Every run gets a readable key ``<scenario>__<variant>[__<ladder>_<value>]__s<seed>``
that names its result files. A name longer than :data:`NAME_MAX` characters, and a
key that could exceed :data:`KEY_MAX`, is cut short and ends in ``-`` and 8 hex
digits of the SHA-256 of the whole name (:func:`shorten`), so the same name always
gives the same file name and two names give two; shorter names are kept as they are.

A sweep has at most :data:`MAX_RUNS` runs, counting every seed ``max_seeds`` may
add, and at most :data:`MAX_SEEDS` seeds per cell; a larger one is refused before
any run is built.
"""

from __future__ import annotations

import fnmatch
import glob
import hashlib
import itertools
import json
import math
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Literal

from dfcoa_opt.bench.variants import (
    Ladder,
    Variant,
    check_value,
    ladder_variants,
    named_variants,
    parse_ladders,
    reaches,
    suffix,
)
from dfcoa_opt.errors import DfcoaError, ScenarioError, did_you_mean
from dfcoa_opt.params import build, param
from dfcoa_opt.sim.loader import load_scenario, read_toml
from dfcoa_opt.sim.scenario import Scenario

_UNSAFE = re.compile(r"[^A-Za-z0-9_.+-]+")
#: The source of a sweep given as a dict (:func:`sweep_from_dict`), as its errors name it.
DICT_SOURCE = "<dict>"
#: Longest name :func:`safe_name` returns (scenario, variant, ladder label: parts of file names).
NAME_MAX = 120
#: Longest run key, and longest file stem joined from several names; with the hidden
#: temporary name of an atomic write it stays well below the 255 bytes of a file name.
KEY_MAX = 200
_HEAD_MAX = KEY_MAX - len("__s") - 20  # a run key before its seed (20 digits hold any seed)
#: Most runs a sweep may have, every seed ``max_seeds`` may add counted.
MAX_RUNS = 1_000_000
#: Most seeds per (scenario, variant, rung): ``seeds``, ``max_seeds``, ``[variant_seeds]``.
MAX_SEEDS = 100_000


def shorten(text: str, limit: int = NAME_MAX, full: str | None = None) -> str:
    """``text`` itself if it has at most ``limit`` characters, else a stable shorter form.

    The shorter form is the start of ``text``, ``-`` and the first 8 hex digits of
    the SHA-256 of ``full`` (default: ``text``), ``limit`` characters in all: the
    same input always gives the same name, and two inputs two names.
    """
    if len(text) <= limit:
        return text
    whole = text if full is None else full
    digest = hashlib.sha256(whole.encode("utf-8", "surrogatepass")).hexdigest()[:8]
    return f"{text[:limit - 9]}-{digest}"


def safe_name(name: Any) -> str:
    """A file-name-safe form of a name: runs of other characters become ``_``.

    At most :data:`NAME_MAX` characters: a longer one is cut short with a hash
    of the whole name (:func:`shorten`); a shorter one is unchanged.
    """
    full = str(name)
    return shorten(_UNSAFE.sub("_", full).strip("_") or "_", NAME_MAX, full)


@dataclass(frozen=True)
class SweepSpec:
    """A whole sweep file."""

    scenarios: tuple[str, ...] = param((), doc="Scenario files or globs, relative to the sweep "
                                               "file.")
    name: str = param("", doc="Sweep name; default: the file name without .toml.")
    description: str = param("", doc="Free text.")
    controllers: tuple[str, ...] | None = param(
        None, doc="Controller ids, each a variant named by its id; '*' = every registered "
                  "controller. Default: '*', or none when [variants] names variants.")
    plugins: tuple[str, ...] = param((), doc="Controller files (.py, relative to the sweep "
                                             "file) or module names imported before the "
                                             "controllers are resolved (docs/controllers.md).")
    seeds: int = param(20, doc="Seeds per (scenario, variant, ladder rung); with max_seeds, "
                               "the first seeds of each.", ge=1, le=MAX_SEEDS)
    max_seeds: int = param(0, doc="With > 0: add seeds to each (scenario, variant, rung) until "
                                  "its success rate's Wilson 95 % interval is within "
                                  "+-max_half_width, at most this many seeds "
                                  "(dfcoa_opt.bench.precision).", ge=0, le=MAX_SEEDS)
    max_half_width: float = param(0.15, doc="Target half-width of the success rate's interval "
                                            "with max_seeds (fraction).", gt=0.0, le=0.5)
    decide_at: float = param(0.0, doc="With max_seeds and > 0: a cell whose interval lies wholly "
                                      "above or below this success rate (fraction) is settled "
                                      "too, however wide; 0 = off.", ge=0.0, lt=1.0)
    first_seed: int = param(0, doc="The first seed.", ge=0)
    grid: dict[str, Any] = param(default_factory=dict, doc="Dotted scenario key -> list of "
                                                           "values; runs take every combination.")
    variants: Any = param(None, doc="[variants] name = { controller = id, dotted key = value }; "
                                    "or [[variants]] override sets combined with every "
                                    "controller.")
    baseline: str = param("", doc="Variant the report compares every other variant to (paired "
                                  "statistics).")
    ladder: Any = param(None, doc="[ladder] (key and values, or [[ladder.rungs]]) or [[ladder]] "
                                  "(each with its own scenarios): a difficulty ladder.")
    variant_files: tuple[str, ...] = param((), doc="Files or globs (relative to the sweep file) "
                                                  "whose [variants] tables join this sweep's, "
                                                  "e.g. the tuned variants of dfcoa tune.")
    variant_seeds: dict[str, int] = param(default_factory=dict, doc="Variant name or glob -> its "
                                                                    "number of seeds instead of "
                                                                    "seeds (the first pattern "
                                                                    "that matches).", ge=1,
                                    le=MAX_SEEDS)
    tune: Any = param(None, doc="[tune]: the budget of dfcoa tune (dfcoa_opt.bench.tune."
                                "TuneSpec); dfcoa bench ignores it.")
    split: Literal["", "train", "validation", "test"] = param(
        "", doc="Every run's seed must lie in this range of its scenario's [splits] "
                "(docs/heldout.md); empty: no check.")


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
    variant: str = ""
    ladder: str = ""
    ladder_value: float | None = None

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
    def variant_name(self) -> str:
        """The variant's name (the controller id when none was given)."""
        return self.variant or self.controller

    @property
    def key(self) -> str:
        """File-name-safe unique id of the run (readable; a hash only in a name too long).

        At most :data:`KEY_MAX` characters: each name is :func:`safe_name`, and the
        part before ``__s<seed>`` is shortened when longer than the room a 20-digit
        seed leaves (so every seed of a cell shares it).
        """
        rung = ("" if self.ladder_value is None
                else f"__{safe_name(self.ladder)}_{self.ladder_value:g}")
        head = f"{safe_name(self.scenario)}__{safe_name(self.variant_name)}{rung}"
        return f"{shorten(head, _HEAD_MAX)}__s{self.seed}"


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
    variants: tuple[Variant, ...] = ()
    ladders: tuple[Ladder, ...] = ()
    max_seeds: int = 0

    def extended(self, runs: Iterable[RunSpec]) -> Sweep:
        """The same sweep with ``runs`` added (e.g. seeds of :mod:`dfcoa_opt.bench.precision`)."""
        have = set(self.runs)
        return replace(self, runs=self.runs + tuple(r for r in runs if r not in have))

    @property
    def name(self) -> str:
        """Sweep name."""
        return self.spec.name

    @property
    def baseline(self) -> str:
        """The baseline variant's name ("" without one)."""
        return self.spec.baseline

    def describe(self) -> dict[str, Any]:
        """Variants, baseline and ladders as JSON data (for the manifest and the report)."""
        names = list(dict.fromkeys(r.variant_name for r in self.runs))
        ctrl = {r.variant_name: (r.controller, r.overrides_dict) for r in self.runs}
        return {
            "variants": [{"name": n, "controller": ctrl[n][0]} for n in names],
            "baseline": self.baseline,
            "ladders": [{"label": lad.label, "log_x": lad.log_x,
                         "values": [r.value for r in lad.rungs]} for lad in self.ladders],
        }


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


@dataclass(frozen=True)
class _Grid:
    """The grid of a sweep: its points, the keys that vary, and what the run count needs.

    Attributes:
        points: Every combination (with the older ``[[variants]]`` override sets).
        varying: The keys that take several values.
        sizes: Grid key -> its number of values.
        sets: The ``[[variants]]`` override sets (``[{}]`` without them).
    """

    points: list[dict[str, Any]]
    varying: list[str]
    sizes: dict[str, int]
    sets: list[dict[str, Any]]

    def configurations(self, controller: str) -> int:
        """How many distinct override sets the grid gives runs of ``controller`` (at most)."""
        sets = {canonical({k: x for k, x in s.items() if reaches(k, controller)})
                for s in self.sets}
        return len(sets) * math.prod(n for k, n in self.sizes.items() if reaches(k, controller))


def _grid(spec: SweepSpec, src: str) -> _Grid:
    """Grid points (with the older ``[[variants]]`` override sets) and the keys that vary.

    Raises:
        ScenarioError: A grid key without values, a value a row cannot hold (NaN,
            inf, a date), or more than :data:`MAX_RUNS` combinations (refused before
            they are built).
    """
    grid = _flatten(spec.grid)
    for k, v in grid.items():
        if not isinstance(v, list) or not v:
            raise ScenarioError(src, f"grid.{k}", "must be a non-empty array of values")
        for i, x in enumerate(v):
            check_value(x, src, f"grid.{k}[{i}]")
    sets: list[dict[str, Any]] = [{}]
    if isinstance(spec.variants, list):
        if not all(isinstance(v, Mapping) for v in spec.variants):
            raise ScenarioError(src, "variants", "[[variants]] must be tables of dotted keys")
        sets = [_flatten(v) for v in spec.variants] or [{}]
        for i, one in enumerate(sets):
            for k, x in one.items():
                check_value(x, src, f"variants[{i}].{k}")
    combos = len(sets) * math.prod(len(v) for v in grid.values())
    if combos > MAX_RUNS:
        raise ScenarioError(src, "grid", f"has {combos:,} combinations of values, more than "
                                         f"the {MAX_RUNS:,} runs a sweep may have; use fewer "
                                         "values, or split the sweep")
    points = [dict(zip(grid, combo, strict=True)) for combo in itertools.product(*grid.values())]
    varying = [k for k, v in grid.items() if len(v) > 1]
    for k in dict.fromkeys(k for s in sets for k in s):
        if len({json.dumps(s.get(k), sort_keys=True) for s in sets}) > 1 and k not in varying:
            varying.append(k)
    return _Grid([{**v, **p} for v in sets for p in points], varying,
                 {k: len(v) for k, v in grid.items()}, sets)


def _variants(spec: SweepSpec, src: str, base: Path) -> list[Variant]:
    """Plain controllers (named by id), the ``[variants]`` table and the variant files' tables."""
    from dfcoa_opt.control.registry import available, controller_class
    from dfcoa_opt.errors import UnknownNameError

    named = (named_variants(spec.variants, _flatten, src)
             if isinstance(spec.variants, Mapping) else [])
    for path in _scenario_files(spec.variant_files, src, base, "variant_files"):
        table = read_toml(path).get("variants")
        if not isinstance(table, Mapping) or not table:
            raise ScenarioError(str(path), "variants", "is required: a table of named variants "
                                                       "([variants.<name>] controller = ...)")
        named += named_variants(table, _flatten, str(path))
    if spec.variants is not None and not isinstance(spec.variants, (Mapping, list)):
        raise ScenarioError(src, "variants", "must be a table ([variants]) or an array of "
                                             "tables ([[variants]])")
    ids = spec.controllers if spec.controllers is not None else (() if named else ("*",))
    known = available()
    out: list[Variant] = []
    for i, cid in enumerate(ids):
        for c in (known if cid == "*" else [cid]):
            try:
                controller_class(c)
            except UnknownNameError as exc:
                raise ScenarioError(src, f"controllers[{i}]", str(exc)) from None
            if all(v.name != c for v in out):
                out.append(Variant(c, c))
    for v in named:
        try:
            controller_class(v.controller)
        except UnknownNameError as exc:
            raise ScenarioError(src, f"variants.{v.name}.controller", str(exc)) from None
        if any(o.name == v.name for o in out):
            raise ScenarioError(src, f"variants.{v.name}", "is also a plain controller of "
                                                           "this sweep; choose another name")
        out.append(v)
    return out


def _variant_seeds(spec: SweepSpec, variants: Sequence[Variant], src: str) -> dict[str, int]:
    """Each variant's seed count from ``[variant_seeds]`` (only those a pattern names).

    Raises:
        ScenarioError: A pattern that names no variant of the sweep.
    """
    out: dict[str, int] = {}
    for pattern, count in spec.variant_seeds.items():
        hits = [v.name for v in variants if fnmatch.fnmatchcase(v.name, pattern)]
        if not hits:
            raise ScenarioError(src, f"variant_seeds.{pattern}", "names no variant of this sweep"
                                + did_you_mean(pattern, [v.name for v in variants]))
        for name in hits:
            out.setdefault(name, count)
    return out


def _scenario_files(patterns: Sequence[str], src: str, base: Path, key: str) -> list[Path]:
    files: list[Path] = []
    for i, pattern in enumerate(patterns):
        hits = sorted(Path(p) for p in glob.glob(str(base / pattern)))
        if not hits:
            raise ScenarioError(src, f"{key}[{i}]", f"'{pattern}' matches no file "
                                                    f"(relative to {base})")
        files += [h.resolve() for h in hits if h.resolve() not in files]
    return files


def canonical(overrides: Mapping[str, Any]) -> str:
    """Canonical JSON of an override set (sorted keys, no spaces): the hashed form."""
    return json.dumps(dict(overrides), sort_keys=True, separators=(",", ":"))


def load_sweep(path: str | Path, seeds: int | None = None,
               overrides: Mapping[str, Any] | None = None) -> Sweep:
    """Read, validate and expand a sweep file.

    Every scenario is loaded once per distinct override set (with the first
    seed), so a bad scenario, override or controller parameter fails here,
    before any run.

    Args:
        path: The sweep ``.toml``.
        seeds: Replace the file's seed count (e.g. a quick smoke run).
        overrides: Dotted keys set in every run on top of the file's own
            (e.g. ``{"t_max": 5.0}`` for a reduced configuration).

    Raises:
        ScenarioError: One line naming the file, the key and the problem.
    """
    path = Path(path)
    data = read_toml(path)
    data.setdefault("name", path.stem)
    text = path.read_bytes().decode("utf-8")
    return expand_sweep(data, str(path), path.parent, text, seeds, overrides)


def sweep_from_dict(data: Mapping[str, Any], base_dir: str | Path = ".",
                    seeds: int | None = None,
                    overrides: Mapping[str, Any] | None = None) -> Sweep:
    """A sweep given as a dict with the keys of a sweep file (the Python facade's).

    Args:
        data: Sweep keys (``scenarios``, ``controllers``, ``seeds``, ...); ``name``
            defaults to ``"sweep"``.
        base_dir: Folder that relative scenario patterns start from.
        seeds: As :func:`load_sweep`.
        overrides: As :func:`load_sweep`.

    Raises:
        ScenarioError: One line naming the key and the problem (file ``<dict>``).
    """
    data = {"name": "sweep", **dict(data)}
    text = json.dumps(data, sort_keys=True, default=str)
    return expand_sweep(data, DICT_SOURCE, Path(base_dir), text, seeds, overrides)


def expand_sweep(data: dict[str, Any], src: str, base: Path, text: str,
                 seeds: int | None = None,
                 overrides: Mapping[str, Any] | None = None) -> Sweep:
    """Validate and expand sweep keys read from ``src`` (its ``text`` goes in the manifest)."""
    spec = build(SweepSpec, data, src)
    if spec.max_seeds and spec.max_seeds < spec.seeds:
        raise ScenarioError(src, "max_seeds", f"must be 0 or >= seeds ({spec.seeds}), got "
                                              f"{spec.max_seeds}")
    if seeds is not None and not 1 <= seeds <= MAX_SEEDS:
        raise ScenarioError(src, "seeds", f"the seed count given instead ({seeds}) must be "
                                          f"between 1 and {MAX_SEEDS:,}")
    for k, x in (overrides or {}).items():
        check_value(x, "--set", k)
    from dfcoa_opt.control.plugins import is_file_spec, load_plugins

    load_plugins([str(base / p) if is_file_spec(p) else p for p in spec.plugins],
                 f"{src}: plugins")
    variants = _variants(spec, src, base)
    seeds_of = _variant_seeds(spec, variants, src)
    ladders = parse_ladders(spec.ladder, _flatten, src)
    grid = _grid(spec, src)
    points, varying = grid.points, grid.varying
    groups: list[tuple[list[Path], Ladder | None]] = []
    own = [lad for lad in ladders if lad.scenarios]
    if spec.scenarios:
        shared = next((lad for lad in ladders if not lad.scenarios), None)
        groups.append((_scenario_files(spec.scenarios, src, base, "scenarios"), shared))
    for i, lad in enumerate(own):
        groups.append((_scenario_files(lad.scenarios, src, base,
                                       f"ladder[{i}].scenarios"), lad))
    if not groups:
        raise ScenarioError(src, "scenarios", "lists no scenario")
    n_seeds = spec.seeds if seeds is None else seeds
    climbers = ladder_variants(ladders, variants, src)
    grows = spec.max_seeds if seeds is None else 0  # the seeds max_seeds may add count too
    total = sum(len(files) * (len(lad.rungs) if lad else 1) * grid.configurations(v.controller)
                * max(grows, n_seeds if seeds is not None else seeds_of.get(v.name, n_seeds))
                for files, lad in groups for v in climbers.get(lad, variants))
    if total > MAX_RUNS:
        counted = "max_seeds" if grows else "seeds"
        raise ScenarioError(src, "", f"the sweep has {total:,} runs (scenarios x variants x grid "
                                     f"points x ladder rungs x {counted}), more than the "
                                     f"{MAX_RUNS:,} a sweep may have; use fewer, or split the "
                                     "sweep")
    names: dict[str, Path] = {}
    probed: dict[tuple[str, str], Scenario] = {}
    cells: dict[RunSpec, int] = {}  # each (scenario, variant, rung): its seeds built
    runs: list[RunSpec] = []
    for files, lad in groups:
        for f, rung, point, v in itertools.product(files, lad.rungs if lad else (None,), points,
                                                   climbers.get(lad, variants)):
            base = {**point, **dict(rung.overrides if rung else ()), **(overrides or {})}
            _probe(f, base, spec.first_seed, src, probed)  # every grid key, whoever it reaches
            ov = {k: x for k, x in {**base, **dict(v.overrides)}.items()
                  if reaches(k, v.controller)}
            probe = _probe(f, ov, spec.first_seed, src, probed)
            scen = probe.name
            if spec.split:  # the seeds that max_seeds may add included
                most = max([n_seeds, *(seeds_of.values() if seeds is None else ())])
                last = spec.first_seed + max(most, spec.max_seeds if seeds is None else 0)
                check_split(probe, spec.split, range(spec.first_seed, last), src)
            if names.setdefault(scen, f) != f:
                raise ScenarioError(src, "scenarios", f"two scenarios are named '{scen}': "
                                                      f"{names[scen]} and {f}")
            name = v.name + suffix({k: x for k, x in point.items() if reaches(k, v.controller)},
                                   varying)
            count = n_seeds if seeds is not None else seeds_of.get(v.name, n_seeds)
            first = RunSpec(str(f), scen, v.controller, spec.first_seed, canonical(ov), name,
                            lad.label if lad else "", rung.value if rung else None)
            done = cells.setdefault(first, 0)  # controller-specific keys make duplicates:
            if done >= count:                   # each run is built once, where it first comes
                continue
            cells[first] = count
            if not done:
                _check_row(first, src)
            runs += [RunSpec(first.scenario_file, scen, v.controller, seed, first.overrides,
                             name, first.ladder, first.ladder_value)
                     for seed in range(spec.first_seed + done, spec.first_seed + count)]
    _check_unique(list(cells), src)  # every cell has the first seed: one run of each will do
    sweep = Sweep(spec, src, hashlib.sha256(text.encode()).hexdigest(), text,
                  tuple(runs), tuple(variants),
                  tuple(ladders), spec.max_seeds if seeds is None else 0)
    names_run = list(dict.fromkeys(r.variant_name for r in runs))
    if spec.baseline and spec.baseline not in names_run:
        raise ScenarioError(src, "baseline", f"'{spec.baseline}' is not a variant of this sweep"
                            + did_you_mean(spec.baseline, names_run)
                            + "; variants: " + ", ".join(names_run))
    return sweep


def check_split(scenario: Scenario, split: str, seeds: Iterable[int], src: str) -> None:
    """Every seed of ``seeds`` lies in ``split``'s range of the scenario's ``[splits]``.

    Raises:
        ScenarioError: The scenario declares no such range, or a seed lies outside
            it (the message names the split the seed belongs to, if any).
    """
    splits = scenario.spec.splits
    bounds = splits.range_of(split)
    if bounds is None:
        raise ScenarioError(src, "split", f"'{split}': scenario {scenario.name} "
                                          f"({scenario.source}) declares no [splits] {split} "
                                          "seed range")
    for seed in seeds:
        if not bounds[0] <= seed <= bounds[1]:
            other = splits.split_of(seed)
            where = f"a '{other}' seed" if other else "in no split"
            raise ScenarioError(src, "split", f"'{split}': seed {seed} of scenario "
                                              f"{scenario.name} is {where}, outside its "
                                              f"{split} seeds [{bounds[0]}, {bounds[1]}]")


def _probe(file: Path, overrides: Mapping[str, Any], seed: int, src: str,
           probed: dict[tuple[str, str], Scenario]) -> Scenario:
    """Load ``file`` with ``overrides`` once (validation); the scenario.

    ``probed`` caches the scenarios of the (file, overrides) pairs already loaded.
    """
    probe = RunSpec(str(file), file.stem, "", seed, canonical(overrides))
    if (str(file), probe.overrides) not in probed:
        try:
            probed[(str(file), probe.overrides)] = load_run_scenario(probe)
        except DfcoaError as exc:
            hint = f" (with overrides {json.dumps(dict(overrides))})" if overrides else ""
            raise ScenarioError(src, "scenarios", f"{exc}{hint}") from None
    return probed[(str(file), probe.overrides)]


def _check_row(run: RunSpec, src: str) -> None:
    """A run's row can be written: its identity is JSON without NaN or inf.

    The values are checked where the sweep file sets them; this is the last
    check, once per (scenario, variant, rung), before anything is written.

    Raises:
        ScenarioError: Naming the run's key.
    """
    identity = {"key": run.key, "scenario": run.scenario, "scenario_file": run.scenario_file,
                "controller": run.controller, "seed": run.seed,
                "overrides": run.overrides_dict, "variant": run.variant_name,
                "ladder": run.ladder, "ladder_value": run.ladder_value}
    try:
        json.dumps(identity, allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise ScenarioError(src, "", f"run {run.key}: its result row cannot be written as "
                                     f"JSON ({exc})") from None


def _check_unique(runs: Sequence[RunSpec], src: str) -> None:
    """Two runs with one key would share result files: name the variants apart."""
    seen: dict[str, RunSpec] = {}
    for r in runs:
        other = seen.setdefault(r.key, r)
        if other is not r:
            raise ScenarioError(src, "variants", f"two configurations of variant "
                                                 f"'{r.variant_name}' on {r.scenario} "
                                                 f"({other.overrides} and {r.overrides}); give "
                                                 "them different names")


def describe_runs(runs: Iterable[RunSpec]) -> str:
    """``12 runs: 2 scenarios x 3 variants x 2 seeds`` style summary."""
    runs = list(runs)
    sc = {r.scenario for r in runs}
    var = {r.variant_name for r in runs}
    sd = {r.seed for r in runs}
    rungs = {(r.scenario, r.ladder, r.ladder_value) for r in runs if r.ladder_value is not None}
    text = f"{len(runs)} runs: {len(sc)} scenarios x {len(var)} variants x {len(sd)} seeds"
    return text + (f" ({len(rungs)} ladder rungs)" if rungs else "")
