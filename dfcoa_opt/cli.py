"""The ``dfcoa`` command (also ``python -m dfcoa_opt``).

Bad input (scenario files, names, options) prints one line
``dfcoa: error: FILE: KEY: problem`` on stderr and exits with code 2, never a
traceback. A run that fails (controller raised, returned NaN) exits with 1.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from dfcoa_opt.errors import DfcoaError

EXIT_BAD_INPUT = 2
EXIT_RUN_FAILED = 1


def _jsonable(x: Any) -> Any:
    """Floats that JSON cannot hold (NaN, inf) become ``null``."""
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    return x


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="dfcoa", description="Multi-robot formation control "
                                "with obstacle avoidance: simulate, compare, reproduce papers.")
    sub = p.add_subparsers(dest="cmd", required=True)

    r = sub.add_parser("run", help="simulate one scenario with one controller")
    r.add_argument("scenario", help="scenario .toml file")
    r.add_argument("--controller", default="goto_slot", help="controller id (dfcoa list "
                   "controllers); default goto_slot")
    r.add_argument("--seed", type=int, default=None, help="run seed (default: the file's seed)")
    r.add_argument("--out", default="out", help="folder for the log .npz, metrics .json and "
                   "plots (default ./out)")
    r.add_argument("--json", action="store_true", help="print one JSON object to stdout")
    r.add_argument("--plot", action="store_true", help="write a PNG of map and trajectories")
    r.add_argument("--animate", metavar="FILE.gif", help="write a GIF animation")

    ls = sub.add_parser("list", help="list controllers or scenarios")
    ls.add_argument("what", choices=("controllers", "scenarios"))
    ls.add_argument("--dir", default="scenarios", help="where to look for scenarios")

    sub.add_parser("schema", help="print the scenario key reference (Markdown)")

    f = sub.add_parser("figures", help="regenerate tables and figures")
    f.add_argument("--out", default="paper_figures")
    f.add_argument("--scenarios", default="scenarios")
    return p


def _cmd_run(a: argparse.Namespace) -> int:
    from dfcoa_opt import metrics
    from dfcoa_opt.sim.loader import load_scenario
    from dfcoa_opt.sim.simulator import ControllerError, run_scenario

    scenario = load_scenario(a.scenario)
    if a.animate and not a.animate.lower().endswith(".gif"):
        raise DfcoaError(f"--animate: '{a.animate}' must end in .gif")
    try:
        log = run_scenario(scenario, a.controller, a.seed)
    except ControllerError as exc:
        print(f"dfcoa: run failed: {exc}", file=sys.stderr)
        return EXIT_RUN_FAILED
    summary = metrics.summary(log, scenario.spec.metrics)
    seed = log.meta["seed"]
    out = Path(a.out)
    stem = out / f"{scenario.name}-{a.controller}-s{seed}"
    log.save(stem.with_suffix(".npz"))
    result = {"scenario": scenario.name, "controller": a.controller, "seed": seed,
              "metrics": _jsonable(summary)}
    stem.with_suffix(".json").write_text(json.dumps(result, indent=2) + "\n")
    if a.plot or a.animate:
        from dfcoa_opt import plotting

        goal, start = scenario.spec.leader.goal, scenario.spec.leader.start
        if a.plot:
            plotting.plot_run(log, scenario.world.grid, stem.with_suffix(".png"), goal=goal,
                              start=start, shapes=scenario.world.shapes)
        if a.animate:
            plotting.animate_run(log, scenario.world.grid, a.animate, goal=goal, start=start,
                                 shapes=scenario.world.shapes)
    if a.json:
        print(json.dumps(result))
    else:
        print(f"{scenario.name} / {a.controller} / seed {seed}: "
              f"{'reached goal' if summary['success'] else 'did not reach goal'} "
              f"in {log.t[-1]:.1f} s simulated ({log.meta['wall_time']:.2f} s wall)")
        for k, v in summary.items():
            print(f"  {k:28s} {v}")
        print(f"  log: {stem.with_suffix('.npz')}")
    return 0


def _cmd_list(a: argparse.Namespace) -> int:
    if a.what == "controllers":
        from dfcoa_opt.control.registry import available, controller_class

        for cid in available():
            doc = (controller_class(cid).__doc__ or "").strip().splitlines()
            print(f"{cid:20s} {doc[0] if doc else ''}")
        return 0
    root = Path(a.dir)
    if not root.is_dir():
        raise DfcoaError(f"{root}: scenario folder not found")
    for path in sorted(root.rglob("*.toml")):
        print(path)
    return 0


def _cmd_schema(_: argparse.Namespace) -> int:
    from dfcoa_opt.sim.docs import schema_markdown

    print(schema_markdown(), end="")
    return 0


def _cmd_figures(a: argparse.Namespace) -> int:
    from dfcoa_opt.figures import make_figures

    make_figures(Path(a.scenarios), Path(a.out))
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the exit code."""
    args = _parser().parse_args(argv)
    handlers = {"run": _cmd_run, "list": _cmd_list, "schema": _cmd_schema,
                "figures": _cmd_figures}
    try:
        return handlers[args.cmd](args)
    except DfcoaError as exc:
        print(f"dfcoa: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
