"""Reading, validating and expanding a sweep file into its runs (:func:`load_sweep`)."""

from __future__ import annotations

import hashlib
import itertools
import json
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from dfcoa_opt.bench.sweep.factors import (
    grid_of,
    scenario_files,
    variant_seeds_of,
    variants_of,
)
from dfcoa_opt.bench.sweep.specs import (
    DICT_SOURCE,
    MAX_RUNS,
    MAX_SEEDS,
    RunSpec,
    Sweep,
    SweepSpec,
    canonical,
    load_run_scenario,
)
from dfcoa_opt.bench.sweep.variants import (
    Ladder,
    check_value,
    ladder_variants,
    parse_ladders,
    reaches,
    suffix,
)
from dfcoa_opt.core.errors import DfcoaError, ScenarioError, did_you_mean
from dfcoa_opt.core.params import build
from dfcoa_opt.scenario.overrides import read_toml
from dfcoa_opt.scenario.scenario import Scenario

__all__ = ["check_split", "expand_sweep", "load_sweep", "sweep_from_dict"]


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

    Returns:
        The expanded sweep.

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

    Returns:
        The expanded sweep.

    Raises:
        ScenarioError: One line naming the key and the problem (file ``<dict>``).
    """
    data = {"name": "sweep", **dict(data)}
    text = json.dumps(data, sort_keys=True, default=str)
    return expand_sweep(data, DICT_SOURCE, Path(base_dir), text, seeds, overrides)


def expand_sweep(data: dict[str, Any], src: str, base: Path, text: str,
                 seeds: int | None = None,
                 overrides: Mapping[str, Any] | None = None) -> Sweep:
    """Validate and expand sweep keys read from ``src`` (its ``text`` goes in the manifest).

    Args:
        data: The sweep's keys, as read.
        src: Where they come from, for messages (a file, or :data:`DICT_SOURCE`).
        base: Folder that relative patterns (scenarios, plugins, variant files) start from.
        text: The sweep's text (its SHA-256 identifies the sweep).
        seeds: As :func:`load_sweep`.
        overrides: As :func:`load_sweep`.

    Returns:
        The expanded sweep.

    Raises:
        ScenarioError: One line naming ``src``, the key and the problem.
    """
    spec = build(SweepSpec, data, src)
    if spec.max_seeds and spec.max_seeds < spec.seeds:
        raise ScenarioError(src, "max_seeds", f"must be 0 or >= seeds ({spec.seeds}), got "
                                              f"{spec.max_seeds}")
    if seeds is not None and not 1 <= seeds <= MAX_SEEDS:
        raise ScenarioError(src, "seeds", f"the seed count given instead ({seeds}) must be "
                                          f"between 1 and {MAX_SEEDS:,}")
    for k, x in (overrides or {}).items():
        check_value(x, "--set", k)
    _load_plugins(spec.plugins, src, base)
    variants = variants_of(spec, src, base)
    seeds_of = variant_seeds_of(spec, variants, src)
    ladders = parse_ladders(spec.ladder, src)
    grid = grid_of(spec, src)
    points, varying = grid.points, grid.varying
    groups: list[tuple[list[Path], Ladder | None]] = []
    own = [lad for lad in ladders if lad.scenarios]
    if spec.scenarios:
        shared = next((lad for lad in ladders if not lad.scenarios), None)
        groups.append((scenario_files(spec.scenarios, src, base, "scenarios"), shared))
    for i, lad in enumerate(own):
        groups.append((scenario_files(lad.scenarios, src, base,
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

    Args:
        scenario: A scenario of the sweep.
        split: ``train``, ``validation`` or ``test``.
        seeds: The seeds its runs may take.
        src: The sweep, for messages.

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


def _load_plugins(plugins: Sequence[str], src: str, base: Path) -> None:
    """Import the sweep's ``plugins`` (files relative to ``base``) before its controllers.

    Raises:
        ScenarioError: Naming ``src`` and ``plugins[i]``: a file or module not
            found, or its import raised.
    """
    from dfcoa_opt.core.plugins import is_file_spec, load_plugin

    for i, plugin in enumerate(plugins):
        where = f"{src}: plugins[{i}]"
        try:
            load_plugin(str(base / plugin) if is_file_spec(plugin) else plugin, where)
        except DfcoaError as exc:  # "<where>: <plugin>: problem", or the plugin's own error
            raise ScenarioError(src, f"plugins[{i}]",
                                str(exc).removeprefix(f"{where}: ")) from None


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
