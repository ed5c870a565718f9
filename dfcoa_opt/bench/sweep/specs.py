"""The data of a sweep: the keys of a sweep file, its runs and their names.

:class:`SweepSpec` is the schema of a sweep file (every key, its type, default
and bounds); :class:`RunSpec` is one simulation, everything a worker needs to
run it; :class:`Sweep` is a sweep validated and expanded by
:func:`~dfcoa_opt.bench.sweep.expand.load_sweep`.

Run keys (:attr:`RunSpec.key`), report files and results folders join the names
of scenarios, variants and ladder labels, made file-name-safe by
:func:`safe_name`. A name longer than :data:`NAME_MAX` characters, and a key that
could exceed :data:`KEY_MAX`, is cut short and ends in ``-`` and 8 hex digits of
the SHA-256 of the whole name (:func:`shorten`), so the same name always gives
the same file name and two names give two; shorter names are kept as they are.

Every public name here is re-exported by :mod:`dfcoa_opt.bench.sweep.expand`, the
module to import them from.
"""

from __future__ import annotations

import hashlib
import json
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, Literal

from dfcoa_opt.core.params import param
from dfcoa_opt.scenario.loader import load_scenario

if TYPE_CHECKING:
    from dfcoa_opt.bench.sweep.variants import Ladder, Variant
    from dfcoa_opt.scenario.scenario import Scenario

_UNSAFE = re.compile(r"[^A-Za-z0-9_.+-]+")
#: Longest name :func:`safe_name` returns (scenario, variant, ladder label: parts of file names).
NAME_MAX = 120
#: Longest run key, and longest file stem joined from several names; with the hidden
#: temporary name of an atomic write it stays well below the 255 bytes of a file name.
KEY_MAX = 200
_HEAD_MAX = KEY_MAX - len("__s") - 20  # a run key before its seed (20 digits hold any seed)
#: The source of a sweep given as a dict (:func:`~dfcoa_opt.bench.sweep.expand.sweep_from_dict`),
#: as its errors name it.
DICT_SOURCE = "<dict>"
#: Most runs a sweep may have, every seed ``max_seeds`` may add counted.
MAX_RUNS = 1_000_000
#: Most seeds per (scenario, variant, rung): ``seeds``, ``max_seeds``, ``[variant_seeds]``.
MAX_SEEDS = 100_000


def shorten(text: str, limit: int = NAME_MAX, full: str | None = None) -> str:
    """``text`` itself if it has at most ``limit`` characters, else a stable shorter form.

    The shorter form is the start of ``text``, ``-`` and the first 8 hex digits of
    the SHA-256 of ``full`` (default: ``text``), ``limit`` characters in all: the
    same input always gives the same name, and two inputs two names.

    Args:
        text: The name.
        limit: Most characters of the result.
        full: What the hash is taken of (default: ``text``), e.g. the name before
            :func:`safe_name` replaced its unsafe characters.

    Returns:
        ``text``, or its shortened form.
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

    Args:
        name: Any value; its ``str`` is the name.

    Returns:
        Letters, digits and ``_ . + -`` only (``_`` for a name with none of them).
    """
    full = str(name)
    return shorten(_UNSAFE.sub("_", full).strip("_") or "_", NAME_MAX, full)


@dataclass(frozen=True)
class SweepSpec:
    """A whole sweep file: every key, its type, default, bounds and doc."""

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
        overrides: Canonical JSON of the dotted-key overrides (:func:`canonical`).
        variant: Variant name; empty: the controller id.
        ladder: Label of the ladder the run climbs; empty without one.
        ladder_value: The value of its rung; None without a ladder.
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

        At most :data:`KEY_MAX` characters: each name
        is :func:`safe_name`, and the
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
        variants: The sweep's variants (plain controllers first, then named ones).
        ladders: Its difficulty ladders.
        max_seeds: ``spec.max_seeds``, or 0 when a seed count replaced the file's.
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


def canonical(overrides: Mapping[str, Any]) -> str:
    """Canonical JSON of an override set (sorted keys, no spaces): the hashed form.

    Args:
        overrides: Dotted key -> value.

    Returns:
        The JSON text :attr:`RunSpec.overrides` holds.
    """
    return json.dumps(dict(overrides), sort_keys=True, separators=(",", ":"))


def load_run_scenario(run: RunSpec) -> Scenario:
    """Load a run's scenario: the file, its seed replaced, its overrides applied.

    Args:
        run: The run.

    Returns:
        The validated scenario.

    Raises:
        ScenarioError: The file, or the file with the run's overrides, is invalid.
    """
    return load_scenario(run.scenario_file, run.seed, run.overrides_dict)


def describe_runs(runs: Iterable[RunSpec]) -> str:
    """``12 runs: 2 scenarios x 3 variants x 2 seeds`` style summary.

    Args:
        runs: The runs (of one sweep).

    Returns:
        One line, with the number of ladder rungs when there are any.
    """
    runs = list(runs)
    sc = {r.scenario for r in runs}
    var = {r.variant_name for r in runs}
    sd = {r.seed for r in runs}
    rungs = {(r.scenario, r.ladder, r.ladder_value) for r in runs if r.ladder_value is not None}
    text = f"{len(runs)} runs: {len(sc)} scenarios x {len(var)} variants x {len(sd)} seeds"
    return text + (f" ({len(rungs)} ladder rungs)" if rungs else "")
