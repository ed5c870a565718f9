"""Figure recipe "beyond": the ``cbf`` filter and the ``nmpc`` controller.

The same report as the "comparison" recipe (mean ± 95 % CI per controller and
scenario, box plots, trajectories) over fewer seeds, plus the solve time per
robot per step (median and p95) and the counted solver failures and fallbacks.
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import numpy as np

from dfcoa_opt import metrics
from dfcoa_opt.bench.recipes import Artefact, recipe
from dfcoa_opt.bench.recipes.comparison import report_artefacts
from dfcoa_opt.bench.results.logs import read_log
from dfcoa_opt.bench.results.store import ResultsStore
from dfcoa_opt.core.atomic import atomic_write


def solve_time_table(store: ResultsStore) -> list[str]:
    """Markdown rows: controller x scenario, solve time per robot per step and failures."""
    times: dict[tuple[str, str], list[np.ndarray]] = defaultdict(list)
    counts: dict[tuple[str, str], np.ndarray] = defaultdict(lambda: np.zeros(3, int))
    for row in store.rows():
        if row["status"] != "ok":
            continue
        log = read_log(store.root, row)
        key = (row["controller"], row["scenario"])
        used = (log.filter_time > 0.0) | (log.filter_status != 0)
        times[key].append(log.filter_time[used])
        c = metrics.filter_counts(log)
        counts[key] += [int(used.sum()), c["filter_solver_failures"],
                        c["filter_fallbacks"] - c["filter_solver_failures"]]
    lines = ["| controller | scenario | solve time median (ms) | p95 (ms) | robot-steps | "
             "solver failures | infeasible (policy applied) |", "|---|---|---|---|---|---|---|"]
    for (cid, scen), chunks in sorted(times.items()):
        t = np.concatenate(chunks)
        if t.size == 0:
            continue
        n, fails, infeasible = counts[(cid, scen)]
        lines.append(f"| {cid} | {scen} | {1e3 * np.median(t):.3f} | "
                     f"{1e3 * np.percentile(t, 95):.3f} | {n} | {fails} | {infeasible} |")
    return lines


@recipe("beyond", sweep="sweeps/beyond.toml",
        title="Beyond the papers: CBF-QP filter and distributed NMPC (3 seeds)", budget=60)
def render_beyond(store: ResultsStore, dest: Path) -> list[Artefact]:
    """The comparison report over this sweep, and the solve-time table."""
    arts = report_artefacts(store, dest, "no paper (beyond the papers: cbf, nmpc)")
    lines = ["# Solve time per robot per step, and counted failures", "",
             "Robot-steps with a solver (`filter_time` > 0 or a status): `nmpc`'s NLP, the "
             "`cbf` filter's programs (its time is the step's total over the robots, fast "
             "path included), the `orca` filter's exact LP (`goto_slot+orca`, `orca_nav`). "
             "Wall-clock times on the machine that ran `make figures`, over all seeds "
             "(per run: `dfcoa_opt.metrics.solver.solve_time_stats`). `dfcoa` has no solver.", "",
             *solve_time_table(store)]
    atomic_write(dest / "solve_times.md", "\n".join(lines) + "\n")
    return [*arts, Artefact("solve_times.md", "-", "median and p95 solve time per robot per "
                                                   "step, solver failures, fallbacks")]
