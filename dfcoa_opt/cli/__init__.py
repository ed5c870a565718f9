"""The ``dfcoa`` command (also ``python -m dfcoa_opt``).

Bad input (scenario files, names, options) prints one line
``dfcoa: error: FILE: KEY: problem`` on stderr and exits with code 2, never a
traceback. A run that fails (controller raised, returned NaN) exits with 1.
Ctrl-C or SIGTERM during ``bench`` or ``figures`` stops the workers, prints one
line saying how many runs are saved, and exits with 130 (SIGINT) or 143
(SIGTERM); rerunning the same command resumes.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import re
import signal
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from dfcoa_opt.bench.lifecycle import Interrupted, SweepInterrupted, interruptible
from dfcoa_opt.core.errors import DfcoaError, RunFailed

if TYPE_CHECKING:
    from dfcoa_opt.scenario.scenario import Scenario
    from dfcoa_opt.sim.log import RunLog

EXIT_BAD_INPUT = 2
EXIT_RUN_FAILED = 1


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="dfcoa", description="Multi-robot formation control "
                                "with obstacle avoidance: simulate, compare, reproduce papers.")
    sub = p.add_subparsers(dest="cmd", required=True)

    r = sub.add_parser("run", help="simulate one scenario with one controller")
    r.add_argument("scenario", help="scenario .toml file")
    r.add_argument("--controller", default="goto_slot", help="controller id (dfcoa list "
                   "controllers); default goto_slot")
    seed = r.add_mutually_exclusive_group()
    seed.add_argument("--seed", type=int, default=None, help="run seed (default: the file's seed)")
    seed.add_argument("--seeds", metavar="LIST", help="several runs stepped as one batch, e.g. "
                      "0-19 or 0,3,7 (one log per seed, the same as one run per --seed)")
    r.add_argument("--out", default="out", help="folder for the log .npz, metrics .json and "
                   "plots (default ./out)")
    r.add_argument("--json", action="store_true", help="print one JSON object to stdout")
    r.add_argument("--plot", action="store_true", help="write a PNG of map and trajectories")
    r.add_argument("--animate", metavar="FILE.gif", help="write a GIF animation")
    r.add_argument("--mcap", metavar="FILE.mcap", help="write the run as a rosbag2 MCAP file "
                   "for Foxglove / RViz 2 (needs the 'ros' extra; docs/ros.md)")
    _set_arg(r)

    ls = sub.add_parser("list", help="list controllers, scenarios or figure recipes")
    ls.add_argument("what", choices=("controllers", "scenarios", "recipes"))
    ls.add_argument("--dir", default="scenarios", help="where to look for scenarios")

    sub.add_parser("schema", help="print the scenario key reference (Markdown)")

    b = sub.add_parser("bench", help="run a sweep (controllers x scenarios x seeds) into a "
                       "results folder; resumes, --rerun forces")
    b.add_argument("sweep", help="sweep .toml file")
    b.add_argument("--out", help="results folder (default ./results/<sweep name>)")
    _executor_args(b)
    b.add_argument("--rerun", action="store_true", help="run again the runs that have a row")
    b.add_argument("--seeds", type=int, help="override the sweep's number of seeds")
    b.add_argument("--mcap", action="store_true", help="also write <out>/mcap/<key>.mcap for "
                   "every run the report's trajectory figures draw, simulated again with its "
                   "LiDAR scans (needs the 'ros' extra; docs/ros.md)")

    t = sub.add_parser("tune", help="tune variants of a tuning sweep with Optuna on its "
                       "training seeds (the same budget for each); resumes")
    t.add_argument("sweep", help="tuning sweep .toml (split = \"train\", a [tune] table)")
    t.add_argument("--variant", action="append", required=True, metavar="NAME",
                   help="variant to tune (repeatable); '*' = every variant of the sweep")
    t.add_argument("--out", default="results/tune", help="folder of the trials' runs and "
                   "journals (default results/tune)")
    t.add_argument("--variants-out", metavar="DIR", help="folder of the variants files "
                   "(default: [tune] out, beside the sweep file)")
    t.add_argument("--trials", type=int, help="override [tune] trials (quick runs)")
    _executor_args(t)

    rp = sub.add_parser("report", help="tables (Markdown, CSV) and figures from a results "
                        "folder; never re-simulates")
    rp.add_argument("results", help="results folder written by dfcoa bench")
    rp.add_argument("--out", help="output folder (default RESULTS/report)")
    rp.add_argument("--baseline", help="variant to compare the others with (default: the "
                                       "sweep's baseline; '' for none)")

    c = sub.add_parser("compare", help="put a controller among the published methods of a "
                       "recipe (heldout, comparison): simulate only it, on their worlds")
    c.add_argument("recipe", help="heldout or comparison")
    c.add_argument("--controller", required=True, help="controller id (a --plugin's too)")
    c.add_argument("--tune", action="store_true", help="tune it first with the published "
                   "methods' budget on the training seeds (scenarios/sweeps/tune.toml)")
    c.add_argument("--families", help="only these scenarios, comma-separated (e.g. "
                   "rooms,crowd)")
    c.add_argument("--seeds", type=int, help="only the first N worlds of each scenario")
    c.add_argument("--verify", choices=("sample", "all", "none"), default="sample",
                   help="simulate again one published run of each variant (sample, the "
                        "default), every one (all) or none, and compare the digests")
    c.add_argument("--out", help="results folder (default ./results/compare_<recipe>_<id>)")
    c.add_argument("--scenarios", default="scenarios", help="scenario root holding sweeps/")
    c.add_argument("--published", default="paper_figures", help="folder of the published runs "
                   "(default paper_figures)")
    _executor_args(c)

    f = sub.add_parser("figures", help="regenerate every paper table and figure (make figures)")
    f.add_argument("--out", default="paper_figures", help="output folder (default paper_figures)")
    f.add_argument("--scenarios", default="scenarios", help="scenario root holding sweeps/")
    f.add_argument("--cache", default=".dfcoa-cache", help="result cache (default .dfcoa-cache)")
    f.add_argument("--only", action="append", help="only this recipe (repeatable)")
    f.add_argument("--seeds", type=int, help="override every recipe's seed count (quick runs)")
    f.add_argument("--keep-logs", action="store_true", help="keep every run's full log in the "
                   "cache (default: prune the logs figures read to the fields read, compact "
                   "the others)")
    _executor_args(f)
    for name in ("run", "list", "bench", "tune", "report", "compare", "figures"):
        sub.choices[name].add_argument(
            "--plugin", action="append", default=[], metavar="FILE.py|MODULE",
            help="import a controller file or module first (repeatable; also "
                 "$DFCOA_PLUGINS, ':'-separated)")
    return p


def _executor_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--executor", choices=("serial", "process", "dask"), default=None,
                   help="default: process (dask when --scheduler or --dask-local is given)")
    p.add_argument("--jobs", type=int, help="worker processes (default: the core count)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--scheduler", metavar="ADDR", help="Dask scheduler, e.g. tcp://host:8786")
    g.add_argument("--dask-local", type=int, metavar="N", help="start a local Dask cluster "
                   "with N workers")
    p.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                   help="progress bar (default: when stdout is a terminal)")
    _set_arg(p)


def _set_arg(p: argparse.ArgumentParser) -> None:
    """The ``--set KEY=VALUE`` option (run, bench, tune, figures), read by :func:`_overrides`."""
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="dotted scenario key set in every run before validation, VALUE in "
                        "TOML syntax; a bare word is a string (e.g. --set t_max=5.0 "
                        "--set formation.shape=line); repeatable")


_BARE_WORD = re.compile(r"[A-Za-z_][A-Za-z0-9_.\-]*")


def parse_set_value(value: str):
    """The VALUE of ``--set KEY=VALUE``: a TOML value, else a bare word as a string.

    TOML first, so ``5``, ``5.0``, ``true``, ``inf``, ``[1, 2]`` and ``"a b"``
    keep their meaning; a bare word (``line``, ``turtlebot3_burger``) is that
    string.

    Raises:
        ValueError: Neither a TOML value nor a bare word.
    """
    import tomllib

    try:
        return tomllib.loads(f"v = {value}")["v"]
    except tomllib.TOMLDecodeError:
        if _BARE_WORD.fullmatch(value.strip()):
            return value.strip()
        raise ValueError(value) from None


def _overrides(items: Sequence[str]) -> dict | None:
    """``--set KEY=VALUE`` options as a dict (VALUE read by :func:`parse_set_value`)."""
    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise DfcoaError(f"--set: '{item}' is not KEY=VALUE")
        try:
            out[key.strip()] = parse_set_value(value)
        except ValueError:
            raise DfcoaError(f"--set: {key.strip()}: '{value}' is not a TOML value or a bare "
                             "word (quote other strings)") from None
    return out or None


def _executor(a: argparse.Namespace):
    from dfcoa_opt.bench.executors import ExecutorConfig

    kind = a.executor or ("dask" if a.scheduler or a.dask_local else "process")
    return ExecutorConfig(kind, a.jobs, a.scheduler, a.dask_local)


def _cmd_bench(a: argparse.Namespace) -> int:
    from dfcoa_opt.bench.harness import default_folder, run_sweep
    from dfcoa_opt.bench.sweep.expand import load_sweep

    if a.seeds is not None and a.seeds < 1:
        raise DfcoaError(f"--seeds: must be >= 1, got {a.seeds}")
    config = _executor(a)
    if a.mcap:
        from dfcoa_opt.viz.mcap import require_rosbags

        require_rosbags()  # before the sweep, not after it
    sweep = load_sweep(a.sweep, a.seeds, _overrides(a.set))
    out = Path(a.out) if a.out else default_folder(sweep)
    result = run_sweep(sweep, out, config, rerun=a.rerun, progress=a.progress)
    print(result.summary())
    if a.mcap:
        from dfcoa_opt.bench.report.document import load_rows
        from dfcoa_opt.bench.report.mcap_runs import MCAP_DIR, write_run_mcaps

        files, notes = write_run_mcaps(out, load_rows(out))
        print(f"mcap: {len(files)} files in {out / MCAP_DIR} (the runs the report's "
              "trajectory figures draw)")
        for note in notes:
            print(f"  note: {note}")
    print(f"report: dfcoa report {out}")
    return 0


def _cmd_tune(a: argparse.Namespace) -> int:
    from dfcoa_opt.bench.executors import kept_workers
    from dfcoa_opt.bench.tune import tune_variant, tuning_sweep

    if a.trials is not None and a.trials < 1:
        raise DfcoaError(f"--trials: must be >= 1, got {a.trials}")
    if a.set:
        raise DfcoaError("--set: dfcoa tune runs the tuning sweep as written (its settings are "
                         "part of what the tuned variants mean)")
    config = _executor(a)
    sweep, spec = tuning_sweep(a.sweep, a.trials)
    names = [v.name for v in sweep.variants]
    wanted = names if "*" in a.variant else list(dict.fromkeys(a.variant))
    with kept_workers(config):  # one pool of workers for every trial of every variant
        for name in wanted:
            result = tune_variant(sweep, spec, name, Path(a.out), config, a.variants_out,
                                  a.progress)
            best, first = result.best, result.trials[0]
            print(f"{name}: best trial {best.number} of {len(result.trials)}: "
                  f"{best.successes}/{best.runs} succeeded on training seeds (defaults: "
                  f"{first.successes}/{first.runs}); ran {result.ran} runs -> {result.path}")
    return 0


def _cmd_compare(a: argparse.Namespace) -> int:
    from dfcoa_opt.bench.compare import compare
    from dfcoa_opt.bench.executors import kept_workers
    from dfcoa_opt.bench.sweep.specs import safe_name

    config = _executor(a)
    out = a.out or f"results/compare_{a.recipe}_{safe_name(a.controller)}"
    families = [f.strip() for f in a.families.split(",") if f.strip()] if a.families else None
    with kept_workers(config):  # one pool for the tuning, the runs and the check
        result = compare(a.recipe, a.controller, out, scenarios=a.scenarios,
                         figures=a.published, plugin_files=a.plugin, tune=a.tune,
                         families=families, seeds=a.seeds, verify=a.verify, config=config,
                         progress=a.progress)
    print(result.summary())
    return 0


def _cmd_report(a: argparse.Namespace) -> int:
    from dfcoa_opt.bench.report.document import make_report

    results = Path(a.results)
    if a.baseline:
        from dfcoa_opt.bench.report.document import load_rows
        from dfcoa_opt.bench.report.plots import variant_name
        from dfcoa_opt.core.errors import did_you_mean

        names = sorted({variant_name(r) for r in load_rows(results)})
        if a.baseline not in names:
            raise DfcoaError(f"--baseline: '{a.baseline}' is not a variant of {results}"
                             f"{did_you_mean(a.baseline, names)}; variants: {', '.join(names)}")
    paths = make_report(results, Path(a.out) if a.out else None, baseline=a.baseline)
    for p in paths:
        print(p)
    return 0


def seed_list(text: str) -> list[int]:
    """The seeds of ``--seeds``: ``0-19``, ``0,3,7`` or both (``0-4,10``), in that order.

    At most :data:`~dfcoa_opt.bench.sweep.specs.MAX_SEEDS`, the bound of a sweep's
    seeds, counted before any run is built.

    Raises:
        DfcoaError: Not such a list, a seed below 0, a seed twice, or too many seeds.
    """
    from dfcoa_opt.bench.sweep.specs import MAX_SEEDS

    seeds: list[int] = []
    for part in text.split(","):
        lo, dash, hi = part.strip().partition("-")
        try:
            first, last = int(lo), int(hi if dash else lo)
        except ValueError:
            raise DfcoaError(f"--seeds: '{text}' is not a seed list (e.g. 0-19 or 0,3,7)") from None
        if first < 0 or last < first:
            raise DfcoaError(f"--seeds: '{part.strip()}' must be a seed >= 0 or a range lo-hi "
                             f"with lo <= hi")
        if len(seeds) + last - first + 1 > MAX_SEEDS:
            raise DfcoaError(f"--seeds: '{text}' names more than {MAX_SEEDS:,} seeds, the most "
                             f"a sweep takes; run them as a sweep in parts (dfcoa bench)")
        seeds += range(first, last + 1)
    if len(set(seeds)) != len(seeds):
        raise DfcoaError(f"--seeds: '{text}' names a seed twice")
    return seeds


def _cmd_run(a: argparse.Namespace) -> int:
    from dfcoa_opt import metrics
    from dfcoa_opt.bench.runner import jsonable
    from dfcoa_opt.bench.sweep.specs import safe_name
    from dfcoa_opt.cli.text import robot_text, run_summary
    from dfcoa_opt.metrics.units import units
    from dfcoa_opt.scenario.loader import load_scenario
    from dfcoa_opt.sim.batch import BatchSimulator
    from dfcoa_opt.sim.simulator import batch_controllers

    seeds = seed_list(a.seeds) if a.seeds is not None else [a.seed]
    scenario = load_scenario(a.scenario, seeds[0], _overrides(a.set), "--set")
    if a.animate and not a.animate.lower().endswith(".gif"):
        raise DfcoaError(f"--animate: '{a.animate}' must end in .gif")
    if a.animate and len(seeds) > 1:
        raise DfcoaError("--animate: one GIF needs one run; use --seed")
    if a.mcap and not a.mcap.lower().endswith(".mcap"):
        raise DfcoaError(f"--mcap: '{a.mcap}' must end in .mcap")
    if a.mcap and len(seeds) > 1:
        raise DfcoaError("--mcap: one file holds one run; use --seed")
    if a.mcap:
        from dfcoa_opt.viz.mcap import require_rosbags, write_mcap

        require_rosbags()  # before the run, not after it
    sim = BatchSimulator(scenario, batch_controllers(a.controller, scenario, len(seeds)), seeds,
                         record_scans=bool(a.mcap))
    try:
        logs = sim.run_all()
    except RunFailed as exc:  # a controller's bad command, a state beyond float range
        print(f"dfcoa: run failed: {one_line(str(exc))}", file=sys.stderr)
        return EXIT_RUN_FAILED
    for sc, log in zip(sim.scenarios, logs, strict=True):
        summary = metrics.summary(log, sc.spec.metrics)
        seed = log.meta["seed"]
        stem = Path(a.out) / safe_name(f"{sc.name}-{a.controller}-s{seed}")
        log.save(f"{stem}.npz")
        result = {"scenario": sc.name, "controller": a.controller, "seed": seed,
                  "metrics": jsonable(summary), "units": units(summary)}
        Path(f"{stem}.json").write_text(json.dumps(result, indent=2) + "\n")
        if a.plot or a.animate:
            from dfcoa_opt.viz import animation, plotting

            goal, start = sc.spec.leader.goal, sc.spec.leader.start
            if a.plot:
                plotting.plot_run(log, sc.world.grid, Path(f"{stem}.png"), goal=goal,
                                  start=start, shapes=sc.world.shapes, metrics=sc.spec.metrics)
            if a.animate:
                animation.animate_run(log, sc.world.grid, a.animate, goal=goal, start=start,
                                      shapes=sc.world.shapes, metrics=sc.spec.metrics)
        if a.mcap:
            write_mcap(log, a.mcap, sc.world)
        if a.json:
            print(json.dumps(result))  # one object per line (JSON Lines) with --seeds
            continue
        files = {"log": f"{stem}.npz", "metrics": f"{stem}.json"}
        files.update({"plot": f"{stem}.png"} if a.plot else {})
        files.update({"animation": a.animate} if a.animate else {})
        files.update({"mcap": a.mcap} if a.mcap else {})
        print(run_summary(f"{sc.name} / {a.controller} / seed {seed}", summary,
                          float(log.t[-1]), float(log.meta["wall_time"]), files,
                          detail=len(seeds) == 1, robots=robot_text(log.meta.get("robots")),
                          collided=_collided(log, sc)))
    return 0


def _collided(log: RunLog, scenario: Scenario) -> str:
    """Who touched what at a run's first contact (``""`` without one), as figure titles say it."""
    from dfcoa_opt.metrics.contacts import contacts_at, describe, first_contact_step

    k = first_contact_step(log)
    return "" if k is None else describe(contacts_at(log, k, scenario.world.grid))


def _cmd_list(a: argparse.Namespace) -> int:
    if a.what == "controllers":
        from dfcoa_opt.cli.text import controller_list

        print(controller_list())
        return 0
    if a.what == "recipes":
        from dfcoa_opt.bench.recipes import registered

        for r in registered():
            print(f"{r.name:18s} {r.sweep or '(no sweep)':31s} {r.title}")
        return 0
    root = Path(a.dir)
    if not root.is_dir():
        raise DfcoaError(f"{root}: scenario folder not found")
    for path in sorted(root.rglob("*.toml")):
        if "sweeps" not in path.relative_to(root).parts:  # sweep files are not scenarios
            print(path)
    return 0


def _cmd_schema(_: argparse.Namespace) -> int:
    from dfcoa_opt.scenario.reference import schema_markdown

    print(schema_markdown(), end="")
    return 0


def _cmd_figures(a: argparse.Namespace) -> int:
    from dfcoa_opt.bench.figures import make_figures

    if a.seeds is not None and a.seeds < 1:
        raise DfcoaError(f"--seeds: must be >= 1, got {a.seeds}")
    index = make_figures(Path(a.scenarios), Path(a.out), Path(a.cache), _executor(a),
                         only=a.only, seeds=a.seeds, progress=a.progress,
                         overrides=_overrides(a.set), compact=not a.keep_logs)
    print(index)
    return 0


def one_line(text: str) -> str:
    """``text`` on one line: line breaks and other control characters written as escapes.

    A message quotes what the user gave (a controller id, a key, a file name),
    which may hold a line break; the error is still one line.
    """
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the exit code."""
    args = _parser().parse_args(argv)
    handlers = {"run": _cmd_run, "list": _cmd_list, "schema": _cmd_schema,
                "bench": _cmd_bench, "tune": _cmd_tune, "report": _cmd_report,
                "compare": _cmd_compare, "figures": _cmd_figures}
    # bench and figures: SIGTERM too stops them with one line (and SIGINT raises
    # Interrupted rather than KeyboardInterrupt) from the start, imports included
    stoppable = (interruptible() if args.cmd in ("bench", "tune", "compare", "figures")
                 else contextlib.nullcontext())
    try:
        with stoppable:
            if getattr(args, "plugin", None):
                from dfcoa_opt.core.plugins import load_plugins

                load_plugins(args.plugin)
            return handlers[args.cmd](args)
    except DfcoaError as exc:
        print(f"dfcoa: error: {one_line(str(exc))}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except SweepInterrupted as exc:  # every finished run is saved
        print(f"dfcoa: {exc}", file=sys.stderr)
        return exc.exit_code
    except (Interrupted, KeyboardInterrupt) as exc:
        signum = getattr(exc, "signum", signal.SIGINT)
        print("dfcoa: interrupted; every finished run is saved: run the same command to "
              "resume", file=sys.stderr)
        return 128 + int(signum)
    except BrokenPipeError:  # output piped into e.g. `head`, which stopped reading
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
