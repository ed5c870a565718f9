"""Headless figures of a results folder: metric box plots and ladder curves, and their helpers.

Built on :mod:`dfcoa_opt.viz.plotting` (bare ``Figure`` + Agg canvas, never pyplot).
Inputs are rows (dicts of the harness's row schema, see
:mod:`dfcoa_opt.bench.runner`); nothing is simulated. The map figures of single
runs (trajectory panels, failure snapshots) are in :mod:`dfcoa_opt.bench.report.trajectories`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from matplotlib.lines import Line2D

from dfcoa_opt.bench.results.logs import read_log
from dfcoa_opt.bench.results.store import ResultsStore
from dfcoa_opt.metrics.units import UNITS
from dfcoa_opt.scenario.loader import load_scenario
from dfcoa_opt.sim.log import RunLog
from dfcoa_opt.viz.layout import new_figure, save_png, wrap_text
from dfcoa_opt.viz.plotting import robot_colors

if TYPE_CHECKING:
    from dfcoa_opt.scenario.scenario import Scenario

Row = Mapping[str, Any]

#: Summary key -> its name in tables and axes; the unit comes from
#: :data:`dfcoa_opt.metrics.units.UNITS`.
METRIC_LABELS: dict[str, str] = {
    "fce_open_rms": "FCE RMS on open stretches", "fse_open_rms": "FSE RMS on open stretches",
    "open_pct": "open steps", "fce_rms": "FCE RMS", "fce_mean": "FCE mean", "fce_max": "FCE max",
    "fce_x_rms": "FCE x RMS", "fce_y_rms": "FCE y RMS", "fse_rms": "FSE RMS",
    "fse_mean": "FSE mean", "fste_max": "FStE max", "fste_final": "FStE final",
    "stability_pct": "Stability", "vce_rms": "VCE RMS", "v_rms": "RMS v", "w_rms": "RMS ω",
    "risk_mean": "Risk mean", "risk_max": "Risk max", "risk_raw_mean": "Risk mean, eq 11",
    "risk_raw_max": "Risk max, eq 11", "risk_clip_pct": "Risk at clip",
    "first_contact_time": "First contact", "deadlock_time": "Deadlock onset",
    "min_inter_robot_distance": "Min robot distance",
    "min_obstacle_clearance": "Min obstacle clearance", "collisions": "Collisions",
    "robot_contact_steps": "Robot contacts", "obstacle_contact_steps": "Obstacle contacts",
    "dynamic_contact_steps": "Moving-obstacle contacts", "path_length_mean": "Path length",
    "time_to_goal": "Time to goal", "success": "Success",
    "filter_interventions": "Filter interventions", "filter_fallbacks": "Filter fallbacks",
    "filter_solver_failures": "Solver failures", "filter_time_median": "Filter time median",
    "mse_mean": "MSE mean", "lf_error_mean": "Slot error mean", "steps": "Steps",
}


def metric_header(metric: str) -> str:
    """Column title ``"label (unit)"`` of a summary key (the key itself when unknown)."""
    label = METRIC_LABELS.get(metric, metric)
    unit = UNITS.get(metric, "").replace("^2", "²")
    return f"{label} ({unit})" if unit not in ("", "1") else label


def scenario_for_row(row: Row) -> Scenario:
    """Rebuild the scenario a row ran: its file, with the row's seed and overrides.

    Args:
        row: A result row (``scenario_file``, ``seed``, ``overrides``).

    Raises:
        DfcoaError: If the file is missing or invalid (one-line message).
    """
    return load_scenario(str(row.get("scenario_file", "")), int(row["seed"]),
                         row.get("overrides") or {})


def ok_runs(store: ResultsStore) -> list[tuple[Row, RunLog]]:
    """The successful rows of a store with their logs, by controller, overrides, seed."""
    rows = sorted((r for r in store.rows() if r["status"] == "ok"),
                  key=lambda r: (r["controller"], r.get("overrides_hash", ""), r["seed"]))
    return [(r, read_log(store.root, r)) for r in rows]


def variant_name(row: Row) -> str:
    """A row's variant name (its controller id for rows written before variants had names)."""
    return str(row.get("variant") or row["controller"])


def as_number(value: Any) -> float:
    """A metric value as float (bools as 0/1); NaN for null and non-numbers."""
    return float(value) if isinstance(value, (bool, int, float)) else math.nan


def metric_boxplots(rows: Sequence[Row], metric: str, path: str | Path,
                    label: str | None = None) -> Path:
    """Save box plots of one metric over seeds: one panel per scenario, one box per variant.

    Only ok rows with a finite value count; every value is also drawn as a dot,
    and the tick label gives the variant's name and the number of values.

    Args:
        rows: Result rows (any scenarios).
        metric: Summary key, e.g. ``"fce_rms"``.
        path: Output ``.png``; parent folders are created.
        label: Y-axis label with unit; default :func:`metric_header`.

    Returns:
        The written path.
    """
    ok = [r for r in rows if r.get("status") == "ok"]
    scenarios = sorted({str(r["scenario"]) for r in rows})
    n_panels = max(1, len(scenarios))
    fig = new_figure((max(4.5, 4.0 * n_panels), 4.5))
    axes = fig.subplots(1, n_panels, squeeze=False)[0]
    for ax, scen in zip(axes, scenarios, strict=False):
        variants = sorted({variant_name(r) for r in rows if str(r["scenario"]) == scen})
        data = []
        for var in variants:
            x = np.array([as_number((r.get("metrics") or {}).get(metric)) for r in ok
                          if str(r["scenario"]) == scen and variant_name(r) == var])
            data.append(x[np.isfinite(x)])
        pos = np.arange(1, len(variants) + 1)
        filled = [i for i, x in enumerate(data) if x.size]
        if filled:
            ax.boxplot([data[i] for i in filled], positions=pos[filled], widths=0.5,
                       showfliers=False, medianprops={"color": "black"})
        # every value, spread evenly (no randomness); one line of dots per panel
        spread = [pos[i] + (np.linspace(-0.12, 0.12, x.size) if x.size > 1 else 0.0 * x)
                  for i, x in enumerate(data)]
        ax.plot(np.concatenate(spread), np.concatenate(data), "o", color=robot_colors(1)[0],
                alpha=0.6, markersize=4, zorder=3)
        ax.set_xticks(pos, [f"{v}\n(n={x.size})" for v, x in zip(variants, data, strict=True)],
                      fontsize="small", rotation=60, ha="right")
        ax.set_xlim(0.4, len(variants) + 0.6)
        ax.set_title(scen)
        ax.grid(True, axis="y", alpha=0.3)
        if not filled:
            ax.text(0.5, 0.5, "no finite values", transform=ax.transAxes, ha="center")
    if not scenarios:
        axes[0].text(0.5, 0.5, "no runs", transform=axes[0].transAxes, ha="center")
    axes[0].set_ylabel(label or metric_header(metric))
    return save_png(fig, path)


#: Line styles and markers of the ladder curves (cycled), so overlapping lines stay readable.
_STYLES = ("-", "--", "-.", ":")
_MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*")


#: Width of the ladder figures' note of always-0 % variants, inches (the legend's column).
_NOTE_IN = 2.4


def ladder_figure(series: Mapping[str, Sequence[tuple[float, float, float, float, int]]],
                  xlabel: str, path: str | Path, title: str, log_x: bool = False) -> Path:
    """Success rate against a ladder's value, one line per variant, with Wilson intervals.

    Only the variants that succeed on some rung are drawn; those at 0 % on every
    rung are named in a note at the end of the legend ("0 % on every rung: a, b,
    c"); the ladder's table keeps every variant with its intervals. The drawn
    lines are shifted sideways by 1 % of the axis each, so variants with the
    same rate at a rung do not hide each other.

    Args:
        series: Variant -> points ``(value, rate, low, high, n)``: the rung's value,
            the success rate and its interval bounds (fractions), the runs.
        xlabel: The ladder's label.
        path: Output ``.png``.
        title: Figure title.
        log_x: Log scale for the value axis (e.g. team sizes 4 -> 100).

    Returns:
        The written path.
    """
    fig = new_figure((8.0, 4.8))
    ax = fig.add_subplot()
    names = list(series)
    colors = robot_colors(max(1, len(names)))  # by place among all variants: stable colours
    values = [p[0] for pts in series.values() for p in pts]
    span = (max(values) - min(values)) if values else 0.0
    # Variants at 0 % on every rung are named, not drawn. They have no curve to read (no
    # break point, the same flat line), and a dozen of them stacked their identical error
    # bars on 0 % into one block that hid the few curves that differ (crossing, message
    # latency: 11 of 13). Small multiples would keep them apart but spend a panel on each
    # flat line and shrink the informative curves to a thirteenth of the figure; a note
    # says the same in one line, and the report's table keeps every variant's numbers.
    drawn = [name for name in names if any(p[1] > 0 for p in series[name])]
    never = [name for name in names if name not in drawn]
    for place, name in enumerate(drawn):
        i = names.index(name)
        pts = sorted(series[name])
        x = np.array([p[0] for p in pts], dtype=float)
        # dodge the lines sideways (1 % of the axis per line) so equal rates stay apart
        dodge = 0.01 * (place - (len(drawn) - 1) / 2)
        x = x * (1.0 + dodge) if log_x else x + dodge * span
        y = 100.0 * np.array([p[1] for p in pts])
        lo = 100.0 * np.array([p[2] for p in pts])
        hi = 100.0 * np.array([p[3] for p in pts])
        runs = sorted({p[4] for p in pts})
        n = f"n={runs[0]}" if len(runs) == 1 else f"n={runs[0]}-{runs[-1]}"
        ax.errorbar(x, y, yerr=[np.maximum(y - lo, 0.0), np.maximum(hi - y, 0.0)],
                    color=colors[i], capsize=3,
                    linestyle=_STYLES[i % len(_STYLES)], marker=_MARKERS[i % len(_MARKERS)],
                    label=f"{name} ({n})")
    if log_x:
        ax.set_xscale("log")
    if values and not drawn:  # nothing drawn: the rungs' range all the same
        lo_x, hi_x = min(values), max(values)
        pad = 0.05 * (hi_x - lo_x) or 0.5
        ax.set_xlim(*((lo_x / 1.2, hi_x * 1.2) if log_x and lo_x > 0 else
                      (lo_x - pad, hi_x + pad)))
        ax.text(0.5, 0.5, "no variant succeeds on any rung", transform=ax.transAxes,
                ha="center", va="center", color="0.4")
    ax.set_ylim(-3, 103)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("success rate (%)")
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    handles, labels = ax.get_legend_handles_labels()
    if never:  # a handle-less entry: the note, in the legend's column, off the data
        handles.append(Line2D([], [], linestyle="none"))
        labels.append(wrap_text(f"0 % on every rung (see the table): {', '.join(never)}",
                                _NOTE_IN, 8.33))
    fig.legend(handles, labels, loc="outside right upper", fontsize="small")
    return save_png(fig, path)
