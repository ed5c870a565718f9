"""``make bench``: print one table of medians and write ``benchmarks/results.md``.

Each row gives the median, min-max, and the ratio against a reference measured
in the same run (``ref median / our median``: > 1 means we are faster): the
median over at least 5 interleaved repetitions, with the repetitions' min-max
(:mod:`benchmarks.timing`). The machine is noisy; compare ratios, not absolute
times across runs.
"""

from __future__ import annotations

import datetime
from pathlib import Path

from benchmarks import (
    bench_astar,
    bench_batch,
    bench_figures,
    bench_lidar,
    bench_mcl,
    bench_orca,
    bench_reshape,
    bench_sim,
    bench_startup,
    bench_vmas,
)
from benchmarks.timing import ratio_text
from dfcoa_opt.bench.recipes import registered
from dfcoa_opt.core.runtime.provenance import machine, versions

#: Targets from the issues (what, us). Matched by row-title prefix.
TARGETS = {
    "lidar scan 120 beams, 350x350 grid": 20.0,
    "simulator step, 4 unicycles": 500.0,
    "simulator step with mcl": 3000.0,
    "whole S1 run with mcl": 10_000_000.0,
    "A* search 35x35": 100.0,
    "A* search 1024x1024": 30000.0,
    "make figures from a fresh clone": 900e6,  # 15 minutes on 2 cores
    "reshape planning per replanning, corridor": 5000.0,
    "reshape planning per replanning, clutter": 5000.0,
    "reshape planning per replanning, large_20": 5000.0,
    "reshape planning per replanning, large_100": 50000.0,
    "ORCA step, Circle N=10000, one thread": 5000.0,
    "dfcoa --help": 300_000.0,
    "dfcoa list controllers": 1_000_000.0,
    "dfcoa run example_empty.toml": 2_000_000.0,
}
#: Each recipe's budget (its module's ``@recipe(..., budget=)``, CPU-s) bounds its cost row.
TARGETS.update({bench_figures.recipe_title(r.name): r.budget * 1e6
                for r in registered() if r.budget is not None})
#: Targets given as a ratio to the same-run reference (what prefix, minimum ratio).
RATIO_TARGETS = {
    "ORCA step, Circle N=100, one thread": 1.5,
    "ORCA step, Circle N=250, one thread": 1.5,
    "ORCA step, Circle N=1000, one thread": 1.5,
    "ORCA step, Circle N=10000, one thread": 1.5,
    "improved A* search per node": 1 / 1.2,
    # issue 21: JPS vs pyastar2d; matched by prefix, it applies to the JPS row against
    # our A* too (JPS must beat A* to be worth having)
    "JPS search 1024x1024": 1.0,
    # the vector environment against VMAS navigation, one thread each
    "vector env step, 4 robots, 12-beam LiDAR, E=1,": 10.0,
    "vector env step, 4 robots, 12-beam LiDAR, E=64,": 2.0,
    "vector env step, 4 robots, 12-beam LiDAR, E=1024,": 1.0,
    # batched simulation: a run-step in a batch of 20 against one run alone
    **{bench_batch.title(c, s): ratio for c, s, ratio in bench_batch.CASES},
}


def _target(what: str) -> str:
    for prefix, us in TARGETS.items():
        if what.startswith(prefix):
            return f"<= {us:g} us"
    for prefix, ratio in RATIO_TARGETS.items():
        if what.startswith(prefix):
            return f"ratio >= {ratio:.3g}x"
    return ""


def main() -> None:
    """Run every benchmark module, print the table, write results.md."""
    rows = (bench_lidar.run() + bench_sim.run() + bench_mcl.run() + bench_astar.run()
            + bench_orca.run() + bench_reshape.run() + bench_batch.run() + bench_startup.run()
            + bench_vmas.run()
            + bench_figures.run())
    head = [f"# Benchmarks ({datetime.date.today().isoformat()})", "",
            f"CPU: {machine()}; {versions()}.", "",
            "Ratio = reference median / our median, both measured in this run: the median "
            "of the per-repetition ratios over interleaved repetitions of ours and the "
            "reference, with their min-max.", "",
            "| what | median (us) | min-max (us) | target | reference | ref median (us) | ratio |",
            "|---|---|---|---|---|---|---|"]
    body = [f"| {r['what']} | {r['median_us']:.1f} | {r['min_us']:.1f}-{r['max_us']:.1f} | "
            f"{_target(r['what'])} | " + (f"{r['reference']} | {r['ref_median_us']:.1f} | "
                                          f"{ratio_text(r)} |" if "ratio" in r else
                                          "no peer | - | - |") for r in rows]
    text = "\n".join(head + body) + "\n"
    print(text)
    Path(__file__).with_name("results.md").write_text(text)


if __name__ == "__main__":
    main()
