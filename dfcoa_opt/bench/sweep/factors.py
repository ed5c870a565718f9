"""The factors a sweep crosses: scenario files, variants, grid points and seed counts.

Each function reads one group of a sweep file's keys (:class:`SweepSpec`) and
checks it, naming the sweep file and the key in every error;
:func:`~dfcoa_opt.bench.sweep.expand.expand_sweep` takes their product (with the
ladder rungs and the seeds). Named variants and ladders themselves are parsed
by :mod:`dfcoa_opt.bench.sweep.variants`.
"""

from __future__ import annotations

import fnmatch
import glob
import itertools
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from dfcoa_opt.bench.sweep.specs import MAX_RUNS, SweepSpec, canonical
from dfcoa_opt.bench.sweep.variants import Variant, check_value, named_variants, reaches
from dfcoa_opt.core.errors import ScenarioError, did_you_mean
from dfcoa_opt.scenario.overrides import flatten, read_toml


@dataclass(frozen=True)
class Grid:
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


def grid_of(spec: SweepSpec, src: str) -> Grid:
    """Grid points (with the older ``[[variants]]`` override sets) and the keys that vary.

    Args:
        spec: The sweep's keys (``grid``, and ``variants`` in its array form).
        src: The sweep, for messages.

    Returns:
        The grid.

    Raises:
        ScenarioError: A grid key without values, a value a row cannot hold (NaN,
            inf, a date), or more than :data:`~dfcoa_opt.bench.sweep.specs.MAX_RUNS`
            combinations (refused before they are built).
    """
    grid = flatten(spec.grid)
    for k, v in grid.items():
        if not isinstance(v, list) or not v:
            raise ScenarioError(src, f"grid.{k}", "must be a non-empty array of values")
        for i, x in enumerate(v):
            check_value(x, src, f"grid.{k}[{i}]")
    sets: list[dict[str, Any]] = [{}]
    if isinstance(spec.variants, list):
        if not all(isinstance(v, Mapping) for v in spec.variants):
            raise ScenarioError(src, "variants", "[[variants]] must be tables of dotted keys")
        sets = [flatten(v) for v in spec.variants] or [{}]
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
    return Grid([{**v, **p} for v in sets for p in points], varying,
                {k: len(v) for k, v in grid.items()}, sets)


def variants_of(spec: SweepSpec, src: str, base: Path) -> list[Variant]:
    """Plain controllers (named by id), the ``[variants]`` table and the variant files' tables.

    Args:
        spec: The sweep's keys (``controllers``, ``variants``, ``variant_files``).
        src: The sweep, for messages.
        base: Folder the ``variant_files`` patterns are relative to.

    Returns:
        Every variant: the plain controllers first, then the named ones.

    Raises:
        ScenarioError: An unknown controller, a variant file that cannot be read or
            names no variant, a variant named like a plain controller, or no
            variant at all (``controllers = []`` and no named variant).
    """
    from dfcoa_opt.control.registry import available, controller_class
    from dfcoa_opt.core.errors import UnknownNameError

    named = (named_variants(spec.variants, src)
             if isinstance(spec.variants, Mapping) else [])
    read: list[Path] = []
    for i, pattern in enumerate(spec.variant_files):
        for path in _matches(pattern, src, base, f"variant_files[{i}]"):
            if path not in read:
                read.append(path)
                named += _variant_file(path, src, f"variant_files[{i}]")
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
    if not out:
        raise ScenarioError(src, "controllers", "lists no controller (and the sweep names no "
                                                "variant)")
    return out


def _variant_file(path: Path, src: str, key: str) -> list[Variant]:
    """The named variants of one ``variant_files`` file (its ``[variants]`` table).

    Raises:
        ScenarioError: Naming ``src`` and ``key``, then the variant file's own
            problem (it cannot be read, is not TOML, or has no valid ``[variants]``).
    """
    try:
        table = read_toml(path).get("variants")
        if not isinstance(table, Mapping) or not table:
            raise ScenarioError(str(path), "variants", "is required: a table of named variants "
                                                       "([variants.<name>] controller = ...)")
        return named_variants(table, str(path))
    except ScenarioError as exc:
        raise ScenarioError(src, key, str(exc)) from None


def variant_seeds_of(spec: SweepSpec, variants: Sequence[Variant], src: str) -> dict[str, int]:
    """Each variant's seed count from ``[variant_seeds]`` (only those a pattern names).

    Args:
        spec: The sweep's keys.
        variants: The sweep's variants (:func:`variants_of`).
        src: The sweep, for messages.

    Returns:
        Variant name -> its seed count, for the variants a pattern names (the first
        pattern that matches).

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


def _matches(pattern: str, src: str, base: Path, key: str) -> list[Path]:
    """The files (resolved, sorted) a pattern relative to ``base`` matches.

    Raises:
        ScenarioError: Naming ``key``: the pattern matches no file.
    """
    hits = sorted(Path(p) for p in glob.glob(str(base / pattern)))
    if not hits:
        raise ScenarioError(src, key, f"'{pattern}' matches no file (relative to {base})")
    return [h.resolve() for h in hits]


def scenario_files(patterns: Sequence[str], src: str, base: Path, key: str) -> list[Path]:
    """The files the patterns of ``key`` match, each once, in the order of the patterns.

    Args:
        patterns: Files or globs, relative to ``base``.
        src: The sweep, for messages.
        base: The folder the patterns are relative to.
        key: The sweep key that lists them (``scenarios``, ``ladder[0].scenarios``).

    Returns:
        Resolved paths, sorted within each pattern.

    Raises:
        ScenarioError: Naming ``key[i]``: a pattern that matches no file.
    """
    files: list[Path] = []
    for i, pattern in enumerate(patterns):
        files += [h for h in _matches(pattern, src, base, f"{key}[{i}]") if h not in files]
    return files
