"""Figure recipe "comparison": every controller on the common scenarios, and its report."""

from __future__ import annotations

from pathlib import Path

from dfcoa_opt.bench.recipes import Artefact, recipe
from dfcoa_opt.bench.report import make_report
from dfcoa_opt.bench.store import ResultsStore


@recipe("comparison", sweep="sweeps/comparison.toml",
        title="Cross-method comparison on the common scenarios (scenarios/bench/)")
def render_comparison(store: ResultsStore, dest: Path) -> list[Artefact]:
    """Mean ± 95 % CI tables, per-metric box plots and one-seed trajectory overlays."""
    return report_artefacts(store, dest, "paper 000 Table 6 (qualitative there)")


def report_artefacts(store: ResultsStore, dest: Path, paper: str) -> list[Artefact]:
    """The cross-method report of a sweep (:func:`make_report`) as artefacts.

    Args:
        store: The sweep's results.
        dest: Output folder.
        paper: What the main table corresponds to in the papers.
    """
    paths = make_report(store.root, dest)
    arts = []
    for p in paths:
        rel = p.relative_to(dest).as_posix()
        if p.suffix == ".md":
            arts.append(Artefact(rel, paper, "every controller x scenario: mean ± 95 % CI over "
                                             "seeds, success and collision rates"))
        elif p.suffix == ".csv":
            arts.append(Artefact(rel, "-", "the same table as CSV"))
        elif p.name.startswith("traj_"):
            arts.append(Artefact(rel, "-", "trajectories of every controller, one seed"))
        else:
            arts.append(Artefact(rel, "-", f"distribution over seeds: {p.stem}"))
    return arts
