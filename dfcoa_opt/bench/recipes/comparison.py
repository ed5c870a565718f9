"""Figure recipe "comparison": every controller on the common scenarios, and its report."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from dfcoa_opt.bench.recipes import Artefact, recipe
from dfcoa_opt.bench.report.document import DEFAULT_METRICS, load_rows, make_report
from dfcoa_opt.bench.report.paired import PAIRED_METRICS
from dfcoa_opt.bench.report.shared_open import shared_open_table
from dfcoa_opt.bench.report.tables import success_matrix
from dfcoa_opt.bench.results.published import RUNS_FILE, published_rows
from dfcoa_opt.bench.results.store import ResultsStore
from dfcoa_opt.core.atomic import atomic_write
from dfcoa_opt.metrics.deploy import DEPLOY_KEYS

#: The two variants compared on shared open stretches (docs/methods/reshape.md).
SHARED_OPEN = ("reshape", "goto_slot+cbf")
#: The successes of every variant on every scenario (docs/bench_scenarios.md includes it).
MATRIX_FILE = "success_by_scenario.md"
MATRIX_LEGEND = ("Collision-free successes over the seeds of the comparison, per variant and "
                 "common scenario; bold: at least half. A scenario where every method fails, "
                 "or every one succeeds, tells them apart by nothing but their metrics.")
#: The summary keys the report reads (besides the outcome's): the published runs keep them.
METRICS = tuple(dict.fromkeys((*DEFAULT_METRICS, *DEPLOY_KEYS, *PAIRED_METRICS)))


@recipe("comparison", sweep="sweeps/comparison.toml",
        title="Cross-method comparison on the common scenarios (scenarios/bench/)", budget=1000)
def render_comparison(store: ResultsStore, dest: Path) -> list[Artefact]:
    """Mean ± 95 % CI tables, per-metric box plots and one-seed trajectory overlays.

    Also ``shared_open.md``: ``reshape`` against ``goto_slot+cbf`` over the instants
    open in both runs of a seed (their formation error where both can track).
    """
    rows = published_rows(load_rows(store.root), dest / RUNS_FILE, METRICS, "comparison")
    arts = report_artefacts(store, dest, "paper 000 Table 6 (qualitative there)", rows)
    arts.append(Artefact(RUNS_FILE, "-", "every run: variant, scenario, seed, outcome, the "
                                         "metrics the report reads, log digest (dfcoa compare)"))
    atomic_write(dest / MATRIX_FILE, "# Successes by scenario\n\n" + MATRIX_LEGEND + "\n\n"
                 + success_matrix(rows))
    arts.append(Artefact(MATRIX_FILE, "-", "successes of every variant on every common "
                                           "scenario (docs/bench_scenarios.md shows it)"))
    table = shared_open_table(store.root, *SHARED_OPEN)
    if table:
        atomic_write(dest / "shared_open.md", table)
        arts.append(Artefact("shared_open.md", "-", f"{SHARED_OPEN[0]} against "
                             f"{SHARED_OPEN[1]}: formation errors over the instants open "
                             "in both runs of a seed"))
    return arts


#: File-name prefix -> what the file shows (report artefacts other than tables).
_FIGURES = {
    "traj_": "trajectories of every variant, one panel each, one seed",
    "fail_": "snapshot of the first failing seed (first contact, deadlock onset or end)",
    "ladder_": "success rate (Wilson 95 % interval) against the ladder's value, per variant",
    "box_": "distribution over seeds",
}
_TABLES = {
    "report.md": "every variant x scenario: outcome rates (Wilson 95 %), metrics (mean ± 95 % "
                 "CI over seeds), ranking, paired differences, why it fails",
    "report.csv": "the outcome rates and metrics as CSV",
    "ladders.csv": "the ladders' outcome rates and metrics as CSV",
    "paired.csv": "every paired comparison with the baseline (seeds paired and excluded, "
                  "estimate, CI, p, Holm, verdict)",
}


def report_artefacts(store: ResultsStore, dest: Path, paper: str,
                     rows: Sequence[Mapping[str, Any]] | None = None) -> list[Artefact]:
    """The cross-method report of a sweep (:func:`make_report`) as artefacts.

    Args:
        store: The sweep's results.
        dest: Output folder.
        paper: What the main table corresponds to in the papers.
        rows: The runs to report (default: the store's).
    """
    arts = []
    for p in make_report(store.root, dest, rows=rows):
        rel = p.relative_to(dest).as_posix()
        if p.name in _TABLES:
            arts.append(Artefact(rel, paper if p.name == "report.md" else "-", _TABLES[p.name]))
            continue
        what = next((w for k, w in _FIGURES.items() if p.name.startswith(k)), "figure")
        arts.append(Artefact(rel, "-", f"{what}: {p.stem}" if what.startswith("distr") else what))
    return arts
