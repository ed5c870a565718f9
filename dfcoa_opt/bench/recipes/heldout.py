"""Figure recipe "heldout": every method on unseen generated worlds, with defaults and tuned.

The sweep (``scenarios/sweeps/heldout.toml``) runs every variant with its
defaults, and every ``<variant>@tuned`` of ``dfcoa tune`` (the variants files
of ``scenarios/sweeps/tuned/``), on test seeds of the generated families
(``scenarios/heldout/``); the renderer reads the rows (and one seed's logs
per family for the pictures) and writes ``paper_figures/heldout/``:

- ``heldout.md``: how well the difficulty index predicts failure (Spearman's
  rho), the ranking of the tuned variants over every test world with Wilson
  intervals and paired tests, success and outcomes by family and by
  difficulty, BARN's score, the CVaR(0.9) of the formation error and of the
  time to goal, the generalisation gap (training against test success) and
  defaults against tuned;
- ``success_vs_difficulty.png``: success against the difficulty index, one line
  per tuned method;
- ``traj_<family>_s<seed>.png``: every tuned variant on the first test world of
  each family;
- ``fail_<family>_s<seed>.png``: where the first-ranked tuned variant fails, a
  snapshot of each failing test world (first contact, deadlock onset or end);
- ``heldout.csv``, ``by_family.csv``, ``worlds.csv``: the numbers of the tables.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Callable, Hashable, Mapping, Sequence
from pathlib import Path
from typing import Any

from dfcoa_opt.bench.recipes import Artefact, recipe
from dfcoa_opt.bench.report import heldout as ho
from dfcoa_opt.bench.report import paired, stats
from dfcoa_opt.bench.report.document import aggregate, environment_header
from dfcoa_opt.bench.report.failures import run_outcome, snapshot_time
from dfcoa_opt.bench.report.plots import ladder_figure, variant_name
from dfcoa_opt.bench.report.tables import md_escape, ranking_table, rate_cell
from dfcoa_opt.bench.report.trajectories import panels_figure, snapshot_figure
from dfcoa_opt.bench.results.published import RUNS_FILE, published_rows
from dfcoa_opt.bench.results.store import ResultsStore
from dfcoa_opt.bench.runner import is_success
from dfcoa_opt.bench.sweep.specs import safe_name
from dfcoa_opt.core.atomic import atomic_write
from dfcoa_opt.metrics.outcome import OUTCOMES
from dfcoa_opt.metrics.world import WORLD_KEYS
from dfcoa_opt.viz.layout import save_png


def _pct(k: int, n: int) -> str:
    lo, hi = stats.wilson_interval(k, n)
    return rate_cell(k / n, (lo, hi), k, n) if n else "—"


def _num(x: float, digits: int = 2) -> str:
    return f"{x:.{digits}f}" if math.isfinite(x) else "—"


def _table_order(s: ho.VariantStats) -> tuple[int, str]:
    """The order of the variants' table: the most successes first (ties: the name)."""
    return -s.success, s.variant


def _variant_table(names: Sequence[str], rows: Sequence[Mapping[str, Any]]
                   ) -> tuple[list[str], list[ho.VariantStats]]:
    out = [ho.variant_stats(n, [r for r in rows if variant_name(r) == n]) for n in names]
    out = [s for s in out if s.runs]
    lines = ["| variant | worlds | success | collision | deadlock | timeout | failed | "
             "BARN score | CVaR(0.9) FCE RMS (m) | CVaR(0.9) time to goal of the successes (s) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for s in sorted(out, key=_table_order):
        cells = [_pct(s.outcomes.get(o, 0), s.runs) for o in OUTCOMES]
        lines.append(f"| {md_escape(s.variant)} | {s.runs} | " + " | ".join(cells)
                     + f" | {s.outcomes.get('failed', 0)} | {_num(s.barn)} | "
                     f"{_num(s.cvar_fce)} | {_num(s.cvar_time, 1)} |")
    return lines, out


def _group_tables(names: Sequence[str], rows: Sequence[Mapping[str, Any]],
                  group_of: Callable[[Mapping[str, Any]], Hashable],
                  groups: Mapping[Hashable, str]) -> list[str]:
    """Success, and the outcome classes, of each variant in each group of runs (columns).

    Args:
        names: The variants (rows of the tables).
        rows: Their runs.
        group_of: A run's group, None for none.
        groups: Group -> column label, in column order. A run counts in the column
            of its group only, however the labels read.
    """
    head = "| variant | " + " | ".join(md_escape(g) for g in groups.values()) + " |"
    rule = "|---|" + "---|" * len(groups)
    lines, outc = [head, rule], [head.replace("| variant |", "| variant (S/C/D/T %) |"), rule]
    for n in names:
        mine = [r for r in rows if variant_name(r) == n]
        cells, classes = [], []
        for g in groups:
            runs = [r for r in mine if group_of(r) == g]
            cells.append(_pct(sum(is_success(r) for r in runs), len(runs)))
            seen = [run_outcome(r) for r in runs]
            classes.append("/".join(f"{100 * seen.count(o) / len(runs):.0f}" for o in OUTCOMES)
                           if runs else "—")
        lines.append(f"| {md_escape(n)} | " + " | ".join(cells) + " |")
        outc.append(f"| {md_escape(n)} | " + " | ".join(classes) + " |")
    return ["Success:", "", *lines, "", "Outcome classes (success / collision / deadlock / "
            "timeout, % of runs):", "", *outc]


def _difficulty_series(names: Sequence[str], rows: Sequence[Mapping[str, Any]],
                       bins: Sequence[tuple[float, float]], bin_of: Mapping[Any, int]
                       ) -> dict[str, list[tuple[float, float, float, float, int]]]:
    """The figure's data: per method, ``(bin centre, success, Wilson low, high, runs)`` per bin.

    A run counts in the bin of its world's index (``bin_of``: world key -> bin index).
    """
    series: dict[str, list[tuple[float, float, float, float, int]]] = {}
    for n in names:
        for i, (a, b) in enumerate(bins):
            runs = [r for r in rows if variant_name(r) == n and bin_of.get(ho.world_key(r)) == i]
            if runs:
                wins = sum(is_success(r) for r in runs)
                lo, hi = stats.wilson_interval(wins, len(runs))
                series.setdefault(ho.method_of(n), []).append(
                    ((a + b) / 2, wins / len(runs), lo, hi, len(runs)))
    return series


def _difficulty(names: Sequence[str], rows: Sequence[Mapping[str, Any]],
                ws: Sequence[ho.World], dest: Path) -> tuple[list[str], Path]:
    """The tables by quartile of the difficulty index, and success against it (figure).

    Runs are grouped by the index of their world's bin (:func:`ho.bin_of`), so a
    world counts in one bin whatever the bins' labels.
    """
    bins = ho.difficulty_bins(ws)
    bin_of = {(w.scenario, w.seed): ho.bin_of(w.metrics["world_difficulty"], bins) for w in ws}
    path = ladder_figure(_difficulty_series(names, rows, bins, bin_of),
                         "difficulty index (bin centre)", dest / "success_vs_difficulty.png",
                         "Tuned methods on the test worlds: success against difficulty")
    table = _group_tables(names, rows, lambda r: bin_of.get(ho.world_key(r)),
                          dict(enumerate(ho.bin_labels(bins))))
    return table, path


def _gap_and_defaults(methods: Sequence[str], rows: Sequence[Mapping[str, Any]],
                      tuned: Mapping[str, Mapping[str, Any]]) -> tuple[list[str], list[str]]:
    """The generalisation gap of each tuned variant, and defaults against tuned."""
    gap = ["| method | training success (tuned) | test success (tuned) | gap (points) |",
           "|---|---|---|---|"]
    base = {m: {ho.world_key(r): r for r in rows if variant_name(r) == m} for m in methods}
    tune = {m: {ho.world_key(r): r for r in rows if variant_name(r) == m + ho.TUNED}
            for m in methods}
    cells, ps = [], []
    for m in methods:
        info = tuned.get(m + ho.TUNED, {})
        test = list(tune[m].values())
        if info and test:
            k, n = int(info["train_success"]), int(info["train_runs"])
            t = sum(is_success(r) for r in test)
            gap.append(f"| {md_escape(m)} | {_pct(k, n)} | {_pct(t, len(test))} | "
                       f"{100 * (k / n - t / len(test)):+.0f} |")
        shared = sorted(set(base[m]) & set(tune[m]))
        if not shared:
            continue
        a = [is_success(tune[m][w]) for w in shared]
        b = [is_success(base[m][w]) for w in shared]
        mc = stats.mcnemar_exact(a, b)
        cells.append((m, info, shared, sum(b), sum(a), mc))
        ps.append(mc.p_value)
    adjusted = stats.holm(ps)
    dvt = ["| method | training: defaults | training: tuned | validation: defaults | "
           "validation: tuned | test: defaults | test: tuned (same worlds) | tuned − defaults "
           "| McNemar p (Holm) |",
           "|---|---|---|---|---|---|---|---|---|"]
    for (m, info, shared, kb, ka, mc), p in zip(cells, adjusted, strict=True):
        n_tr = int(info.get("train_runs", 0))
        tr_d = _pct(int(info["default_train_success"]), n_tr) if info else "—"
        tr_t = _pct(int(info["train_success"]), n_tr) if info else "—"
        n_va = int(info.get("validation_runs", 0))
        va_d = _pct(int(info["default_validation_success"]), n_va) \
            if "default_validation_success" in info else "—"
        va_t = _pct(int(info["validation_success"]), n_va) if n_va else "—"
        verdict = stats.verdict(mc.difference, float(p), True)
        mark = f" **{verdict}**" if verdict != "no difference" else ""
        dvt.append(f"| {md_escape(m)} | {tr_d} | {tr_t} | {va_d} | {va_t} | "
                   f"{_pct(kb, len(shared))} | "
                   f"{_pct(ka, len(shared))} | {100 * mc.difference:+.0f} pts | "
                   f"{float(p):.3g}{mark} |")
    return gap, dvt


def _failures(best: ho.VariantStats, rows: Sequence[Mapping[str, Any]], logs: Path,
              dest: Path) -> tuple[list[str], list[Artefact]]:
    """Where the first-ranked tuned variant fails: each failing test world, by family.

    Each failing world gets a snapshot at its first contact, at the onset of
    its deadlock, or at its end (:func:`~dfcoa_opt.bench.report.failures.snapshot_time`).

    Args:
        best: The first row of the tuned variants' table (the most successes over
            every test world; ties: the name).
        rows: The tuned variants' runs.
        logs: The results folder of their logs.
        dest: Output folder of the snapshots.

    Returns:
        The section's lines, and its pictures.
    """
    mine = [r for r in rows if variant_name(r) == best.variant]
    lines = ["## Where the first-ranked variant fails", "",
             f"`{best.variant}` ({best.success} of {best.runs} test worlds): each world it "
             "did not succeed in, by family, with the map and the robots at the first contact, at "
             "the onset of the deadlock, or at the end of the run.", ""]
    arts: list[Artefact] = []
    for scen in sorted({str(r["scenario"]) for r in mine}):
        failed = sorted((r for r in mine if str(r["scenario"]) == scen and not is_success(r)),
                        key=lambda r: int(r["seed"]))
        ran = sum(str(r["scenario"]) == scen for r in mine)
        lines += [f"### {scen}: {len(failed)} of {ran} failed", ""]
        for r in failed:
            t = snapshot_time(r)
            when = f" at {t:.1f} s" if math.isfinite(t) else ""
            text = f"- seed {r['seed']}: {run_outcome(r)}{when}"
            if not r.get("log"):
                lines.append(f"{text} (no log)")
                continue
            name = f"fail_{safe_name(scen)}_s{r['seed']}.png"
            snapshot_figure(r, logs, dest / name, t)
            lines.append(f"{text}: [snapshot]({name})")
            arts.append(Artefact(name, "-", f"{best.variant} on {scen} seed {r['seed']}: "
                                            f"{run_outcome(r)}"))
        lines.append("")
    return lines, arts


def _variant_files(store: ResultsStore) -> list[Path]:
    """The sweep's variants files (``variant_files``, relative to the sweep file)."""
    from dfcoa_opt.scenario.overrides import read_toml

    sweep_file = Path(str(store.manifest().get("sweep_file", "")))
    patterns = read_toml(store.root / "sweep.toml").get("variant_files", [])
    return sorted({p for pat in patterns for p in sweep_file.parent.glob(pat)})


def _csv(rows: Sequence[Sequence[Any]]) -> str:
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerows(rows)
    return buf.getvalue()


#: The summary keys the held-out tables read (besides the outcome's): the published runs keep
#: them (``runs.csv``).
METRICS = ("fce_rms", "first_contact_time", "deadlock_time", *WORLD_KEYS)


@recipe("heldout", sweep="sweeps/heldout.toml",
        title="Held-out benchmark: generated worlds, test seeds, every method tuned alike",
        budget=900)
def render_heldout(store: ResultsStore, dest: Path) -> list[Artefact]:
    """The tables and figures of the module docstring, from the published runs (``runs.csv``)."""
    rows = published_rows(store.rows(), dest / RUNS_FILE, METRICS, "heldout")
    arts = heldout_report(rows, dest, str(store.manifest().get("baseline") or ""),
                          ho.read_tuned(_variant_files(store)),
                          environment_header(store.root).rstrip("\n"), store.root)
    return [*arts, Artefact(RUNS_FILE, "-", "every run: variant, world, outcome, the metrics "
                                            "these tables read, log digest (dfcoa compare)")]


def heldout_report(rows: Sequence[Mapping[str, Any]], dest: Path, baseline: str,
                   tuned_info: Mapping[str, Mapping[str, Any]], header: str,
                   logs: Path | None, ranked: Sequence[str] = ()) -> list[Artefact]:
    """Write ``heldout.md``, its CSVs and figures from the runs of the held-out sweep.

    Args:
        rows: Every run (published, and a compared controller's).
        dest: Output folder.
        baseline: The variant the ranking pairs the others with.
        tuned_info: The ``[tuned]`` tables of the variants files, by tuned variant.
        header: The report's provenance lines (machine, packages, dates).
        logs: The results folder of the rows' logs, for the trajectory panels and the
            failure snapshots; None draws none (published runs come without logs).
        ranked: Variants ranked beside the tuned ones (a compared controller, tuned
            or not).
    """
    names = list(dict.fromkeys(variant_name(r) for r in rows))
    tuned_names = [n for n in names if ho.is_tuned(n) or n in ranked]
    methods = [ho.method_of(n) for n in tuned_names if ho.method_of(n) in names]
    tuned_rows = [r for r in rows if variant_name(r) in tuned_names]
    ws = ho.worlds(rows, tuned_names)
    rho, p_rho, n_rho = ho.spearman(ws)
    per_scen = {}
    for r in tuned_rows:
        per_scen.setdefault(str(r["scenario"]), set()).add(int(r["seed"]))
    defaults_worlds = {ho.world_key(r) for r in rows if not ho.is_tuned(variant_name(r))}
    md = ["# Held-out benchmark: unseen generated worlds", "",
          header, "",
          "Every method runs on test seeds of the generated families (scenarios/heldout/, "
          "docs/heldout.md), which no tuning saw: with its defaults, and as `<method>@tuned`, "
          "the best of the same tuning budget on training seeds (`dfcoa tune`, "
          "scenarios/sweeps/tune.toml). No paper has these tables.", "",
          f"- Test worlds: {len(ws)} for the tuned variants ("
          + ", ".join(f"{s}: {len(v)}" for s, v in sorted(per_scen.items()))
          + f"); {len(defaults_worlds)} for the defaults (the first seeds of each family).",
          f"- Runs: {len(rows)}.",
          f"- Spearman's rho between the difficulty index and the failure rate averaged over "
          f"the {len(tuned_names)} tuned variants, over the {n_rho} test worlds: "
          f"**{_num(rho)}** (p = {p_rho:.2g}).", ""]
    table, tuned_stats = _variant_table(tuned_names, tuned_rows)
    md += ["## Tuned variants over every test world", "", *table, "",
           "BARN score: success × T_ref / clip(T, T_ref, 2 T_ref), T_ref the leader's time "
           "along its reference path; CVaR(0.9): the mean of the worst 10 % (FCE RMS: of "
           "every run, a run that raised counting as infinite; time to goal: of the runs "
           "that succeeded).", ""]
    pool = ho.pooled(tuned_rows)
    groups = aggregate(pool, ("time_to_goal",))
    comps = [c for c in paired.compare(pool, baseline, ()) if c.metric == "success"]
    if baseline in tuned_names:
        md += ["### Ranking", "", ranking_table(groups, comps, baseline,
                                                paired.success_pairs(pool)),
               f"Success against `{baseline}`: McNemar exact, Holm. Both it and the shared "
               "ranks pair the runs by test world (family and seed), over every test world.",
               ""]
    families = sorted({str(r["scenario"]) for r in tuned_rows})
    md += ["## By family", "", *_group_tables(tuned_names, tuned_rows,
                                              lambda r: str(r["scenario"]),
                                              {f: f for f in families}), ""]
    bins, figure = _difficulty(tuned_names, tuned_rows, ws, dest)
    md += ["## By difficulty", "", "The tuned variants in four bins of the difficulty index "
           "(quartiles of the test worlds; bins whose edges coincide merge).", "", *bins, "",
           f"![success against difficulty]({figure.name})", ""]
    gap, dvt = _gap_and_defaults(methods, rows, tuned_info)
    md += ["## Generalisation gap", "", "Training success of the best trial (the tuning "
           "seeds it was chosen on) against test success:", "", *gap, "",
           "## Defaults against tuned", "", "On the test worlds both ran (paired by world); "
           "training and validation columns from the variants files (the tuned parameters "
           "are the defaults' unless a finalist beat them significantly on the validation "
           "worlds, docs/heldout.md):", "", *dvt, ""]
    default_table, _ = _variant_table(methods, [r for r in rows if variant_name(r) in methods])
    md += ["### Defaults over their test worlds", "", *default_table, ""]
    arts = [Artefact("success_vs_difficulty.png", "-", "success against the difficulty "
                     "index, one line per tuned method (Wilson 95 %)")]
    for scen, seeds in sorted(per_scen.items()) if logs is not None else ():
        first = min(seeds)
        chosen = [r for r in tuned_rows if str(r["scenario"]) == scen and int(r["seed"]) == first]
        name = f"traj_{safe_name(scen)}_s{first}.png"
        save_png(panels_figure(chosen, logs), dest / name)
        md += [f"![{scen}]({name})", ""]
        arts.append(Artefact(name, "-", f"every tuned variant on the first test world of "
                                        f"{scen}"))
    if logs is not None and tuned_stats:
        best = min(tuned_stats, key=_table_order)  # the table's first row
        lines, pictures = _failures(best, tuned_rows, logs, dest)
        md += lines
        arts += pictures
    atomic_write(dest / "heldout.md", "\n".join(md).rstrip("\n") + "\n")
    atomic_write(dest / "worlds.csv", _csv(
        [["scenario", "seed", "failure_rate", *sorted(ws[0].metrics)] if ws else []]
        + [[w.scenario, w.seed, w.failure, *(w.metrics[k] for k in sorted(w.metrics))]
           for w in ws]))
    _, every = _variant_table(names, rows)
    atomic_write(dest / "heldout.csv", _csv(
        [["variant", "runs", "success", "ci_low", "ci_high", *OUTCOMES, "failed", "barn_score",
          "cvar_fce", "cvar_time_to_goal"]]
        + [[s.variant, s.runs, s.success, *s.interval, *(s.outcomes.get(o, 0) for o in OUTCOMES),
            s.outcomes.get("failed", 0), s.barn, s.cvar_fce, s.cvar_time] for s in every]))
    fam = aggregate(rows, ())
    atomic_write(dest / "by_family.csv", _csv(
        [["scenario", "variant", "runs", *[f"{o}_rate" for o in OUTCOMES]]]
        + [[g["scenario"], g["variant"], g["runs"], *(g[f"{o}_rate"] for o in OUTCOMES)]
           for g in fam]))
    return [Artefact("heldout.md", "no paper (held-out benchmark)", "Spearman's rho, ranking, "
                     "success and outcomes by family and difficulty, BARN score, CVaR, "
                     "generalisation gap, defaults against tuned"),
            Artefact("heldout.csv", "-", "every variant over its test worlds"),
            Artefact("by_family.csv", "-", "outcome rates by family and variant"),
            Artefact("worlds.csv", "-", "every test world: difficulty metrics and failure rate "
                                        "over the tuned variants"), *arts]
