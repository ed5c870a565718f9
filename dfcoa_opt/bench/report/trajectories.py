"""Map figures of saved runs: trajectory panels per scenario and seed, failure snapshots.

Built on :mod:`dfcoa_opt.viz.plotting` (bare ``Figure`` + Agg, never pyplot). The
map is rebuilt from the row's scenario file with the row's seed and overrides
(maps may depend on both); runs are read from their saved logs, never
re-simulated. Contacts are marked as in the single-run figures
(:func:`dfcoa_opt.viz.plotting.draw_contacts`), outcomes worded by
:func:`dfcoa_opt.metrics.outcome.outcome_text`. Axes are in metres.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.lines import Line2D
from matplotlib.patches import Circle as CirclePatch
from matplotlib.patches import Patch

from dfcoa_opt.bench.report.plots import scenario_for_row, variant_name
from dfcoa_opt.bench.results.logs import LogCompacted, read_log
from dfcoa_opt.bench.results.store import file_sha256
from dfcoa_opt.bench.sweep.specs import safe_name
from dfcoa_opt.core.errors import DfcoaError
from dfcoa_opt.metrics import outcome
from dfcoa_opt.metrics.contacts import contacts_at, describe, first_contact_step, robot_radius
from dfcoa_opt.sim.log import RunLog
from dfcoa_opt.viz.layout import legend_and_fit, map_figure, new_figure, save_png, wrap_text
from dfcoa_opt.viz.plotting import (
    CONTACT_COLOR,
    LEADER_STYLE,
    OCCUPIED_COLOR,
    TITLE_PT,
    Z_LEADER,
    Z_ROBOT,
    _robot_label,
    draw_contacts,
    draw_world,
    robot_colors,
)

if TYPE_CHECKING:
    from matplotlib.artist import Artist
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from dfcoa_opt.world.grid import OccupancyGrid

Row = Mapping[str, Any]
#: Panels per row of a trajectory figure.
COLUMNS = 4
#: Size of one panel, inches.
PANEL_IN = 3.4
#: Font size of the panels' titles ("small"), pt.
PANEL_TITLE_PT = 8.33
#: The leader's path in a panel: the single-run style, narrower for the thinner robot lines.
PANEL_LEADER: dict[str, Any] = {**LEADER_STYLE, "linewidth": 2.0}


def outcome_text(row: Row) -> str:
    """``"collision at t = 12.30 s"``, ``"deadlock from t = 40.00 s"``, ``"success"``, ...

    :func:`dfcoa_opt.metrics.outcome.outcome_text` of the row's metrics; ``"run failed"``
    for a run that raised, ``"?"`` for an old row without an outcome.
    """
    if row.get("status") != "ok":
        return "run failed"
    m = row.get("metrics") or {}
    return outcome.outcome_text(str(m.get("outcome", "?")), m.get("first_contact_time"),
                                m.get("deadlock_time"))


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
    """Every robot's trajectory (own colour), its final dot, and the leader's path below them."""
    pose = np.asarray(log.pose, dtype=float)[:upto]
    # one collection, not a line per robot (a 100-robot panel drew 100 Line2D)
    ax.add_collection(LineCollection(list(pose[:, :, :2].transpose(1, 0, 2)),
                                     colors=robot_colors(pose.shape[1]), linewidths=1.0,
                                     alpha=alpha, zorder=Z_ROBOT, label="trajectories"),
                      autolim=False)
    if len(pose) and upto is None:
        ax.plot(pose[-1, :, 0], pose[-1, :, 1], "o", color="black", markersize=2.5, zorder=4)
    lead = np.asarray(log.leader, dtype=float)[:upto, :2]
    ax.plot(lead[:, 0], lead[:, 1], zorder=Z_LEADER, label="leader path",
            **{**PANEL_LEADER, "alpha": PANEL_LEADER["alpha"] * alpha})


def _mark_first_contact(ax: Axes, row: Row, log: RunLog, grid: OccupancyGrid) -> bool:
    """Mark a collision's first contact (:func:`~dfcoa_opt.viz.plotting.draw_contacts`).

    Only a row whose outcome is ``collision`` reads the log's contact fields.

    Returns:
        Whether anything was drawn.
    """
    if (row.get("metrics") or {}).get("outcome") != "collision":
        return False
    k = first_contact_step(log)
    return k is not None and bool(draw_contacts(ax, log, k, contacts_at(log, k, grid),
                                                robot_radius(log)))


def _panel_legend(fig: Figure, n_robots: int, contact: bool) -> None:
    """The panels' legend, under them: robots, leader, start, goal, obstacles, contacts."""
    color = robot_colors(max(n_robots, 1))
    handles: list[Artist] = [
        Line2D([], [], color=color[0], linewidth=1.0, label="robots (a colour each)"),
        Line2D([], [], marker="o", color="black", markersize=2.5, linestyle="none",
               label="final position"),
        Line2D([], [], label="leader path", **PANEL_LEADER),
        Line2D([], [], marker="s", color="black", markerfacecolor="none", markersize=9,
               linestyle="none", label="start"),
        Line2D([], [], marker="*", color="gold", markeredgecolor="black", markersize=15,
               linestyle="none", label="goal"),
        Patch(facecolor=OCCUPIED_COLOR, edgecolor="black", label="obstacle")]
    if contact:
        handles += [Patch(fill=False, edgecolor=CONTACT_COLOR, linewidth=2.0, label="in contact"),
                    Line2D([], [], marker="X", color=CONTACT_COLOR, markeredgecolor="black",
                           markersize=11, linestyle="none", label="first contact")]
    fig.legend(handles=handles, loc="outside lower center", ncols=min(len(handles), 4),
               fontsize="small")


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
    fig = new_figure((PANEL_IN * cols, PANEL_IN * nrows * 0.9 + 1.0))
    axes = fig.subplots(nrows, cols, squeeze=False).ravel()
    contact = False
    for ax, row in zip(axes, rows, strict=False):
        name = variant_name(row)
        draw_world(ax, sc.world.grid, sc.spec.leader.goal, sc.spec.leader.start,
                   shapes=sc.world.shapes)  # and the axis labels, x (m) and y (m)
        if name in logs:
            _draw_run(ax, logs[name])
            contact |= _mark_first_contact(ax, row, logs[name], sc.world.grid)
        else:
            err = " ".join(str(row.get("error") or "no log").split())
            ax.text(0.5, 0.5, f"run failed:\n{err[:60]}", transform=ax.transAxes,
                    ha="center", va="center", fontsize="small", wrap=True)
        ax.set_xlim(view[0], view[1])
        ax.set_ylim(view[2], view[3])
        ax.set_title(wrap_text(f"{name} — {outcome_text(row)}", PANEL_IN - 0.2,
                               PANEL_TITLE_PT), fontsize=PANEL_TITLE_PT)
    for ax in axes[len(rows):]:
        ax.set_axis_off()
    fig.suptitle(f"{scen} — seed {seed}")
    n_robots = max((np.asarray(log.pose).shape[1] for log in logs.values()), default=1)
    _panel_legend(fig, n_robots, contact)
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


def overlay_rows(rows: Sequence[Row], seed: int | None = None
                 ) -> dict[str, tuple[int | None, list[Row]]]:
    """The runs :func:`overlay_figures` draws: ``{scenario: (seed, its rows)}``.

    Args:
        rows: Result rows of any scenarios (outside ladders).
        seed: Seed to draw; default each scenario's smallest seed with a log.
    """
    out: dict[str, tuple[int | None, list[Row]]] = {}
    for scen in sorted({str(r["scenario"]) for r in rows}):
        mine = [r for r in rows if str(r["scenario"]) == scen]
        seeds = sorted({int(r["seed"]) for r in mine if r.get("log")})
        pick = seeds[0] if seed is None and seeds else seed
        out[scen] = (pick, [r for r in mine if pick is not None and int(r["seed"]) == int(pick)])
    return out


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
    for scen, (pick, chosen) in overlay_rows(rows, seed).items():
        if not any(r.get("log") for r in chosen):
            notes.append(f"{scen}: no run with a log for seed {pick}, no trajectory figure")
            continue
        path = Path(out_dir) / f"traj_{safe_name(scen)}_s{pick}.png"
        try:
            written[scen] = [save_png(panels_figure(chosen, results_dir), path)]
        except LogCompacted:
            raise  # ``make figures`` runs the run again and renders anew
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


def snapshot_figure(row: Row, results_dir: str | Path, path: str | Path, t: float,
                    title: str | None = None) -> Path:
    """The map and the robots at the logged instant nearest ``t`` (s).

    Robots are discs of their true radius (legend "robot i", or a colour bar of
    indices for large teams); the contacts of that instant are marked
    (:func:`~dfcoa_opt.viz.plotting.draw_contacts`: a red ``X`` where they touch, red
    rings around the robots and moving discs involved); moving obstacles are grey
    discs, formation slots small black crosses (×), the leader a black triangle
    (▲) on its dashed path, and the trajectories up to ``t`` faded. The legend
    names every marker; the figure is sized to the map and the title wrapped to
    its width.

    Args:
        row: The run's row.
        results_dir: The results folder.
        path: Output ``.png``.
        t: Time to show, s (``inf``: the last instant).
        title: Figure title; default three lines: ``"<scenario> / <variant> / seed <s>"``,
            the outcome, ``"at t = <t> s: <what touches, or no contact>"``.

    Returns:
        The written path.

    Raises:
        DfcoaError: The scenario file or the log cannot be read.
    """
    log = read_log(results_dir, row)
    sc = scenario_for_row(row)
    grid = sc.world.grid
    k = nearest_step(log, t)
    fig = map_figure(grid, None, 100.0)
    ax = fig.add_subplot()
    draw_world(ax, grid, sc.spec.leader.goal, sc.spec.leader.start, shapes=sc.world.shapes)
    _draw_run(ax, log, upto=k + 1, alpha=0.35)
    r = robot_radius(log)
    colors = robot_colors(log.pose.shape[1])
    for i, color in enumerate(colors):
        # add_artist, not add_patch: the limits are set below, and add_patch's update
        # of them from every disc's Bezier extrema took most of a 100-robot snapshot
        xy = (float(log.pose[k, i, 0]), float(log.pose[k, i, 1]))
        ax.add_artist(CirclePatch(xy, r, facecolor=color, alpha=0.8, zorder=6,
                                  edgecolor="black", linewidth=0.5,
                                  label=_robot_label(i, len(colors))))
    for j, (c, rad) in enumerate(zip(np.asarray(log.dyn_pos[k]), np.asarray(log.dyn_radius),
                                     strict=True)):
        ax.add_artist(CirclePatch(c, rad, facecolor="grey", alpha=0.6, zorder=5,
                                  label="moving obstacle" if j == 0 else None))
    ax.plot(log.slots[k, :, 0], log.slots[k, :, 1], "x", color="black", markersize=4, zorder=7,
            label="formation slots")
    ax.plot([log.leader[k, 0]], [log.leader[k, 1]], "^", color="black", markersize=7, zorder=7,
            label="leader")
    contacts = contacts_at(log, k, grid)
    draw_contacts(ax, log, k, contacts, r)
    view = _view([log], grid.extent)
    ax.set_xlim(view[0], view[1])
    ax.set_ylim(view[2], view[3])
    head = title or (f"{row['scenario']} / {variant_name(row)} / seed {row['seed']}\n"
                     f"{outcome_text(row)}\nat t = {log.t[k]:.2f} s: "
                     f"{describe(contacts) or 'no contact'}")
    width = max(float(fig.get_size_inches()[0]) - 2.0, 3.0)  # the legend takes ~2 in
    ax.set_title(wrap_text(head, width, TITLE_PT), fontsize=TITLE_PT)
    legend_and_fit(fig, ax, colors, fit=True, freeze=True)
    return save_png(fig, path)
