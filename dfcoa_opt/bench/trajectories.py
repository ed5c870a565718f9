"""Map figures of saved runs: trajectory panels per scenario and seed, failure snapshots.

Built on :mod:`dfcoa_opt.plotting` (bare ``Figure`` + Agg, never pyplot). The
map is rebuilt from the row's scenario file with the row's seed and overrides
(maps may depend on both); runs are read from their saved logs, never
re-simulated.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.patches import Circle as CirclePatch

from dfcoa_opt.bench.logs import read_log
from dfcoa_opt.bench.plots import save_png, scenario_for_row, variant_name
from dfcoa_opt.bench.store import file_sha256
from dfcoa_opt.bench.sweep import safe_name
from dfcoa_opt.errors import DfcoaError
from dfcoa_opt.figure_layout import new_figure
from dfcoa_opt.plotting import draw_world, robot_colors
from dfcoa_opt.sim.log import RunLog

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

Row = Mapping[str, Any]
#: Panels per row of a trajectory figure.
COLUMNS = 4
#: Size of one panel, inches.
PANEL_IN = 3.4
#: Robot radius assumed for logs that do not record it (``RobotSpec`` default), m.
DEFAULT_RADIUS = 0.2


def outcome_text(row: Row) -> str:
    """``"collision at 12.3 s"``, ``"deadlock from 40.0 s"``, ``"success"``, ``"run failed"``."""
    if row.get("status") != "ok":
        return "run failed"
    m = row.get("metrics") or {}
    outcome = str(m.get("outcome", "?"))
    t = m.get("first_contact_time" if outcome == "collision" else "deadlock_time")
    if outcome in ("collision", "deadlock") and isinstance(t, (int, float)):
        return f"{outcome} {'at' if outcome == 'collision' else 'from'} {t:.1f} s"
    return outcome


def _view(logs: Sequence[RunLog], extent: tuple[float, float, float, float]
          ) -> tuple[float, float, float, float]:
    """The map's extent widened to every trajectory and leader track of ``logs``."""
    lo = np.array([extent[0], extent[2]])
    hi = np.array([extent[1], extent[3]])
    for log in logs:
        pts = np.concatenate([np.asarray(log.pose, float)[..., :2].reshape(-1, 2),
                              np.asarray(log.leader, float)[:, :2]])
        pts = pts[np.isfinite(pts).all(axis=1)]
        if len(pts):
            lo, hi = np.minimum(lo, pts.min(axis=0)), np.maximum(hi, pts.max(axis=0))
    return float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1])


def _draw_run(ax: Axes, log: RunLog, upto: int | None = None, alpha: float = 1.0) -> None:
    """Every robot's trajectory (own colour), its final dot, and the leader's track dashed."""
    pose = np.asarray(log.pose, dtype=float)[:upto]
    # one collection, not a line per robot (a 100-robot panel drew 100 Line2D)
    ax.add_collection(LineCollection(list(pose[:, :, :2].transpose(1, 0, 2)),
                                     colors=robot_colors(pose.shape[1]), linewidths=1.0,
                                     alpha=alpha, zorder=3), autolim=False)
    if len(pose) and upto is None:
        ax.plot(pose[-1, :, 0], pose[-1, :, 1], "o", color="black", markersize=2.5, zorder=4)
    lead = np.asarray(log.leader, dtype=float)[:upto, :2]
    ax.plot(lead[:, 0], lead[:, 1], "--", color="black", linewidth=0.8, zorder=4)


def panels_figure(rows: Sequence[Row], results_dir: str | Path) -> Figure:
    """One panel per variant for one scenario and seed: same map, same axes.

    Args:
        rows: Rows of one scenario and seed (one per variant; a row without a log
            gets a panel saying why).
        results_dir: The results folder the rows' ``log`` paths are relative to.

    Returns:
        The figure (panels titled ``"<variant> — <outcome>"``).

    Raises:
        ValueError: The rows mix scenarios or seeds, repeat a variant, or there is none.
        DfcoaError: The scenario file or a log cannot be read.
    """
    rows = sorted(rows, key=lambda r: variant_name(r))
    if not rows:
        raise ValueError("no row to draw")
    ids = {(str(r["scenario"]), int(r["seed"])) for r in rows}
    if len(ids) > 1:
        raise ValueError(f"rows mix scenarios or seeds: {sorted(ids)}")
    scen, seed = ids.pop()
    names = [variant_name(r) for r in rows]
    if len(set(names)) < len(names):
        raise ValueError(f"rows repeat a variant (e.g. ladder rungs): {sorted(names)}")
    sc = scenario_for_row(next((r for r in rows if r.get("log")), rows[0]))
    logs = {variant_name(r): read_log(results_dir, r) for r in rows if r.get("log")}
    view = _view(list(logs.values()), sc.world.grid.extent)
    cols = min(COLUMNS, len(rows))
    nrows = math.ceil(len(rows) / cols)
    fig = new_figure((PANEL_IN * cols, PANEL_IN * nrows * 0.9 + 0.4))
    axes = fig.subplots(nrows, cols, squeeze=False).ravel()
    for ax, row in zip(axes, rows, strict=False):
        name = variant_name(row)
        draw_world(ax, sc.world.grid, sc.spec.leader.goal, sc.spec.leader.start,
                   shapes=sc.world.shapes)
        if name in logs:
            _draw_run(ax, logs[name])
        else:
            err = " ".join(str(row.get("error") or "no log").split())
            ax.text(0.5, 0.5, f"run failed:\n{err[:60]}", transform=ax.transAxes,
                    ha="center", va="center", fontsize="small", wrap=True)
        ax.set_xlim(view[0], view[1])
        ax.set_ylim(view[2], view[3])
        ax.set_title(f"{name} — {outcome_text(row)}", fontsize="small")
        ax.set_xlabel("")
        ax.set_ylabel("")
    for ax in axes[len(rows):]:
        ax.set_axis_off()
    fig.suptitle(f"{scen} — seed {seed}")
    return fig


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
    """One trajectory figure per scenario (:func:`panels_figure`): ``traj_<scenario>_s<seed>.png``.

    Args:
        rows: Result rows of any scenarios (outside ladders).
        results_dir: The results folder.
        out_dir: Output folder.
        seed: Seed to draw; default each scenario's smallest seed with a log.

    Returns:
        ``({scenario: written paths}, notes)``: one note per figure that could not
        be drawn, or whose scenario file no longer matches the rows' hash.
    """
    written: dict[str, list[Path]] = {}
    notes: list[str] = []
    for scen in sorted({str(r["scenario"]) for r in rows}):
        mine = [r for r in rows if str(r["scenario"]) == scen]
        seeds = sorted({int(r["seed"]) for r in mine if r.get("log")})
        pick = seeds[0] if seed is None and seeds else seed
        chosen = [r for r in mine if pick is not None and int(r["seed"]) == int(pick)]
        if not any(r.get("log") for r in chosen):
            notes.append(f"{scen}: no run with a log for seed {pick}, no trajectory figure")
            continue
        path = Path(out_dir) / f"traj_{safe_name(scen)}_s{pick}.png"
        try:
            written[scen] = [save_png(panels_figure(chosen, results_dir), path)]
        except DfcoaError as exc:
            notes.append(f"{scen}: trajectory figure skipped: {exc}")
            continue
        if any(_changed(r) for r in chosen):
            notes.append(f"{scen}: its scenario file changed since the runs; the map of "
                         f"{path.name} may differ from the one driven")
    return written, notes


def nearest_step(log: RunLog, t: float) -> int:
    """Index of the logged instant nearest ``t`` (s); the last one for t = inf."""
    if not math.isfinite(t):
        return len(log.t) - 1
    return int(np.argmin(np.abs(np.asarray(log.t) - t)))


def contacts_at(log: RunLog, k: int) -> np.ndarray:
    """``(N,)`` which robots touch something at instant ``k``.

    A robot touches a static obstacle when its clearance is below its radius,
    another robot when their centres are closer than two radii, and a moving
    disc when it overlaps it -- the simulator's contact rules.
    """
    r = float(log.meta.get("robot_radius", DEFAULT_RADIUS))
    pos = np.asarray(log.pose[k, :, :2], dtype=float)
    hit = np.asarray(log.clearance[k]) < r
    if len(pos) > 1:
        d = np.linalg.norm(pos[:, None] - pos[None], axis=-1)
        np.fill_diagonal(d, np.inf)
        hit |= (d < 2.0 * r).any(axis=1)
    if len(log.dyn_radius):
        dd = np.linalg.norm(pos[:, None] - np.asarray(log.dyn_pos[k])[None], axis=-1)
        hit |= (dd < r + np.asarray(log.dyn_radius)[None]).any(axis=1)
    return hit


def snapshot_figure(row: Row, results_dir: str | Path, path: str | Path, t: float,
                    title: str | None = None) -> Path:
    """The map and the robots at the logged instant nearest ``t`` (s).

    Robots are discs of their true radius, red-edged when in contact
    (:func:`contacts_at`); moving obstacles grey discs; formation slots small
    crosses; the trajectories up to ``t`` faded; the leader a black triangle.

    Args:
        row: The run's row.
        results_dir: The results folder.
        path: Output ``.png``.
        t: Time to show, s (``inf``: the last instant).
        title: Figure title; default ``"<scenario> / <variant> / seed <s> at t = <t> s"``.

    Returns:
        The written path.

    Raises:
        DfcoaError: The scenario file or the log cannot be read.
    """
    log = read_log(results_dir, row)
    sc = scenario_for_row(row)
    k = nearest_step(log, t)
    fig = new_figure((7.0, 6.0))
    ax = fig.add_subplot()
    draw_world(ax, sc.world.grid, sc.spec.leader.goal, sc.spec.leader.start,
               shapes=sc.world.shapes)
    _draw_run(ax, log, upto=k + 1, alpha=0.35)
    r = float(log.meta.get("robot_radius", DEFAULT_RADIUS))
    hit = contacts_at(log, k)
    for i, (color, touching) in enumerate(zip(robot_colors(log.pose.shape[1]), hit,
                                              strict=True)):
        # add_artist, not add_patch: the limits are set below, and add_patch's update
        # of them from every disc's Bezier extrema took most of a 100-robot snapshot
        ax.add_artist(CirclePatch(log.pose[k, i, :2], r, facecolor=color, alpha=0.8, zorder=6,
                                  edgecolor="red" if touching else "black",
                                  linewidth=2.0 if touching else 0.5))
    for c, rad in zip(np.asarray(log.dyn_pos[k]), np.asarray(log.dyn_radius), strict=True):
        ax.add_artist(CirclePatch(c, rad, facecolor="grey", alpha=0.6, zorder=5))
    ax.plot(log.slots[k, :, 0], log.slots[k, :, 1], "x", color="black", markersize=4, zorder=7)
    ax.plot([log.leader[k, 0]], [log.leader[k, 1]], "^", color="black", markersize=7, zorder=7)
    view = _view([log], sc.world.grid.extent)
    ax.set_xlim(view[0], view[1])
    ax.set_ylim(view[2], view[3])
    ax.set_title(title or f"{row['scenario']} / {variant_name(row)} / seed {row['seed']} at "
                          f"t = {log.t[k]:.1f} s ({int(hit.sum())} robot(s) in contact)")
    return save_png(fig, path)
