"""``dfcoa compare``: a controller among the published methods, on their very worlds.

A recipe that ranks methods (:data:`COMPARABLE`: ``heldout``, ``comparison``)
publishes its runs (``paper_figures/<recipe>/runs.csv``,
:mod:`dfcoa_opt.bench.results.published`). :func:`compare` simulates only
the new controller, on exactly the published worlds (the recipe's sweep:
its scenario files, test seeds and settings), and writes the recipe's own
tables with the new controller ranked among the published ones and paired
with them world by world. With ``tune``, it first tunes the controller with
the published methods' budget on the training seeds (the ``make tune``
sweep), writing the variants file into the results folder, not into the
repository.

Before it trusts the published rows it simulates a sample of them again --
one run of every published variant, or every run with ``verify="all"`` --
and compares their log digests: a published number that this code and
machine no longer reproduce is named in one line, with the commit the rows
came from, and the report carries the warning.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from dfcoa_opt.bench.executors import ExecutorConfig, run_all
from dfcoa_opt.bench.harness import run_sweep
from dfcoa_opt.bench.recipes import RECIPES
from dfcoa_opt.bench.recipes.heldout import heldout_report
from dfcoa_opt.bench.report import heldout as ho
from dfcoa_opt.bench.report.document import environment_header, make_report
from dfcoa_opt.bench.report.plots import variant_name
from dfcoa_opt.bench.results.published import RUNS_FILE, read_runs
from dfcoa_opt.bench.results.store import display_path
from dfcoa_opt.bench.sweep.expand import sweep_from_dict
from dfcoa_opt.bench.sweep.factors import scenario_files
from dfcoa_opt.bench.sweep.specs import RunSpec, canonical, safe_name
from dfcoa_opt.bench.tune import TUNED, tune_variant, tuning_sweep_of
from dfcoa_opt.core import plugins
from dfcoa_opt.core.errors import DfcoaError, did_you_mean
from dfcoa_opt.scenario.overrides import read_toml

#: The recipes a controller can be compared in: they publish their runs.
COMPARABLE = ("heldout", "comparison")
#: The tuning sweep whose budget and training seeds ``--tune`` uses (relative to the
#: scenario root), the one ``make tune`` ran for the published methods.
TUNE_SWEEP = "sweeps/tune.toml"
#: The sweep keys a comparison keeps from the recipe's sweep: what makes its worlds.
WORLD_KEYS = ("split", "first_seed", "grid", "description")


@dataclass(frozen=True)
class Mismatch:
    """A published run that this code simulates to another log digest.

    Attributes:
        key: The run's key.
        variant: Its variant.
        published: The published digest.
        now: The digest simulated here ("failed: ..." when the run failed).
    """

    key: str
    variant: str
    published: str
    now: str


@dataclass(frozen=True)
class CompareResult:
    """What a comparison did and found.

    Attributes:
        recipe: The recipe.
        variant: The compared controller's variant name (``<id>@tuned`` when tuned).
        report: The report's main file.
        rank: The variant's rank line (``"3-5 of 15"``), or "" when unranked.
        success: Its success cell of the ranking (``"45% [35, 55] (45/100)"``).
        ran: Runs of the new controller simulated now (cached ones aside).
        verified: Published runs simulated again.
        mismatches: Those whose digest differs.
        commit: The commit the published rows came from.
        tuned_file: The variants file ``--tune`` wrote, or None.
    """

    recipe: str
    variant: str
    report: Path
    rank: str
    success: str
    ran: int
    verified: int
    mismatches: tuple[Mismatch, ...] = ()
    commit: str = "unknown"
    tuned_file: Path | None = field(default=None)

    def summary(self) -> str:
        """The lines ``dfcoa compare`` prints."""
        where = (f"ranks {self.rank} (success {self.success})" if self.rank
                 else "is not in the ranking")
        lines = [f"{self.variant} {where} among the published methods of {self.recipe}; "
                 f"simulated {self.ran} runs of it -> {display_path(str(self.report))}"]
        if self.tuned_file is not None:
            lines.append(f"tuned: {display_path(str(self.tuned_file))}")
        if self.mismatches:
            lines.append(mismatch_line(self.mismatches, self.verified, self.commit))
        else:
            lines.append(f"verified: {self.verified} published runs simulated again give "
                         "their published digests")
        return "\n".join(lines)


def mismatch_line(mismatches: Sequence[Mismatch], verified: int, commit: str) -> str:
    """One line: how many published runs gave other digests here, and where they came from."""
    first = mismatches[0]
    return (f"warning: {len(mismatches)} of {verified} published runs simulated again give "
            f"other digests here (first: {first.key}, {first.variant}); the published rows "
            f"came from commit {commit}: their numbers are not this code's on this machine")


def published_path(root: Path, recipe: str) -> Path:
    """The published runs of a recipe under a figures folder (``paper_figures``)."""
    return root / recipe / RUNS_FILE


def _check_recipe(name: str) -> Any:
    """The recipe ``name``, which must publish its runs."""
    if name not in COMPARABLE:
        raise DfcoaError(f"compare: recipe '{name}' publishes no runs"
                         f"{did_you_mean(name, COMPARABLE)}; a controller is compared in: "
                         f"{', '.join(COMPARABLE)}")
    return RECIPES.get(name)


def _subset(rows: Sequence[Mapping[str, Any]], families: Sequence[str] | None,
            seeds: int | None) -> list[dict[str, Any]]:
    """The published rows of the chosen scenarios, on their first ``seeds`` seeds each."""
    known = sorted({str(r["scenario"]) for r in rows})
    if families:
        bad = [f for f in families if f not in known]
        if bad:
            raise DfcoaError(f"--families: '{bad[0]}' is not a scenario of the published runs"
                             f"{did_you_mean(bad[0], known)}; they are: {', '.join(known)}")
    kept = [dict(r) for r in rows if not families or str(r["scenario"]) in families]
    if seeds is not None:
        first = {s: sorted({int(r["seed"]) for r in kept if r["scenario"] == s})[:seeds]
                 for s in {str(r["scenario"]) for r in kept}}
        kept = [r for r in kept if int(r["seed"]) in first[str(r["scenario"])]]
    for r in kept:
        r["log"] = None  # its log is in the publisher's results folder, not here
    return kept


def _worlds(rows: Sequence[Mapping[str, Any]]) -> dict[str, list[int]]:
    """Scenario -> the seeds of its worlds, of the variants with the most worlds."""
    per: dict[tuple[str, str], set[int]] = {}
    for r in rows:
        per.setdefault((variant_name(r), str(r["scenario"])), set()).add(int(r["seed"]))
    out: dict[str, set[int]] = {}
    for (_, scen), seeds in per.items():
        if len(seeds) > len(out.get(scen, ())):
            out[scen] = seeds
    return {s: sorted(v) for s, v in sorted(out.items())}


def _scenario_files(data: Mapping[str, Any], sweep_file: Path) -> dict[str, str]:
    """Scenario name -> its file (absolute), as the recipe's sweep names them."""
    out = {}
    for path in scenario_files(data.get("scenarios", []), str(sweep_file), sweep_file.parent,
                               "scenarios"):
        out[str(read_toml(path).get("name") or path.stem)] = str(path)
    return out


def verify_runs(rows: Sequence[Mapping[str, Any]], files: Mapping[str, str], everything: bool,
                config: ExecutorConfig) -> tuple[int, list[Mismatch]]:
    """Simulate published runs again and compare their digests.

    Args:
        rows: Published rows (with ``overrides`` and ``digest``).
        files: Scenario name -> its file.
        everything: Every row; else the first row (by scenario, seed) of each variant.
        config: Executor of the runs.

    Returns:
        How many runs were simulated, and the mismatches.
    """
    ok = [r for r in rows if r.get("status") == "ok" and r.get("digest")]
    if not everything:
        first: dict[str, Mapping[str, Any]] = {}
        for r in sorted(ok, key=lambda r: (str(r["scenario"]), int(r["seed"]))):
            first.setdefault(variant_name(r), r)
        ok = list(first.values())
    specs = {}
    for r in ok:
        run = RunSpec(files[str(r["scenario"])], str(r["scenario"]),
                      str(r["controller"]), int(r["seed"]), canonical(r.get("overrides") or {}),
                      str(r.get("variant") or ""), str(r.get("ladder") or ""),
                      r.get("ladder_value"))
        specs[run.key] = (run, r)
    runs = [run for run, _ in specs.values()]
    bad = []
    for outcome in run_all(runs, config):
        row = outcome.row
        pub = specs[str(row["key"])][1]
        now = (str(row.get("digest")) if row["status"] == "ok"
               else f"failed: {row.get('error')}")
        if now != pub["digest"]:
            bad.append(Mismatch(str(row["key"]), variant_name(pub), str(pub["digest"]), now))
    return len(runs), sorted(bad, key=lambda m: m.key)


def _tune(controller: str, scenarios: Path, out: Path, config: ExecutorConfig,
          progress: bool | None) -> Path:
    """Tune ``controller`` as ``make tune`` tuned the published methods; its variants file."""
    path = scenarios / TUNE_SWEEP
    data = read_toml(path)
    data.update(controllers=[], variants={controller: {"controller": controller}},
                name=f"tune_{safe_name(controller)}")
    sweep, spec = tuning_sweep_of(data, path)
    return tune_variant(sweep, spec, controller, out / "tune", config, out / "tuned",
                        progress).path


def compare(recipe: str, controller: str, out: str | Path, *, scenarios: str | Path = "scenarios",
            figures: str | Path = "paper_figures", plugin_files: Sequence[str] = (),
            tune: bool = False, families: Sequence[str] | None = None,
            seeds: int | None = None, verify: str = "sample",
            config: ExecutorConfig | None = None, progress: bool | None = None
            ) -> CompareResult:
    """Put a controller among a recipe's published methods (module docstring).

    Args:
        recipe: One of :data:`COMPARABLE`.
        controller: A registry id (``+filter`` too), or ``policy:PATH``.
        out: Results folder: the new runs, the tuning, the report.
        scenarios: The scenario root (its ``sweeps/``).
        figures: The folder of the published runs (``paper_figures``).
        plugin_files: Plugins to load first (``--plugin``), also in the workers.
        tune: Tune the controller first, with the published methods' budget.
        families: Only these scenarios (``rooms,crowd``); default all.
        seeds: Only the first ``seeds`` worlds of each scenario; default all.
        verify: ``"sample"`` (one published run of each variant), ``"all"`` or
            ``"none"``.
        config: Executor of the runs.
        progress: Progress bars (default: when stdout is a terminal).

    Raises:
        DfcoaError: An unknown recipe, family or controller; no published runs; a
            bad ``verify`` or ``seeds``.
    """
    rec = _check_recipe(recipe)
    if verify not in ("sample", "all", "none"):
        raise DfcoaError(f"--verify: '{verify}' must be sample, all or none")
    if seeds is not None and seeds < 1:
        raise DfcoaError(f"--seeds: must be >= 1, got {seeds}")
    out, scenarios, config = Path(out).resolve(), Path(scenarios), config or ExecutorConfig()
    plugin_paths = [str(Path(p).resolve()) for p in plugin_files]
    plugins.load_plugins(plugin_paths)
    from dfcoa_opt.control.registry import controller_class

    controller_class(controller)  # an unknown id: one line before anything runs
    published, meta = read_runs(published_path(Path(figures), recipe))
    published = _subset(published, families, seeds)
    if not published:
        raise DfcoaError(f"{published_path(Path(figures), recipe)}: no published run left")
    sweep_file = scenarios / str(rec.sweep)
    data = read_toml(sweep_file)
    files = _scenario_files(data, sweep_file)
    missing = sorted({str(r["scenario"]) for r in published} - files.keys())
    if missing:
        raise DfcoaError(f"{sweep_file}: scenarios: no file is the published scenario "
                         f"'{missing[0]}'; the sweep's are: {', '.join(sorted(files))}")
    tuned_file = _tune(controller, scenarios, out, config, progress) if tune else None
    name = f"{controller}{TUNED}" if tune else controller
    worlds = _worlds(published)
    sweep_data: dict[str, Any] = {k: data[k] for k in WORLD_KEYS if k in data}
    sweep_data.update(name=f"{recipe}_{safe_name(controller)}", controllers=[],
                      scenarios=sorted(files[s] for s in worlds),
                      seeds=max(len(s) for s in worlds.values()), plugins=plugin_paths)
    if tuned_file is not None:
        sweep_data["variant_files"] = [str(tuned_file)]
    else:
        sweep_data["variants"] = {name: {"controller": controller}}
    sweep = sweep_from_dict(sweep_data, sweep_file.parent)
    runs = [r for r in sweep.runs if r.variant_name == name
            and int(r.seed) in worlds.get(r.scenario, ())]
    result = run_sweep(replace(sweep, runs=tuple(runs)), out / "runs", config,
                       progress=progress)
    verified, bad = ((0, []) if verify == "none"
                     else verify_runs(published, files, verify == "all", config))
    commit = meta.get("commit", "unknown")
    new_rows = result.store.rows()
    rows = [*published, *new_rows]
    report_dir = out / "report"
    report_dir.mkdir(parents=True, exist_ok=True)
    header = environment_header(result.store.root).rstrip("\n")
    header += (f"\n- Published runs: {published_path(Path(figures), recipe).as_posix()} "
               f"(commit {commit}); {verified} of them simulated again here"
               + (f", **{len(bad)} with another digest**" if bad else ", every digest the same"))
    warning = [f"> **Warning:** {mismatch_line(bad, verified, commit)}", ""] if bad else []
    baseline = str(data.get("baseline") or "")
    if recipe == "heldout":
        tuned_info = ho.read_tuned(sorted(sweep_file.parent.glob("tuned/*.toml"))
                                   + ([tuned_file] if tuned_file else []))
        heldout_report(rows, report_dir, baseline, tuned_info, header, None, ranked=[name])
        report = report_dir / "heldout.md"
    else:
        make_report(result.store.root, report_dir, baseline=baseline, rows=rows)
        report = report_dir / "report.md"
    if warning:
        report.write_text("\n".join(warning) + "\n" + report.read_text(encoding="utf-8"),
                          encoding="utf-8")
    rank, success = _rank(report.read_text(encoding="utf-8"), name)
    return CompareResult(recipe, name, report, rank, success, result.ran, verified,
                         tuple(bad), commit, tuned_file)


_RANK = re.compile(r"^\| ([0-9]+(?:-[0-9]+)?) \| (.+?) \| (.+?) \|")


def _rank(markdown: str, name: str) -> tuple[str, str]:
    """The variant's rank (``"3-5 of 15"``) and success cell in the report's first ranking."""
    lines = markdown.splitlines()
    start = next((i for i, ln in enumerate(lines) if ln.strip() == "### Ranking"), None)
    if start is None:
        return "", ""
    found, count = None, 0
    for ln in lines[start + 1:]:
        if ln.startswith("#"):
            break
        m = _RANK.match(ln)
        if m:
            count += 1
            if m.group(2).replace("\\", "") == name and found is None:
                found = (m.group(1), m.group(3))
    if found is None:
        return "", ""
    return f"{found[0]} of {count}", found[1]

