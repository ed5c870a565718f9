"""The report of a finished sweep, read from its results folder.

A results folder (written by the harness) holds ``manifest.json``, ``rows/<key>.json``
and ``logs/<key>.npz``. Only those files (and, for map backgrounds, the scenario files)
are read; nothing is simulated, so re-rendering gives a byte-identical ``report.md``.

Per scenario (and per rung of a ladder) and variant: the outcome of every run
(success, collision, deadlock, timeout; :mod:`dfcoa_opt.metrics.outcome`) as rates with
Wilson 95 % intervals, and the mean of each metric over seeds with the
half-width of its Student-t 95 % confidence interval (:mod:`dfcoa_opt.bench.report.tables`);
with a ``baseline``, paired comparisons and a ranking
(:mod:`dfcoa_opt.bench.report.paired`); for every variant below 50 % success, why it
fails (:mod:`dfcoa_opt.bench.report.failures`); trajectory panels and failure snapshots
(:mod:`dfcoa_opt.bench.report.trajectories`), box plots (:mod:`dfcoa_opt.bench.report.plots`) and
the ladders (:mod:`dfcoa_opt.bench.report.ladders`). Use: ``make_report("results/my_sweep")``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping, Sequence
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np
from scipy.stats import t as student_t

from dfcoa_opt.bench.report import failures, ladders, paired, plots, stats, tables, trajectories
from dfcoa_opt.bench.sweep.specs import safe_name
from dfcoa_opt.core.atomic import atomic_write
from dfcoa_opt.core.errors import DfcoaError
from dfcoa_opt.core.runtime import provenance
from dfcoa_opt.metrics.deploy import DEPLOY_KEYS
from dfcoa_opt.metrics.outcome import OUTCOMES

#: Metrics tabulated and box-plotted by default (keys of ``dfcoa_opt.metrics.summary``).
DEFAULT_METRICS: tuple[str, ...] = (
    "time_to_goal", "fce_rms", "fse_rms", "stability_pct", "vce_rms", "risk_raw_mean",
    "risk_raw_max", "min_inter_robot_distance", "min_obstacle_clearance", "path_length_mean",
)

#: Below each scenario's deployability table (docs/robots.md says how to read it).
DEPLOY_LEGEND = ("What the commands asked of the robot (docs/robots.md): the peak wheel speed "
                 "and the peak rim acceleration between two steps (each also as a ratio to "
                 "the robot's limit), the share of robot-steps the robot could not follow as "
                 "asked, the smallest gap between two bodies, and with the gritsbot profile "
                 "the share of runs that pass the Robotarium's checks.")

DEFAULT_BY: tuple[str, ...] = ("scenario", "variant")
#: Grouping of a ladder sweep: one group per rung too.
LADDER_BY: tuple[str, ...] = ("scenario", "ladder", "ladder_value", "variant")
_REQUIRED = ("key", "scenario", "controller", "seed", "status")


# --------------------------------------------------------------------------- loading
def _read_json(path: Path) -> dict[str, Any]:
    """Parse a JSON object file; every failure becomes a one-line :class:`DfcoaError`."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise DfcoaError(f"{path}: not valid JSON ({exc.msg} at line {exc.lineno} "
                         f"column {exc.colno})") from None
    except UnicodeDecodeError as exc:
        raise DfcoaError(f"{path}: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except OSError as exc:
        raise DfcoaError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if not isinstance(data, dict):
        raise DfcoaError(f"{path}: expected a JSON object, got {type(data).__name__}")
    return data


def load_rows(results_dir: str | Path, all_rows: bool = False) -> list[dict[str, Any]]:
    """Read the ``rows/*.json`` of a results folder.

    When ``manifest.json`` lists the sweep's run ``keys`` (the harness writes them),
    only those rows are read, so rows left by an earlier, different sweep in the same
    folder do not enter the report; runs not finished yet are simply absent.

    Args:
        results_dir: The results folder.
        all_rows: Read every row file, whatever the manifest lists.

    Returns:
        The rows, sorted by ``key``.

    Raises:
        DfcoaError: A missing folder, or a row file that cannot be read, is not JSON,
            is not an object, lacks a required field or has an unknown status
            (one-line message naming the file).
    """
    folder = Path(results_dir) / "rows"
    if not folder.is_dir():
        raise DfcoaError(f"{folder}: folder not found (not a results folder?)")
    files = sorted(folder.glob("*.json"))
    keys = _read_manifest(Path(results_dir)).get("keys")
    if isinstance(keys, list) and not all_rows:
        files = [p for p in files if p.stem in {str(k) for k in keys}]
    rows = []
    for path in files:
        row = _read_json(path)
        missing = [k for k in _REQUIRED if k not in row]
        if missing:
            raise DfcoaError(f"{path}: missing field(s) {', '.join(missing)}")
        if row["status"] not in ("ok", "failed"):
            raise DfcoaError(f"{path}: status must be 'ok' or 'failed', got {row['status']!r}")
        if not isinstance(row.get("metrics"), (dict, type(None))):
            raise DfcoaError(f"{path}: 'metrics' must be an object or null")
        rows.append(row)
    return sorted(rows, key=lambda r: str(r["key"]))


def _read_manifest(results_dir: Path) -> dict[str, Any]:
    """``manifest.json`` as a dict; ``{}`` when the file does not exist."""
    path = results_dir / "manifest.json"
    return _read_json(path) if path.exists() else {}


# ------------------------------------------------------------------------ statistics
def mean_ci95(values: Iterable[Any]) -> tuple[float, float, int]:
    """Mean and Student-t 95 % half-width of the finite values.

    Args:
        values: Numbers; None, NaN and inf are skipped.

    Returns:
        ``(mean, half_width, n)`` with ``half_width = t_{0.975, n-1} s / sqrt(n)``
        (``s``: sample standard deviation, ddof 1), in the unit of the values. The
        mean is NaN when n = 0, the half-width NaN when n < 2.
    """
    x = np.array([plots.as_number(v) for v in values], dtype=float)
    x = x[np.isfinite(x)]
    n = int(x.size)
    if n == 0:
        return math.nan, math.nan, 0
    half = student_t.ppf(0.975, n - 1) * np.std(x, ddof=1) / math.sqrt(n) if n > 1 else math.nan
    return float(np.mean(x)), float(half), n


def _sort_key(values: tuple[Any, ...]) -> tuple[tuple[int, Any], ...]:
    """Order tuples of mixed values: numbers first (numerically), then text, then None."""
    return tuple((2, "") if v is None else (0, v) if isinstance(v, (int, float))
                 else (1, str(v)) for v in values)


def _field(row: Mapping[str, Any], name: str) -> Any:
    """A grouping field of a row (``variant`` falls back to the controller id)."""
    if name == "variant":
        return plots.variant_name(row)
    return row.get(name, "base" if name == "overrides_hash" else None)


def aggregate(rows: Sequence[Mapping[str, Any]], metrics: Sequence[str] = DEFAULT_METRICS,
              by: Sequence[str] = DEFAULT_BY) -> list[dict[str, Any]]:
    """Group runs; outcome rates with Wilson intervals and per-metric statistics over seeds.

    Args:
        rows: Rows as returned by :func:`load_rows`.
        metrics: Summary keys to compute statistics for.
        by: Row fields that define a group (``variant`` falls back to the controller).

    Returns:
        One dict per group, sorted by the ``by`` values, with: each ``by`` field;
        ``by`` (the field names); ``runs``, ``failed`` and ``ok`` (counts);
        ``outcomes`` (outcome -> count); per outcome ``<outcome>_rate`` (fraction of
        all runs; a failed run is none of them) and ``<outcome>_ci`` (its Wilson 95 %
        interval); ``reached_rate`` (the goal condition, contacts or not);
        ``success_rate``/``successes`` and ``collision_rate``/``collided``;
        ``dominant_failure`` (the most frequent non-success outcome, or ``failed``);
        ``stats``: metric -> ``{"mean", "ci95", "n", "distinct", "value"}`` over the
        finite values of the ok runs (see :func:`mean_ci95`; ``distinct``: number of
        different values, ``value``: the value when there is one); ``overrides``
        (of the group's first run); ``errors`` (distinct errors of failed runs).
    """
    groups: dict[tuple[Any, ...], list[Mapping[str, Any]]] = {}
    for row in rows:
        values = tuple(_field(row, b) for b in by)
        values = tuple(json.dumps(v, sort_keys=True) if isinstance(v, (dict, list)) else v
                       for v in values)  # hashable
        groups.setdefault(values, []).append(row)
    out = []
    for values in sorted(groups, key=_sort_key):
        members = groups[values]
        ok = [r for r in members if r.get("status") == "ok"]
        mets = [r.get("metrics") or {} for r in ok]
        errors = list(dict.fromkeys(str(r["error"]) for r in members
                                    if r.get("status") == "failed" and r.get("error")))
        counts = {o: sum(failures.run_outcome(r) == o for r in members) for o in OUTCOMES}
        n = len(members)
        group: dict[str, Any] = dict(zip(by, values, strict=True))
        group.update(by=tuple(by), runs=n, failed=n - len(ok), ok=len(ok), outcomes=counts,
                     reached_rate=sum(m.get("reached") is True for m in mets) / n,
                     successes=counts["success"], collided=counts["collision"],
                     dominant_failure=failures.dominant_failure(members),
                     stats={}, overrides=dict(members[0].get("overrides") or {}), errors=errors)
        for o in OUTCOMES:
            group[f"{o}_rate"] = counts[o] / n
            group[f"{o}_ci"] = stats.wilson_interval(counts[o], n)
        for metric in metrics:
            x = [plots.as_number(m.get(metric)) for m in mets]
            finite = sorted({v for v in x if math.isfinite(v)})
            mean, half, k = mean_ci95(x)
            group["stats"][metric] = {"mean": mean, "ci95": half, "n": k,
                                      "distinct": len(finite),
                                      "value": finite[0] if len(finite) == 1 else None}
        out.append(group)
    return out


# ------------------------------------------------------------------------ environment
def _parse_time(text: Any) -> datetime | None:
    """An ISO-8601 time (``Z`` allowed; naive means UTC), or None when unparsable."""
    try:
        when = datetime.fromisoformat(str(text).replace("Z", "+00:00"))
    except ValueError:
        return None
    return when if when.tzinfo else when.replace(tzinfo=timezone.utc)


def newest_finished(rows: Iterable[Mapping[str, Any]]) -> str | None:
    """The latest ``provenance.finished`` of the rows, as written, or None."""
    stamps = [(when, str(text)) for r in rows
              if (text := (r.get("provenance") or {}).get("finished")) is not None
              and (when := _parse_time(text)) is not None]
    return max(stamps)[1] if stamps else None


def _provenance_values(rows: list[dict[str, Any]], key: str) -> list[str]:
    """The distinct non-empty values of ``provenance[key]`` over ``rows``, sorted."""
    return sorted({str(r["provenance"][key]) for r in rows
                   if (r.get("provenance") or {}).get(key)})


def environment_header(results_dir: str | Path) -> str:
    """Markdown lines describing the sweep and the software/hardware.

    The date is the newest ``provenance.finished`` of the rows, not the current
    time, so re-rendering cached results reproduces the same text. Package
    versions and the CPU are those of the machine rendering the report; the hosts
    that ran the rows are listed separately.

    Args:
        results_dir: The results folder.

    Returns:
        Markdown bullet lines, ending with a newline.
    """
    results_dir = Path(results_dir)
    manifest = _read_manifest(results_dir)
    rows = load_rows(results_dir)
    digest = str(manifest.get("sweep_sha256", "")) or "unknown"
    hosts, simd = _provenance_values(rows, "host"), _provenance_values(rows, "simd")
    caps = _provenance_values(rows, "simd_cap")
    keys = manifest.get("keys")
    planned = f" of {len(keys)} in the manifest" if isinstance(keys, list) else ""
    lines = [
        f"- Sweep: **{manifest.get('name', 'unknown')}** (`{manifest.get('sweep_file', '?')}`, "
        f"sha256 `{digest[:12]}`)",
        f"- Sweep file sha256: `{digest}`",
        f"- Date (newest finished run): {newest_finished(rows) or 'unknown'}",
        f"- Runs: {len(rows)}{planned} ({sum(r['status'] == 'failed' for r in rows)} failed); "
        f"hosts: {', '.join(hosts) or 'unknown'}"
        + (f" (numpy SIMD {', '.join(simd)}; cap {', '.join(caps) or 'unknown'})"
           if simd else ""),
        f"- CPU: {provenance.machine()}",
        f"- Packages: {provenance.versions()}",
    ]
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------- report
LEGEND = ("Outcome of every run (docs/metrics.md, outcomes): **success** = the goal reached with "
          "no contact of any kind; **collision** = at least one contact (robot-robot, "
          "robot-obstacle, robot-moving obstacle); **deadlock** = not reached, no contact, no "
          "progress over the final window; **timeout** = the rest. Rates are % of all runs with "
          "the Wilson 95 % interval and the counts; a run that raised (failed) is none of them. "
          "Metric cells: mean ± half-width of the Student-t 95 % confidence interval over the "
          "seeds whose run did not fail; `(n=k)`: only k of them had a value (time to goal exists "
          "only for runs that reached the goal); — : undefined. Risk is paper 000's eq 11 "
          "without normalisation (1/m²); it is undefined (inf) for a run with a contact, so its "
          "mean covers the runs without contact, and such runs sit in the collision column.")


def make_report(results_dir: str | Path, out_dir: str | Path | None = None,
                metrics: Sequence[str] = DEFAULT_METRICS,
                overlay_seed: int | None = None, baseline: str | None = None,
                rows: Sequence[Mapping[str, Any]] | None = None) -> list[Path]:
    """Write ``report.md``, ``report.csv`` and the figures of a results folder.

    Reads only rows, logs and scenario files (for map backgrounds); never simulates.

    Args:
        results_dir: The results folder.
        out_dir: Output folder; default ``results_dir/report``.
        metrics: Summary keys to tabulate, one box plot each (``box_<metric>.png``).
        overlay_seed: Seed of the trajectory panels (``traj_<scenario>_s<seed>.png``);
            default: each scenario's smallest seed with a log.
        baseline: Variant to compare the others to; default the sweep's ``baseline``
            (manifest), none when empty.
        rows: The runs to report; default the folder's rows. A row without a ``log``
            (a published run, :mod:`dfcoa_opt.bench.results.published`) enters the
            tables and no figure that reads logs.

    Returns:
        The written files: report.md, report.csv (ladders.csv, paired.csv when there
        are ladders or a baseline), box plots, trajectory panels, failure snapshots,
        ladder curves.

    Raises:
        DfcoaError: If the folder, a row or the manifest cannot be read.
    """
    results_dir = Path(results_dir)
    out_dir = results_dir / "report" if out_dir is None else Path(out_dir)
    rows = load_rows(results_dir) if rows is None else list(rows)
    out_dir.mkdir(parents=True, exist_ok=True)
    manifest = _read_manifest(results_dir)
    baseline = str(manifest.get("baseline") or "") if baseline is None else baseline
    plain = [r for r in rows if r.get("ladder_value") is None]
    laddered = [r for r in rows if r.get("ladder_value") is not None]
    groups = aggregate(plain, [*metrics, *DEPLOY_KEYS])
    comparisons = paired.compare(rows, baseline) if baseline else []
    md = [f"# Benchmark report: {manifest.get('name', results_dir.name)}", "",
          environment_header(results_dir).rstrip("\n"), "", LEGEND, ""]
    if baseline:
        md += [f"Baseline of the paired comparisons: `{baseline}`.", "",
               tables.ranking_legend(), ""]
    written: list[Path] = []
    trajs, notes = trajectories.overlay_figures(plain, results_dir, out_dir, overlay_seed)
    for scen in sorted({str(g["scenario"]) for g in groups}):
        mine = [g for g in groups if str(g["scenario"]) == scen]
        md += _scenario_section(scen, mine, [r for r in plain if str(r["scenario"]) == scen],
                                [c for c in comparisons if c.table == (scen, "", None)],
                                baseline, metrics, results_dir, out_dir, written)
        md += [f"![trajectories {scen}]({p.name})\n" for p in trajs.get(scen, [])]
    if notes:
        md += ["Notes:", *[f"- {n}" for n in notes], ""]
    lgroups = aggregate(laddered, [*metrics, *DEPLOY_KEYS], LADDER_BY) if laddered else []
    md += ladders.sections(lgroups, manifest, out_dir, written)
    boxes = [plots.metric_boxplots(plain, m, out_dir / f"box_{safe_name(m)}.png")
             for m in metrics] if plain else []
    if boxes:
        md += ["## Distributions over seeds", ""] + [
            f"![{m}]({p.name})\n" for m, p in zip(metrics, boxes, strict=True)]
    overrides = tables.overrides_note(groups + lgroups)
    if overrides:
        md += ["## What each variant sets", "", *overrides, ""]
    md_path, csv_path = out_dir / "report.md", out_dir / "report.csv"
    atomic_write(md_path, "\n".join(md).rstrip("\n") + "\n")
    atomic_write(csv_path, tables.csv_table(groups, [*metrics, *DEPLOY_KEYS]))
    extra = []
    if lgroups:
        extra.append(atomic_write(out_dir / "ladders.csv",
                                  tables.csv_table(lgroups, [*metrics, *DEPLOY_KEYS])))
    if comparisons:
        extra.append(atomic_write(out_dir / "paired.csv", tables.paired_csv(comparisons)))
    return [md_path, csv_path, *extra, *boxes, *[p for s in sorted(trajs) for p in trajs[s]],
            *written]


def _scenario_section(scen: str, groups: Sequence[Mapping[str, Any]],
                      rows: Sequence[Mapping[str, Any]], comparisons: Sequence[Any],
                      baseline: str, metrics: Sequence[str], results_dir: Path,
                      out_dir: Path, written: list[Path]) -> list[str]:
    """Markdown of one scenario: outcomes and metrics, ranking, paired table, failures."""
    md = [f"## Scenario `{scen}`", "", tables.markdown_table(groups, metrics, hide=("scenario",))]
    if baseline and comparisons:
        md += ["### Ranking", "", tables.ranking_table(groups, comparisons, baseline,
                                                       paired.success_pairs(rows), legend=False),
               f"### Paired differences against `{baseline}`", "",
               tables.paired_table(comparisons, paired.PAIRED_METRICS, baseline)]
    deploy = tables.deploy_table(groups, DEPLOY_KEYS, hide=("scenario",))
    if deploy:
        md += ["### Deployability", "", DEPLOY_LEGEND, "", deploy]
    lines, shots = failures.explain(groups, rows, results_dir, out_dir)
    written += shots
    if lines:
        md += ["### Why it fails", "", "Every variant below 50 % success: its most frequent "
               "failure and a snapshot of the first seed that failed so.", "", *lines, ""]
    return md
