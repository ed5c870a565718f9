"""Headless figures of a results folder: metric box plots and trajectory overlays.

Built on :mod:`dfcoa_opt.plotting` (bare ``Figure`` + Agg canvas, never pyplot;
its ``draw_world`` draws the map). Inputs are rows (dicts of the harness's row
schema, see :mod:`dfcoa_opt.bench.report`) and the saved logs; nothing is
simulated. The map of an overlay is rebuilt from the row's scenario file with the
row's seed and overrides, because maps may depend on both.
"""

from __future__ import annotations

import io
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from dfcoa_opt.atomic import atomic_write
from dfcoa_opt.bench.store import ResultsStore, file_sha256
from dfcoa_opt.bench.sweep import safe_name
from dfcoa_opt.errors import DfcoaError
from dfcoa_opt.plotting import draw_world, new_figure, robot_colors
from dfcoa_opt.sim.loader import load_scenario
from dfcoa_opt.sim.log import RunLog

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from dfcoa_opt.sim.scenario import Scenario

Row = Mapping[str, Any]

#: Summary key -> (label, unit) for table headers and axes; units as in docs/metrics.md.
METRIC_INFO: dict[str, tuple[str, str]] = {
    "fce_rms": ("FCE RMS", "m"), "fce_mean": ("FCE mean", "m"), "fce_max": ("FCE max", "m"),
    "fce_x_rms": ("FCE x RMS", "m"), "fce_y_rms": ("FCE y RMS", "m"), "fse_rms": ("FSE RMS", "m"),
    "fse_mean": ("FSE mean", "m"), "fste_max": ("FStE max", "m"), "fste_final": ("FStE final", "m"),
    "stability_pct": ("Stability", "%"), "vce_rms": ("VCE RMS", "m/s, rad/s mixed"),
    "v_rms": ("RMS v", "m/s"), "w_rms": ("RMS ω", "rad/s"), "risk_mean": ("Risk mean", ""),
    "risk_max": ("Risk max", ""), "min_inter_robot_distance": ("Min robot distance", "m"),
    "min_obstacle_clearance": ("Min obstacle clearance", "m"), "collisions": ("Collisions", ""),
    "robot_contact_steps": ("Robot contacts", "steps"),
    "obstacle_contact_steps": ("Obstacle contacts", "steps"),
    "dynamic_contact_steps": ("Moving-obstacle contacts", "steps"),
    "path_length_mean": ("Path length", "m"), "time_to_goal": ("Time to goal", "s"),
    "success": ("Success", ""), "filter_interventions": ("Filter interventions", ""),
    "filter_fallbacks": ("Filter fallbacks", ""), "filter_solver_failures": ("Solver failures", ""),
    "filter_time_median": ("Filter time median", "s"), "mse_mean": ("MSE mean", "m²"),
    "lf_error_mean": ("Slot error mean", "m"), "steps": ("Steps", ""),
}


def metric_header(metric: str) -> str:
    """Column title ``"label (unit)"`` of a summary key (the key itself when unknown)."""
    label, unit = METRIC_INFO.get(metric, (metric, ""))
    return f"{label} ({unit})" if unit else label


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
    return [(r, RunLog.load(store.root / r["log"])) for r in rows]


def save_png(fig: Figure, path: str | Path) -> Path:
    """Render ``fig`` to PNG and write it atomically to ``path``."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return atomic_write(path, buf.getvalue())


def _variant(row: Row) -> tuple[str, str]:
    """(controller, overrides hash) of a row."""
    return str(row["controller"]), str(row.get("overrides_hash", "base"))


def as_number(value: Any) -> float:
    """A metric value as float (bools as 0/1); NaN for null and non-numbers."""
    return float(value) if isinstance(value, (bool, int, float)) else math.nan


def metric_boxplots(rows: Sequence[Row], metric: str, path: str | Path,
                    label: str | None = None) -> Path:
    """Save box plots of one metric over seeds: one panel per scenario, one box per variant.

    A variant is a controller, suffixed with the overrides hash when a scenario has
    several. Only ok rows with a finite value count; every value is also drawn as
    a dot, and the tick label gives the number of values.

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
    fig = new_figure((max(4.5, 4.0 * n_panels), 4.0))
    axes = fig.subplots(1, n_panels, squeeze=False)[0]
    for ax, scen in zip(axes, scenarios, strict=False):
        variants = sorted({_variant(r) for r in rows if str(r["scenario"]) == scen})
        several = len({h for _, h in variants}) > 1
        data = []
        for var in variants:
            x = np.array([as_number((r.get("metrics") or {}).get(metric)) for r in ok
                          if str(r["scenario"]) == scen and _variant(r) == var])
            data.append(x[np.isfinite(x)])
        pos = np.arange(1, len(variants) + 1)
        filled = [i for i, x in enumerate(data) if x.size]
        if filled:
            ax.boxplot([data[i] for i in filled], positions=pos[filled], widths=0.5,
                       showfliers=False, medianprops={"color": "black"})
        for i, x in enumerate(data):  # every value, spread evenly (no randomness)
            spread = np.linspace(-0.12, 0.12, x.size) if x.size > 1 else np.zeros(x.size)
            ax.plot(pos[i] + spread, x, "o", color=robot_colors(1)[0], alpha=0.6,
                    markersize=4, zorder=3)
        ax.set_xticks(pos, [f"{c}\n{h}\n(n={x.size})" if several else f"{c}\n(n={x.size})"
                            for (c, h), x in zip(variants, data, strict=True)], fontsize="small")
        ax.set_xlim(0.4, len(variants) + 0.6)
        ax.set_title(scen)
        ax.grid(True, axis="y", alpha=0.3)
        if not filled:
            ax.text(0.5, 0.5, "no finite values", transform=ax.transAxes, ha="center")
    if not scenarios:
        axes[0].text(0.5, 0.5, "no runs", transform=axes[0].transAxes, ha="center")
    axes[0].set_ylabel(label or metric_header(metric))
    return save_png(fig, path)


def _load_log(results_dir: Path, row: Row) -> RunLog:
    """The row's saved log; a one-line :class:`DfcoaError` when it cannot be read."""
    path = results_dir / str(row["log"])
    try:
        return RunLog.load(path)
    except FileNotFoundError:
        raise DfcoaError(f"{path}: log file not found") from None
    except Exception as exc:  # noqa: BLE001 - numpy/zip/json errors of a damaged file
        problem = " ".join(str(exc).split()) or type(exc).__name__
        raise DfcoaError(f"{path}: cannot read the log ({problem})") from None


def trajectory_overlay(rows: Sequence[Row], results_dir: str | Path, path: str | Path) -> Path:
    """Save the trajectories of several controllers on one map (one scenario and seed).

    The map (with the leader's start and goal) is drawn once from the first row's
    scenario, loaded with its seed and overrides. Per controller, all robot
    trajectories (``pose[:, i, :2]``) share one colour and one legend entry, with a
    dot at each final position; the leader path (``leader[:, :2]``) is dashed black.
    Rows without a log (failed runs) are skipped.

    Args:
        rows: Rows of one scenario, seed and overrides variant, e.g. one per controller.
        results_dir: The results folder the rows' ``log`` paths are relative to.
        path: Output ``.png``; parent folders are created.

    Returns:
        The written path.

    Raises:
        ValueError: If the rows mix scenarios, seeds or overrides, or none has a log.
        DfcoaError: If the scenario file or a log cannot be read.
    """
    rows = sorted((r for r in rows if r.get("log")), key=lambda r: str(r["key"]))
    if not rows:
        raise ValueError("no row with a log to draw")
    ids = {(str(r["scenario"]), int(r["seed"]), str(r.get("overrides_hash", "base")))
           for r in rows}
    if len(ids) > 1:
        raise ValueError(f"rows mix scenarios, seeds or overrides: {sorted(ids)}")
    scen, seed, var = ids.pop()
    scenario = scenario_for_row(rows[0])
    spec = scenario.spec.leader
    fig = new_figure((8.0, 6.0))
    ax = fig.add_subplot()
    draw_world(ax, scenario.world.grid, spec.goal, spec.start, shapes=scenario.world.shapes)
    controllers = sorted({str(r["controller"]) for r in rows})
    colors = dict(zip(controllers, robot_colors(len(controllers)), strict=True))
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    lo, hi = np.array([x0, y0]), np.array([x1, y1])
    labelled: set[str] = set()
    for row in rows:
        log = _load_log(Path(results_dir), row)
        ctrl, color = str(row["controller"]), colors[str(row["controller"])]
        pose = np.asarray(log.pose, dtype=float)
        for i in range(pose.shape[1]):
            ax.plot(pose[:, i, 0], pose[:, i, 1], "-", color=color, linewidth=1.5, zorder=3,
                    label=ctrl if ctrl not in labelled and i == 0 else None)
        labelled.add(ctrl)
        if len(pose):
            ax.plot(pose[-1, :, 0], pose[-1, :, 1], "o", color=color, markersize=4, zorder=4)
        leader = np.asarray(log.leader, dtype=float)[:, :2]
        ax.plot(leader[:, 0], leader[:, 1], "--", color="black", linewidth=1.0, zorder=4)
        pts = np.concatenate([pose[..., :2].reshape(-1, 2), leader])
        pts = pts[np.isfinite(pts).all(axis=1)]
        if len(pts):  # widen the view to runs that left the map
            lo, hi = np.minimum(lo, pts.min(axis=0)), np.maximum(hi, pts.max(axis=0))
    ax.plot([], [], "--", color="black", linewidth=1.0, label="leader")  # last in legend
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    suffix = "" if var == "base" else f" - overrides {var}"
    ax.set_title(f"{scen} - seed {seed}{suffix}")
    fig.legend(loc="outside right upper", fontsize="small")
    return save_png(fig, path)


def _changed(row: Row) -> bool:
    """True if the row records ``scenario_sha256`` and the file's hash now differs."""
    want = row.get("scenario_sha256")
    if not want:
        return False
    try:
        return file_sha256(str(row["scenario_file"])) != want
    except OSError:
        return True


def overlay_figures(rows: Sequence[Row], results_dir: str | Path, out_dir: str | Path,
                    seed: int | None = None) -> tuple[dict[str, list[Path]], list[str]]:
    """Draw :func:`trajectory_overlay` for every scenario (and overrides variant).

    Files are ``traj_<scenario>_s<seed>.png``, or ``traj_<scenario>_<hash>_s<seed>.png``
    when a scenario has several overrides variants.

    Args:
        rows: Result rows of any scenarios.
        results_dir: The results folder.
        out_dir: Output folder.
        seed: Seed to draw; default each scenario's smallest seed with a log.

    Returns:
        ``({scenario: written paths}, notes)``: one note per figure that could not
        be drawn (no run with a log for that seed, unreadable scenario file or log)
        or whose scenario file no longer matches the row's ``scenario_sha256``.
    """
    written: dict[str, list[Path]] = {}
    notes: list[str] = []
    for scen in sorted({str(r["scenario"]) for r in rows}):
        mine = [r for r in rows if str(r["scenario"]) == scen and r.get("log")]
        seeds = sorted({int(r["seed"]) for r in mine})
        pick = seeds[0] if seed is None and seeds else seed
        chosen = [r for r in mine if pick is not None and int(r["seed"]) == int(pick)]
        if not chosen:
            notes.append(f"{scen}: no run with a log for seed {pick}, no trajectory figure")
            continue
        variants = sorted({str(r.get("overrides_hash", "base")) for r in mine})
        for var in variants:
            part = [r for r in chosen if str(r.get("overrides_hash", "base")) == var]
            if not part:
                continue
            tag = "" if len(variants) == 1 else f"_{safe_name(var)}"
            path = Path(out_dir) / f"traj_{safe_name(scen)}{tag}_s{pick}.png"
            try:
                done = trajectory_overlay(part, results_dir, path)
            except DfcoaError as exc:
                notes.append(f"{scen} ({var}): trajectory figure skipped: {exc}")
                continue
            written.setdefault(scen, []).append(done)
            if _changed(part[0]):
                notes.append(f"{scen} ({var}): {part[0]['scenario_file']} changed since the "
                             f"run; the map of {done.name} may differ from the one driven")
    return written, notes
