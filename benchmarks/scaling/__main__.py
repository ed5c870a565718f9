"""Scaling study (issue 7): cost per step of every registered controller against team size N.

Run ``python -m benchmarks.scaling`` (full study, writes ``benchmarks/scaling.md``,
``scaling.csv`` and ``scaling.png``) or ``python -m benchmarks.scaling --quick``
(smoke configuration, prints only unless ``--out`` is given).

The command line only: the timing is :mod:`benchmarks.scaling.measure`, peak memory
(a fresh ``python -m benchmarks.scaling.memory`` subprocess per controller)
:mod:`benchmarks.scaling.memory`, the summary, CSV, plot and stdout tables
:mod:`benchmarks.scaling.report`, ``scaling.md`` :mod:`benchmarks.scaling.markdown`.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from benchmarks.scaling.markdown import markdown
from benchmarks.scaling.measure import BUDGET_S, SENSING_CALLS, measure, sensing_reference, warm_up
from benchmarks.scaling.memory import peak_memory
from benchmarks.scaling.report import plot, print_summary, summarise, write_csv
from dfcoa_opt.control.registry import available
from dfcoa_opt.core.runtime.provenance import machine, versions

#: Default folder of ``scaling.md``/``.csv``/``.png``: ``benchmarks/``.
OUT_DIR = Path(__file__).resolve().parent.parent
SIZES = (4, 16, 64, 256, 1000)
QUICK_SIZES = (4, 16, 64)


def _ints(text: str) -> list[int]:
    return [int(x) for x in text.split(",") if x.strip()]


def parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    """Command-line options (see ``--help``)."""
    ap = argparse.ArgumentParser(prog="python -m benchmarks.scaling",
                                 description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=_ints, default=None,
                    help=f"team sizes, comma-separated (default {','.join(map(str, SIZES))})")
    ap.add_argument("--controllers", default=None,
                    help="controller ids, comma-separated (default: every registered one)")
    ap.add_argument("--steps", type=int, default=None, help="measured steps per run (30)")
    ap.add_argument("--warmup", type=int, default=None, help="unmeasured steps per run (5)")
    ap.add_argument("--rounds", type=int, default=None, help="interleaved rounds (5)")
    ap.add_argument("--budget", type=float, default=BUDGET_S,
                    help="measured seconds per run before it is cut short (60)")
    ap.add_argument("--memory-n", type=int, default=None,
                    help="team size of the peak-memory runs (largest size); 0 = skip")
    ap.add_argument("--memory-steps", type=int, default=10, help="steps of a memory run")
    ap.add_argument("--out", type=Path, default=None,
                    help="folder for scaling.md/.csv/.png (default benchmarks/; --quick: none)")
    ap.add_argument("--quick", action="store_true",
                    help="smoke run: N=4,16,64, 2+5 steps, 1 round, memory at N=64, no files")
    args = ap.parse_args(argv)
    quick = args.quick
    args.sizes = args.sizes or list(QUICK_SIZES if quick else SIZES)
    args.steps = args.steps or (5 if quick else 30)
    args.warmup = args.warmup if args.warmup is not None else (2 if quick else 5)
    args.rounds = args.rounds or (1 if quick else 5)
    if args.memory_n is None:
        args.memory_n = max(args.sizes)
    if args.out is None and not quick:
        args.out = OUT_DIR
    return args


def main(argv: Sequence[str] | None = None) -> int:
    """Run the study; print the tables; write the files unless ``--quick`` without ``--out``.

    Returns:
        Process exit code (0).
    """
    args = parse_args(argv)
    t_start = time.perf_counter()
    controllers = (args.controllers.split(",") if args.controllers else available())
    sizes = sorted(set(args.sizes))
    print(f"CPU: {machine()}; {versions()}")
    print(f"controllers: {', '.join(controllers)}; sizes {sizes}; {args.rounds} round(s) of "
          f"{args.warmup} + {args.steps} steps")
    warm_up(controllers)
    samples, build = measure(controllers, sizes, args.warmup, args.steps, args.rounds,
                             args.budget)
    summary = summarise(samples, controllers, sizes)
    print_summary(summary, controllers, sizes)
    sensing = sensing_reference(sizes, SENSING_CALLS)
    for r in sensing:
        print(f"sensing N={r['n']:5d}: LiDAR as chosen {r['lidar_default']:.3f} ms, all pairs "
              f"{r['lidar_all_pairs']:.3f}, candidates {r['lidar_kdtree']:.3f}; proximity "
              f"{r['proximity']:.3f} ms, neighbour_table {r['neighbour_table']:.3f}")
    memory: dict[str, dict[str, float]] = {}
    ref_n = min(sizes)
    if args.memory_n:
        memory = peak_memory(controllers, args.memory_n, ref_n, args.memory_steps)
    elapsed = time.perf_counter() - t_start
    print(f"\nwhole run: {elapsed:.1f} s")
    if args.out is not None:
        cfg = {"rounds": args.rounds, "warmup": args.warmup, "steps": args.steps,
               "budget": args.budget, "memory_n": args.memory_n, "memory_ref_n": ref_n,
               "memory_steps": args.memory_steps, "sensing_calls": SENSING_CALLS}
        args.out.mkdir(parents=True, exist_ok=True)
        write_csv(summary, args.out / "scaling.csv")
        plot(summary, controllers, sizes, args.out / "scaling.png")
        (args.out / "scaling.md").write_text(
            markdown(summary, controllers, sizes, memory, build, cfg, elapsed, sensing))
        print(f"wrote {args.out / 'scaling.md'}, scaling.csv, scaling.png")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
