"""Tables, statistics and figures of a finished sweep, read from its results folder.

A results folder (written by the harness) holds ``manifest.json``, ``rows/<key>.json``
and ``logs/<key>.npz``. Only those files (and, for map backgrounds, the scenario files)
are read; nothing is simulated, so re-rendering gives a byte-identical ``report.md``.
Statistics are over seeds: the mean of a metric per group of runs and the half-width of
its Student-t 95 % confidence interval. Use: ``make_report("results/my_sweep")``.
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Iterable, Mapping, Sequence
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats

from dfcoa_opt import environment
from dfcoa_opt.atomic import atomic_write
from dfcoa_opt.bench import plots
from dfcoa_opt.errors import DfcoaError

#: Metrics tabulated and box-plotted by default (keys of ``dfcoa_opt.metrics.summary``).
DEFAULT_METRICS: tuple[str, ...] = (
    "time_to_goal", "fce_rms", "fse_rms", "stability_pct", "vce_rms", "risk_mean",
    "min_inter_robot_distance", "min_obstacle_clearance", "path_length_mean",
)

DEFAULT_BY: tuple[str, ...] = ("scenario", "controller", "overrides_hash")
_REQUIRED = ("key", "scenario", "controller", "seed", "status")
_MAX_ERRORS = 5  # distinct error messages listed under a table
_ERROR_CHARS = 160  # an error message is cut to this length in report.md


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
    half = stats.t.ppf(0.975, n - 1) * np.std(x, ddof=1) / math.sqrt(n) if n > 1 else math.nan
    return float(np.mean(x)), float(half), n


def _sort_key(values: tuple[Any, ...]) -> tuple[tuple[int, Any], ...]:
    """Order tuples of mixed values: numbers first (numerically), then text, then None."""
    return tuple((2, "") if v is None else (0, v) if isinstance(v, (int, float))
                 else (1, str(v)) for v in values)


def aggregate(rows: Sequence[Mapping[str, Any]], metrics: Sequence[str] = DEFAULT_METRICS,
              by: Sequence[str] = DEFAULT_BY) -> list[dict[str, Any]]:
    """Group runs and compute rates and per-metric statistics over seeds.

    Args:
        rows: Rows as returned by :func:`load_rows`.
        metrics: Summary keys to compute statistics for.
        by: Row fields that define a group (a missing ``overrides_hash`` counts as
            ``"base"``).

    Returns:
        One dict per group, sorted by the ``by`` values, with: each ``by`` field;
        ``by`` (the field names); ``runs``, ``failed`` and ``ok`` (counts);
        ``success_rate`` (fraction of all runs that are ok and report success; a
        failed run counts as unsuccessful); ``collision_rate`` (fraction of ok runs
        with ``collisions > 0``, NaN without ok runs); ``successes`` and ``collided``
        (the counts behind both rates); ``stats``: metric ->
        ``{"mean", "ci95", "n"}`` over the finite values of the ok runs (see
        :func:`mean_ci95`); ``overrides`` (the overrides of the group's first run);
        ``errors`` (distinct error messages of failed runs, in key order).
    """
    groups: dict[tuple[Any, ...], list[Mapping[str, Any]]] = {}
    for row in rows:
        values = tuple(row.get(b, "base" if b == "overrides_hash" else None) for b in by)
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
        group: dict[str, Any] = dict(zip(by, values, strict=True))
        wins = sum(m.get("success") is True for m in mets)
        collided = sum(plots.as_number(m.get("collisions")) > 0 for m in mets)
        group.update(
            by=tuple(by), runs=len(members), failed=len(members) - len(ok), ok=len(ok),
            successes=wins, success_rate=wins / len(members), collided=collided,
            collision_rate=collided / len(ok) if ok else math.nan,
            stats={}, overrides=dict(members[0].get("overrides") or {}), errors=errors)
        for metric in metrics:
            mean, half, n = mean_ci95(m.get(metric) for m in mets)
            group["stats"][metric] = {"mean": mean, "ci95": half, "n": n}
        out.append(group)
    return out


# ---------------------------------------------------------------------------- tables
def _rate(rate: float, count: int, total: int) -> str:
    """``"67% (2/3)"``, or an em dash when the rate is undefined."""
    return f"{100.0 * rate:.0f}% ({count}/{total})" if math.isfinite(rate) else "—"


def _cell(stat: Mapping[str, Any], ok: int) -> str:
    """``"mean ± ci"`` with ``" (n=k)"`` when fewer than ``ok`` values were finite."""
    mean, half, n = float(stat["mean"]), float(stat["ci95"]), int(stat["n"])
    text = "—" if not math.isfinite(mean) else (
        f"{mean:.3f} ± {half:.3f}" if math.isfinite(half) else f"{mean:.3f}")
    return f"{text} (n={n})" if n < ok else text


def _id_columns(groups: Sequence[Mapping[str, Any]], hide: Iterable[str]) -> list[str]:
    """The ``by`` fields of the groups, without ``hide``."""
    by = groups[0].get("by", DEFAULT_BY) if groups else DEFAULT_BY
    return [b for b in by if b not in set(hide)]


def _md_escape(text: Any) -> str:
    """Text safe inside a Markdown table cell (one line, no bare pipes)."""
    return " ".join(str(text).split()).replace("|", "\\|")


def markdown_table(groups: Sequence[Mapping[str, Any]], metrics: Sequence[str] = DEFAULT_METRICS,
                   hide: Iterable[str] = ()) -> str:
    """Markdown table of :func:`aggregate` groups, with notes below it.

    Metric cells: ``mean ± 95 % CI half-width``, three decimals (``—`` if undefined,
    no ``±`` for one value), ``(n=k)`` when only k of the ok runs had a finite
    value. Rates are percentages of all runs (success) and of ok runs (collisions).
    Notes: the overrides behind each hash and up to five distinct run errors.

    Args:
        groups: Output of :func:`aggregate`.
        metrics: Summary keys, one column each (must have been aggregated).
        hide: Grouping fields not to show as columns (e.g. ``("scenario",)`` for a
            per-scenario table).

    Returns:
        The Markdown text, ending with a newline.
    """
    ids = _id_columns(groups, hide)
    names = {"overrides_hash": "overrides"}
    head = [names.get(b, b) for b in ids] + ["runs", "failed", "success", "collisions"]
    head += [plots.metric_header(m) for m in metrics]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for g in groups:
        ok = int(g["ok"])
        cells = [f"`{_md_escape(g[b])}`" if b == "overrides_hash" else _md_escape(g[b])
                 for b in ids]
        cells += [str(g["runs"]), str(g["failed"]),
                  _rate(g["success_rate"], g["successes"], g["runs"]),
                  _rate(g["collision_rate"], g["collided"], ok)]
        cells += [_cell(g["stats"][m], ok) for m in metrics]
        lines.append("| " + " | ".join(cells) + " |")
    notes = sorted({(g.get("overrides_hash"), json.dumps(g.get("overrides") or {},
                                                          sort_keys=True)) for g in groups
                    if g.get("overrides")}, key=lambda x: str(x))
    if notes:
        lines += ["", "Overrides:"] + [f"- `{h}`: `{o}`" for h, o in notes]
    failed = [(g, e) for g in groups for e in g.get("errors", [])]
    if failed:
        lines += ["", "Errors of failed runs:"]
        for g, err in failed[:_MAX_ERRORS]:
            who = " / ".join(_md_escape(g[b]) for b in ids)
            short = _md_escape(err)
            short = short if len(short) <= _ERROR_CHARS else short[:_ERROR_CHARS - 1] + "…"
            lines.append(f"- {who}: {short}")
        if len(failed) > _MAX_ERRORS:
            lines.append(f"- … and {len(failed) - _MAX_ERRORS} more distinct error(s)")
    return "\n".join(lines) + "\n"


def _csv_num(value: Any) -> str:
    """A number as CSV text: shortest round-trip float, empty for NaN/inf."""
    if not isinstance(value, float):
        return str(value)
    return repr(value) if math.isfinite(value) else ""


def csv_table(groups: Sequence[Mapping[str, Any]],
              metrics: Sequence[str] = DEFAULT_METRICS) -> str:
    """CSV of :func:`aggregate` groups, one numeric column per statistic.

    Columns: the ``by`` fields, ``overrides`` (JSON), ``runs``, ``failed``, ``ok``,
    ``success_rate`` and ``collision_rate`` (fractions in [0, 1]), then
    ``<metric>_mean``, ``<metric>_ci95`` and ``<metric>_n`` per metric (in the
    metric's unit; empty cells for NaN).

    Args:
        groups: Output of :func:`aggregate`.
        metrics: Summary keys (must have been aggregated).

    Returns:
        The CSV text (one line per group after the header, newline-terminated).
    """
    ids = _id_columns(groups, ())
    head = ids + ["overrides", "runs", "failed", "ok", "success_rate", "collision_rate"]
    head += [f"{m}_{s}" for m in metrics for s in ("mean", "ci95", "n")]
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(head)
    for g in groups:
        row = [g[b] for b in ids] + [json.dumps(g.get("overrides") or {}, sort_keys=True)]
        row += [g[k] for k in ("runs", "failed", "ok", "success_rate", "collision_rate")]
        row += [g["stats"][m][s] for m in metrics for s in ("mean", "ci95", "n")]
        writer.writerow([_csv_num(v) for v in row])
    return buf.getvalue()


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
    hosts = sorted({str((r.get("provenance") or {}).get("host")) for r in rows
                    if (r.get("provenance") or {}).get("host")})
    keys = manifest.get("keys")
    planned = f" of {len(keys)} in the manifest" if isinstance(keys, list) else ""
    lines = [
        f"- Sweep: **{manifest.get('name', 'unknown')}** (`{manifest.get('sweep_file', '?')}`, "
        f"sha256 `{digest[:12]}`)",
        f"- Sweep file sha256: `{digest}`",
        f"- Date (newest finished run): {newest_finished(rows) or 'unknown'}",
        f"- Runs: {len(rows)}{planned} ({sum(r['status'] == 'failed' for r in rows)} failed); "
        f"hosts: {', '.join(hosts) or 'unknown'}",
        f"- CPU: {environment.machine()}",
        f"- Packages: {environment.versions()}",
    ]
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------- report
def make_report(results_dir: str | Path, out_dir: str | Path | None = None,
                metrics: Sequence[str] = DEFAULT_METRICS,
                overlay_seed: int | None = None) -> list[Path]:
    """Write ``report.md``, ``report.csv`` and the figures of a results folder.

    Reads only rows, logs and scenario files (for map backgrounds); never simulates.

    Args:
        results_dir: The results folder.
        out_dir: Output folder; default ``results_dir/report``.
        metrics: Summary keys to tabulate, one box plot each (``box_<metric>.png``).
        overlay_seed: Seed of the trajectory overlays (``traj_<scenario>_s<seed>.png``,
            one per scenario and overrides variant); default: each scenario's
            smallest seed with a log.

    Returns:
        The written files: report.md, report.csv, box plots, overlays.

    Raises:
        DfcoaError: If the folder, a row or the manifest cannot be read.
    """
    results_dir = Path(results_dir)
    out_dir = results_dir / "report" if out_dir is None else Path(out_dir)
    rows = load_rows(results_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    groups = aggregate(rows, metrics)
    name = _read_manifest(results_dir).get("name", results_dir.name)
    boxes = [plots.metric_boxplots(rows, m, out_dir / f"box_{plots.safe_name(m)}.png")
             for m in metrics]
    trajs, notes = plots.overlay_figures(rows, results_dir, out_dir, overlay_seed)
    md = [f"# Benchmark report: {name}", "", environment_header(results_dir).rstrip("\n"), "",
          "Cells: mean ± half-width of the Student-t 95 % confidence interval over seeds, "
          "among the runs that did not fail; `(n=k)`: only k of them had a value (e.g. time "
          "to goal exists only for runs that reached the goal); — : undefined. Success: % "
          "of all runs; collisions: % of non-failed runs with at least one collision.", ""]
    for scen in sorted({str(g["scenario"]) for g in groups}):
        mine = [g for g in groups if str(g["scenario"]) == scen]
        md += [f"## Scenario `{scen}`", "", markdown_table(mine, metrics, hide=("scenario",))]
        md += [f"![trajectories {scen}]({p.name})\n" for p in trajs.get(scen, [])]
    if notes:
        md += ["Notes:", *[f"- {n}" for n in notes], ""]
    md += ["## Distributions over seeds", ""] + [f"![{m}]({p.name})\n"
                                                 for m, p in zip(metrics, boxes, strict=True)]
    md_path, csv_path = out_dir / "report.md", out_dir / "report.csv"
    atomic_write(md_path, "\n".join(md).rstrip("\n") + "\n")
    atomic_write(csv_path, csv_table(groups, metrics))
    return [md_path, csv_path, *boxes, *[p for s in sorted(trajs) for p in trajs[s]]]
