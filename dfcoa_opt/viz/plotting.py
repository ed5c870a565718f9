"""Headless figures and animations of one run: the map, trajectories, time series.

The figures are those of :mod:`dfcoa_opt.viz.layout` (an Agg canvas, no
pyplot, laid out and drawn once, written atomically, map-sized; teams of more
than :data:`~dfcoa_opt.viz.layout.MAX_LEGEND_ROBOTS` robots get a colour
bar of indices). Animations (:mod:`dfcoa_opt.viz.animation`) draw the static map
once and only the moving artists per frame (blitting), and write the GIF with
Pillow.

All coordinates are world metres, angles radians and times seconds. Typical use
with a loaded scenario::

    plot_run(log, scenario.world.grid, "run.png",
             goal=scenario.spec.leader.goal, start=scenario.spec.leader.start)
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import matplotlib as mpl
import numpy as np
from matplotlib.collections import LineCollection, PatchCollection
from matplotlib.colors import ListedColormap, to_rgb
from matplotlib.figure import Figure
from matplotlib.patches import Circle as CirclePatch
from matplotlib.patches import Polygon as PolygonPatch

from dfcoa_opt.metrics.contacts import contacts_at, describe, first_contact_step
from dfcoa_opt.metrics.outcome import classify, outcome_text
from dfcoa_opt.viz.layout import (
    MAX_LEGEND_ROBOTS,
    index_colorbar,
    legend_and_fit,
    map_figure,
    new_figure,
    save_png,
    wrap_text,
)
from dfcoa_opt.world.shapes import Circle

if TYPE_CHECKING:
    from matplotlib.artist import Artist
    from matplotlib.axes import Axes
    from numpy.typing import ArrayLike, NDArray

    from dfcoa_opt.metrics.contacts import Contact
    from dfcoa_opt.scenario.schema import MetricSpec
    from dfcoa_opt.sim.log import RunLog
    from dfcoa_opt.world.grid import OccupancyGrid
    from dfcoa_opt.world.shapes import Shape

#: Colours of the map image: free cells, occupied cells.
FREE_COLOR = "#ffffff"
OCCUPIED_COLOR = "#404040"
#: Colour of moving obstacles.
OBSTACLE_COLOR = "#8c8c8c"
#: Colour of the contact marks (:func:`draw_contacts`).
CONTACT_COLOR = "#e41a1c"
#: Drawing order: moving-obstacle tracks, the leader's path (below every robot's line, so
#: that a robot driving on it stays visible), the robots' lines, the contact marks on top.
Z_OBSTACLE_TRACK, Z_LEADER, Z_ROBOT, Z_CONTACT = 2.0, 2.5, 3.0, 10.0
#: The leader's path: dashed, wider than a robot's line and faint, so that where a robot
#: drives on it (robot 0 often does) the dashes show on both sides of the robot's line.
LEADER_STYLE: dict[str, Any] = {"linestyle": "--", "color": "black", "alpha": 0.4, "linewidth": 3.5}
#: Font size of the run figures' titles, pt.
TITLE_PT = 10.0

_MAP_CMAP = ListedColormap([FREE_COLOR, OCCUPIED_COLOR])


def robot_colors(n: int) -> list[tuple[float, float, float]]:
    """Distinct RGB colours (components in [0, 1]) for ``n`` robots.

    Grey and black are excluded (they mark the map, moving obstacles and the
    leader): up to 9 robots get ``tab10`` without its grey, up to 18 ``tab20``
    without its greys, more are sampled from ``turbo``.

    Args:
        n: Number of robots, >= 0.
    """
    if n <= 9:
        palette = [c for i, c in enumerate(mpl.colormaps["tab10"].colors) if i != 7]
    elif n <= 18:
        palette = [c for i, c in enumerate(mpl.colormaps["tab20"].colors) if i not in (14, 15)]
    else:
        palette = list(mpl.colormaps["turbo"](np.linspace(0.05, 0.95, n)))  # one lookup
    return [tuple(float(v) for v in to_rgb(c)) for c in palette[:n]]  # type: ignore[misc]


def draw_world(ax: Axes, grid: OccupancyGrid, goal: ArrayLike | None = None,
               start: ArrayLike | None = None, *, shapes: Iterable[Shape] = ()) -> None:
    """Draw the occupancy map (occupied dark grey, free white) on ``ax``.

    The image covers ``grid.extent`` with row 0 at the bottom, the axes get an
    equal aspect ratio and limits equal to the extent (callers may widen them).

    Args:
        ax: Target axes.
        grid: The map.
        goal: Leader goal ``(x, y)`` in m, drawn as a star.
        start: Leader start ``(x, y)`` in m, drawn as a square.
        shapes: Exact static shapes, drawn as outlines over the raster.
    """
    xmin, xmax, ymin, ymax = grid.extent
    ax.imshow(grid.occupied.astype(np.uint8), cmap=_MAP_CMAP, vmin=0, vmax=1,
              origin="lower", extent=(xmin, xmax, ymin, ymax), interpolation="nearest",
              zorder=0)
    # one collection, not a patch per shape: ``add_patch`` updates the data limits
    # from each patch's Bezier extrema, 35 % of a cluttered map's trajectory figure
    outlines = [CirclePatch(shape.center, shape.radius) if isinstance(shape, Circle)
                else PolygonPatch(shape.to_polygon().as_array(), closed=True)
                for shape in shapes]
    if outlines:
        ax.add_collection(PatchCollection(outlines, facecolors="none", edgecolors="black",
                                          linewidths=0.8, zorder=1), autolim=False)
    if start is not None:
        sx, sy = np.asarray(start, dtype=float)[:2]
        ax.plot([sx], [sy], "s", color="black", markerfacecolor="none", markersize=9,
                label="start", zorder=5)
    if goal is not None:
        gx, gy = np.asarray(goal, dtype=float)[:2]
        ax.plot([gx], [gy], "*", color="gold", markeredgecolor="black", markersize=15,
                label="goal", zorder=5)
    ax.set_xlim(xmin, xmax)
    ax.set_ylim(ymin, ymax)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")


def run_figure(log: RunLog, grid: OccupancyGrid, goal: ArrayLike | None = None,
               start: ArrayLike | None = None, title: str | None = None, *,
               shapes: Iterable[Shape] = (), figsize: tuple[float, float] | None = None,
               dpi: float = 100.0, metrics: MetricSpec | None = None) -> Figure:
    """The summary figure of a run (what :func:`plot_run` saves).

    Shows the map, each robot's trajectory (legend "robot i"; a colour bar of
    robot indices for more than :data:`MAX_LEGEND_ROBOTS` robots), the virtual
    leader's path (dashed black, below the robots' lines), the final robot discs
    with heading lines, the final formation slots (hollow circles), the moving
    obstacles' trajectories (thin grey) with their final discs, and the first
    contact, if any (:func:`draw_contacts`). The title's second line is the
    run's outcome (:func:`outcome_title`).

    Args:
        log: The run.
        grid: The map the run used.
        goal: Leader goal ``(x, y)`` in m.
        start: Leader start ``(x, y)`` in m.
        title: First line of the title; default ``"{scenario} - {controller} - seed {seed}"``.
        shapes: Exact static shapes to outline.
        figsize: ``(width, height)`` in inches; None:
            :data:`~dfcoa_opt.viz.layout.MAP_FIGURE_WIDTH` wide and as tall as the map needs.
        dpi: Pixels per inch (image is ``figsize * dpi`` pixels).
        metrics: The scenario's metric settings (the deadlock test of the outcome);
            default ``MetricSpec()``.

    Raises:
        ValueError: On an empty log.
    """
    if log.n_steps == 0:
        raise ValueError("the log has no steps")
    fig = map_figure(grid, figsize, dpi)
    ax = fig.add_subplot()
    draw_world(ax, grid, goal, start, shapes=shapes)
    colors = robot_colors(log.n_robots)
    radius = _robot_radius(log, grid)
    pose = np.asarray(log.pose, dtype=float)
    for i, color in enumerate(colors):
        ax.plot(pose[:, i, 0], pose[:, i, 1], "-", color=color, linewidth=2.0,
                label=_robot_label(i, len(colors)), zorder=Z_ROBOT)
    leader = np.asarray(log.leader, dtype=float)
    ax.plot(leader[:, 0], leader[:, 1], label="leader", zorder=Z_LEADER, **LEADER_STYLE)
    dyn = np.asarray(log.dyn_pos, dtype=float)
    for j in range(dyn.shape[1]):
        ax.plot(dyn[:, j, 0], dyn[:, j, 1], "-", color=OBSTACLE_COLOR, linewidth=0.8,
                label="moving obstacle" if j == 0 else None, zorder=Z_OBSTACLE_TRACK)
    final = _Frame(ax, colors, radius, np.asarray(log.dyn_radius, dtype=float))
    final.update(pose[-1], np.asarray(log.slots, dtype=float)[-1], dyn[-1])
    text, k0, contacts = outcome_title(log, grid, metrics)
    if k0 is not None:
        draw_contacts(ax, log, k0, contacts, radius)
    ax.set_title(_title(fig, _default_title(log) if title is None else title, text),
                 fontsize=TITLE_PT)
    _set_view(ax, grid, log, radius, goal, start)
    legend_and_fit(fig, ax, colors, fit=figsize is None)
    return fig


def plot_run(log: RunLog, grid: OccupancyGrid, path: str | Path, goal: ArrayLike | None = None,
             start: ArrayLike | None = None, title: str | None = None, *,
             shapes: Iterable[Shape] = (), figsize: tuple[float, float] | None = None,
             dpi: float = 100.0, metrics: MetricSpec | None = None) -> Path:
    """Save :func:`run_figure` of a run as a PNG at ``path`` (folders are created).

    The other arguments are :func:`run_figure`'s.

    Returns:
        The written path.

    Raises:
        ValueError: On an empty log.
    """
    fig = run_figure(log, grid, goal, start, title, shapes=shapes, figsize=figsize, dpi=dpi,
                     metrics=metrics)
    return save_png(fig, path)


def outcome_title(log: RunLog, grid: OccupancyGrid | None = None,
                  metrics: MetricSpec | None = None) -> tuple[str, int | None, list[Contact]]:
    """A run's outcome in words, the instant of its first contact and the contacts there.

    The outcome is :func:`dfcoa_opt.metrics.outcome.classify`'s, worded by
    :func:`~dfcoa_opt.metrics.outcome.outcome_text`; a collision names what touched
    (:func:`dfcoa_opt.metrics.contacts.describe`).

    Args:
        log: The run.
        grid: Its map (places contacts with the static map on the obstacle).
        metrics: The scenario's metric settings; default ``MetricSpec()``.

    Returns:
        ``(text, k, contacts)``: e.g. ``"collision at t = 29.20 s (robot 4 and a static
        obstacle)"``; the first contact's step index (None without contact); its contacts.
    """
    end = classify(log, metrics)
    k0 = first_contact_step(log)
    contacts = contacts_at(log, k0, grid) if k0 is not None else []
    return (outcome_text(end["outcome"], end["first_contact_time"], end["deadlock_time"],
                         describe(contacts)), k0, contacts)


def draw_contacts(ax: Axes, log: RunLog, k: int, contacts: Sequence[Contact],
                  radius: float) -> list[Artist]:
    """Mark the contacts of instant ``k``: where they touched, and who.

    A red ``X`` at each contact point (legend "contact"), and a red ring around
    every robot and moving disc involved, where it was at ``k`` (legend "in
    contact"), above everything else.

    Args:
        ax: Target axes.
        log: The run.
        k: The instant of the contacts.
        contacts: Its contacts (:func:`dfcoa_opt.metrics.contacts.contacts_at`).
        radius: The robots' drawn radius, m (the rings are a little wider).

    Returns:
        The artists (rings first, then the markers); none without contacts.
    """
    if not contacts:
        return []
    pose, dyn = np.asarray(log.pose[k], dtype=float), np.asarray(log.dyn_pos[k], dtype=float)
    robots = sorted({c.robot for c in contacts} | {c.other for c in contacts
                                                   if c.kind == "robot"})
    discs = sorted({c.other for c in contacts if c.kind == "moving"})
    rings = [CirclePatch((float(pose[i, 0]), float(pose[i, 1])), 1.4 * radius) for i in robots]
    rings += [CirclePatch((float(dyn[j, 0]), float(dyn[j, 1])),
                          float(log.dyn_radius[j]) + 0.4 * radius) for j in discs]
    for n, ring in enumerate(rings):
        ring.set(fill=False, edgecolor=CONTACT_COLOR, linewidth=2.0, zorder=Z_CONTACT,
                 label="in contact" if n == 0 else None)
        ax.add_artist(ring)  # not add_patch: the view is set from the run, not from the marks
    xy = np.array([c.point for c in contacts])
    (mark,) = ax.plot(xy[:, 0], xy[:, 1], "X", color=CONTACT_COLOR, markeredgecolor="black",
                      markeredgewidth=0.8, markersize=11, linestyle="none", label="contact",
                      zorder=Z_CONTACT + 0.1)
    return [*rings, mark]


def plot_timeseries(log: RunLog, series: Mapping[str, ArrayLike], path: str | Path,
                    ylabel: str = "", *, title: str | None = None,
                    figsize: tuple[float, float] = (7.0, 3.5), dpi: float = 100.0) -> Path:
    """Save a PNG of several signals against the run time ``log.t``.

    Up to :data:`MAX_LEGEND_ROBOTS` series get a legend; more are coloured as
    :func:`robot_colors` and named on a colour bar.

    Args:
        log: The run (provides the time axis, s).
        series: Legend label -> ``(T,)`` values, plotted in order.
        path: Output ``.png`` file; parent directories are created.
        ylabel: Y-axis label, with units, e.g. ``"v (m/s)"``.
        title: Optional title.
        figsize: ``(width, height)`` in inches.
        dpi: Pixels per inch.

    Returns:
        The written path.

    Raises:
        ValueError: If a series does not have shape ``(T,)``.
    """
    t = np.asarray(log.t, dtype=float)
    fig = new_figure(figsize, dpi)
    ax = fig.add_subplot()
    many = len(series) > MAX_LEGEND_ROBOTS
    colors = robot_colors(len(series)) if many else [None] * len(series)
    for (label, values), color in zip(series.items(), colors, strict=True):
        y = np.asarray(values, dtype=float)
        if y.shape != t.shape:
            raise ValueError(f"series {label!r} has shape {y.shape}, expected {t.shape}")
        ax.plot(t, y, linewidth=1.5, color=color, label=None if many else label)
    ax.set_xlabel("t (s)")
    ax.set_ylabel(ylabel)
    ax.grid(True, alpha=0.3)
    if many:
        index_colorbar(fig, ax, colors, [str(k) for k in series])  # type: ignore[arg-type]
    elif series:
        ax.legend(fontsize="small")
    if title is not None:
        ax.set_title(title)
    return save_png(fig, path)


class _Frame:
    """Robot discs, heading lines, slot markers and moving-obstacle discs at one step."""

    def __init__(self, ax: Axes, colors: Sequence[tuple[float, float, float]], radius: float,
                 dyn_radius: NDArray[np.float64]) -> None:
        self.radius = radius
        self.discs = [CirclePatch((0.0, 0.0), radius, facecolor=(*c, 0.35), edgecolor=c,
                                  linewidth=1.5, zorder=7) for c in colors]
        self.headings = LineCollection([], colors=colors, linewidths=2.0, zorder=8)
        self.slots = ax.scatter(np.zeros(len(colors)), np.zeros(len(colors)), s=50,
                                facecolors="none", edgecolors=colors, linewidths=1.5,
                                zorder=6, label="slots")
        self.obstacles = [CirclePatch((0.0, 0.0), float(r), facecolor=OBSTACLE_COLOR,
                                      edgecolor="black", alpha=0.7, linewidth=0.8, zorder=5)
                          for r in dyn_radius]
        for patch in (*self.discs, *self.obstacles):
            ax.add_patch(patch)
        ax.add_collection(self.headings, autolim=False)

    def artists(self) -> list[Artist]:
        """Every artist :meth:`update` moves."""
        return [*self.discs, self.headings, self.slots, *self.obstacles]

    def update(self, pose: NDArray[np.float64], slots: NDArray[np.float64],
               dyn_pos: NDArray[np.float64]) -> None:
        """Move everything to ``pose (N, 3)``, ``slots (N, 2)``, ``dyn_pos (M, 2)`` (m, rad)."""
        for disc, p in zip(self.discs, pose, strict=True):
            disc.set_center((p[0], p[1]))
        tip = pose[:, :2] + 1.8 * self.radius * np.column_stack(
            (np.cos(pose[:, 2]), np.sin(pose[:, 2])))
        self.headings.set_segments(list(np.stack((pose[:, :2], tip), axis=1)))
        self.slots.set_offsets(slots.reshape(-1, 2))
        for disc, q in zip(self.obstacles, dyn_pos, strict=True):
            disc.set_center((q[0], q[1]))


def _robot_label(i: int, n: int) -> str | None:
    """Legend label of robot ``i`` of ``n``; None (no entry) past :data:`MAX_LEGEND_ROBOTS`."""
    return f"robot {i}" if n <= MAX_LEGEND_ROBOTS else None


def _robot_radius(log: RunLog, grid: OccupancyGrid) -> float:
    """``meta["robot_radius"]`` in m, or 1 % of the map width when missing or invalid."""
    r = float(log.meta.get("robot_radius", 0.0) or 0.0)
    return r if np.isfinite(r) and r > 0 else 0.01 * grid.size[0]


def _default_title(log: RunLog) -> str:
    m = log.meta
    return f"{m.get('scenario', '?')} - {m.get('controller', '?')} - seed {m.get('seed', '?')}"


def _title(fig: Figure, head: str, outcome: str) -> str:
    """``head`` over ``outcome``, wrapped to the width the map leaves (the legend takes ~2 in)."""
    width = max(float(fig.get_size_inches()[0]) - 2.0, 3.0)
    return wrap_text(f"{head}\n{outcome}", width, TITLE_PT)


def _set_view(ax: Axes, grid: OccupancyGrid, log: RunLog, radius: float,
              goal: ArrayLike | None, start: ArrayLike | None) -> None:
    """Limits covering the map and everything the run visited, with a small margin."""
    xmin, xmax, ymin, ymax = grid.extent
    dyn_r = float(np.max(log.dyn_radius, initial=0.0))
    lo, hi = np.array([xmin, ymin]), np.array([xmax, ymax])
    groups = [(np.asarray(log.pose, dtype=float)[..., :2], radius),
              (np.asarray(log.leader, dtype=float)[:, :2], 0.0),
              (np.asarray(log.slots, dtype=float), 0.0),
              (np.asarray(log.dyn_pos, dtype=float), dyn_r)]
    groups += [(np.asarray(p, dtype=float)[:2], 0.0) for p in (goal, start) if p is not None]
    for pts, margin in groups:
        pts = pts.reshape(-1, 2)
        pts = pts[np.isfinite(pts).all(axis=1)]
        if len(pts):
            lo = np.minimum(lo, pts.min(0) - margin)
            hi = np.maximum(hi, pts.max(0) + margin)
    if (lo < [xmin, ymin]).any() or (hi > [xmax, ymax]).any():
        pad = 0.02 * float(np.max(hi - lo))
        ax.set_xlim(lo[0] - pad, hi[0] + pad)
        ax.set_ylim(lo[1] - pad, hi[1] + pad)


