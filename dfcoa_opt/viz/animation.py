"""GIF animations of one run: the static map drawn once, only the moving artists per frame.

Part of the figures of :mod:`dfcoa_opt.viz.plotting` (its helpers draw the map,
the legend and the view). Each frame restores the picture of the static map
and redraws the trails, robots, leader, slots, moving obstacles and time over
it (blitting); Pillow writes the frames with one 256-colour palette. Headless:
no pyplot, no GUI backend. Coordinates in metres, times in seconds.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from operator import attrgetter
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from matplotlib.figure import Figure
from PIL import Image

from dfcoa_opt.viz.layout import freeze_layout, legend_and_fit, map_figure, save_atomic
from dfcoa_opt.viz.plotting import (
    LEADER_STYLE,
    OBSTACLE_COLOR,
    TITLE_PT,
    Z_LEADER,
    Z_OBSTACLE_TRACK,
    Z_ROBOT,
    _default_title,
    _Frame,
    _robot_label,
    _robot_radius,
    _set_view,
    _title,
    draw_contacts,
    draw_world,
    outcome_title,
    robot_colors,
)

if TYPE_CHECKING:
    from numpy.typing import ArrayLike, NDArray

    from dfcoa_opt.scenario.schema import MetricSpec
    from dfcoa_opt.sim.log import RunLog
    from dfcoa_opt.world.grid import OccupancyGrid
    from dfcoa_opt.world.shapes import Shape


def animate_run(log: RunLog, grid: OccupancyGrid, path: str | Path,
                goal: ArrayLike | None = None, fps: float = 10.0, max_frames: int = 200,
                start: ArrayLike | None = None, *, shapes: Iterable[Shape] = (),
                figsize: tuple[float, float] | None = None, dpi: float = 80.0,
                figure: list[Figure] | None = None, metrics: MetricSpec | None = None) -> Path:
    """Save a GIF animation of a run.

    The ``T`` logged steps are subsampled uniformly (first and last included) to
    ``min(T, max_frames)`` frames. Each frame shows the map, the trails so far,
    the robots as discs with heading lines, the leader, the formation slots
    (hollow circles), the moving obstacles, from the first contact on its marks
    (:func:`~dfcoa_opt.viz.plotting.draw_contacts`), and in the title the run's
    outcome (:func:`~dfcoa_opt.viz.plotting.outcome_title`) and the time. (Pillow
    merges consecutive identical frames; frames always differ in their time.)

    The figure is drawn once; each frame restores that picture without the
    moving artists and draws only them (and the static ones above them) over it.
    The frames share one 256-colour palette, made from the first and last frames.

    Args:
        log: The run.
        grid: The map the run used.
        path: Output ``.gif`` file; parent directories are created.
        goal: Leader goal ``(x, y)`` in m.
        fps: Frames per second of the GIF, > 0.
        max_frames: Largest number of frames, >= 1.
        start: Leader start ``(x, y)`` in m.
        shapes: Exact static shapes to outline.
        figsize: ``(width, height)`` in inches; None:
            :data:`~dfcoa_opt.viz.layout.MAP_FIGURE_WIDTH` wide and as tall as the map needs.
        dpi: Pixels per inch (frames are ``figsize * dpi`` pixels).
        figure: When given, the animation's figure (at its last frame) is appended.
        metrics: The scenario's metric settings (the deadlock test of the outcome);
            default ``MetricSpec()``.

    Returns:
        The written path.

    Raises:
        ValueError: On an empty log, ``max_frames < 1`` or ``fps <= 0``.
    """
    if max_frames < 1 or not fps > 0:
        raise ValueError("need max_frames >= 1 and fps > 0")
    steps = [int(k) for k in frame_indices(log.n_steps, max_frames)]
    anim = _RunAnimation(log, grid, goal, start, shapes, figsize, dpi, metrics)

    def write(tmp: str) -> None:
        palette = _GifPalette([anim.render(steps[0]), anim.render(steps[-1])])
        frames = [palette(anim.render(k)) for k in steps]
        frames[0].save(tmp, format="GIF", save_all=True, append_images=frames[1:],
                       duration=int(1000 / fps), loop=0)

    out = save_atomic(path, write, ".gif")
    anim.set_blitting(False)  # a plain figure again, at its last frame
    if figure is not None:
        figure.append(anim.fig)
    return out


def frame_indices(n_steps: int, max_frames: int) -> NDArray[np.intp]:
    """Uniformly spaced step indices, first and last included, at most ``max_frames``.

    Args:
        n_steps: Number of logged steps T, >= 1.
        max_frames: Largest number of frames, >= 1.

    Returns:
        ``min(n_steps, max_frames)`` strictly increasing indices into ``[0, T)``.
    """
    if n_steps < 1 or max_frames < 1:
        raise ValueError("need n_steps >= 1 and max_frames >= 1")
    n = min(n_steps, max_frames)
    if n == 1:
        return np.array([n_steps - 1], dtype=np.intp)
    # Spacing (T-1)/(n-1) >= 1, so rounding keeps the indices distinct.
    return np.round(np.linspace(0.0, n_steps - 1, n)).astype(np.intp)


# ------------------------------------------------------------------ internals
class _RunAnimation:
    """The figure of :func:`animate_run`, and its frames drawn by blitting.

    Built and laid out as one frame; the artists that move, and the static ones
    drawn above the lowest of them (the same drawing order as a full draw), form
    the overlay. :meth:`render` restores the figure drawn once without the
    overlay, then draws only the overlay.
    """

    def __init__(self, log: RunLog, grid: OccupancyGrid, goal: ArrayLike | None,
                 start: ArrayLike | None, shapes: Iterable[Shape],
                 figsize: tuple[float, float] | None, dpi: float,
                 metrics: MetricSpec | None = None) -> None:
        if log.n_steps == 0:
            raise ValueError("the log has no steps")
        self.pose = np.asarray(log.pose, dtype=float)
        self.leader = np.asarray(log.leader, dtype=float)
        self.slots = np.asarray(log.slots, dtype=float)
        self.dyn = np.asarray(log.dyn_pos, dtype=float)
        self.t = np.asarray(log.t, dtype=float)
        colors = robot_colors(log.n_robots)
        radius = _robot_radius(log, grid)
        self.fig = fig = map_figure(grid, figsize, dpi)
        self.ax = ax = fig.add_subplot()
        draw_world(ax, grid, goal, start, shapes=shapes)
        self.trails = [ax.plot([], [], "-", color=c, linewidth=1.5, zorder=Z_ROBOT,
                               label=_robot_label(i, len(colors)))[0]
                       for i, c in enumerate(colors)]
        self.lead_trail = ax.plot([], [], label="leader", zorder=Z_LEADER, **LEADER_STYLE)[0]
        self.lead_dot = ax.plot([], [], "o", color="black", markersize=5, zorder=6)[0]
        self.dyn_trails = [ax.plot([], [], "-", color=OBSTACLE_COLOR, linewidth=0.8,
                                   zorder=Z_OBSTACLE_TRACK,
                                   label="moving obstacle" if j == 0 else None)[0]
                           for j in range(self.dyn.shape[1])]
        self.frame = _Frame(ax, colors, radius, np.asarray(log.dyn_radius, dtype=float))
        outcome, k0, contacts = outcome_title(log, grid, metrics)
        # the first contact's marks, shown from its frame on (in the legend from the start)
        self.contact_step = k0 if k0 is not None else self.t.size
        self.contact_marks = draw_contacts(ax, log, k0, contacts, radius) if k0 is not None else []
        _set_view(ax, grid, log, radius, goal, start)
        self.head = _title(fig, _default_title(log), outcome)
        self.show(self.t.size - 1)  # the contact marks visible: legend entries copy that
        legend_and_fit(fig, ax, colors, fit=figsize is None)
        self.show(0)
        # Lay the figure out once and freeze it, so frames do not jitter.
        freeze_layout(fig)
        moving = {*self.trails, self.lead_trail, self.lead_dot, *self.dyn_trails,
                  *self.frame.artists(), *self.contact_marks, ax.title}
        order = sorted((a for a in ax.get_children() if a is not ax.patch),
                       key=attrgetter("zorder"))  # as Axes.draw orders them
        first = min(i for i, a in enumerate(order) if a in moving)
        self.overlay = order[first:] + ([ax.title] if ax.title not in order[first:] else [])
        self.background: Any = None

    def show(self, k: int) -> None:
        """Move the artists to step ``k`` (trails up to it); draw nothing."""
        pose, leader, dyn = self.pose, self.leader, self.dyn
        for i, line in enumerate(self.trails):
            line.set_data(pose[: k + 1, i, 0], pose[: k + 1, i, 1])
        self.lead_trail.set_data(leader[: k + 1, 0], leader[: k + 1, 1])
        self.lead_dot.set_data(leader[k : k + 1, 0], leader[k : k + 1, 1])
        for j, line in enumerate(self.dyn_trails):
            line.set_data(dyn[: k + 1, j, 0], dyn[: k + 1, j, 1])
        self.frame.update(pose[k], self.slots[k], dyn[k])
        for mark in self.contact_marks:
            mark.set_visible(k >= self.contact_step)
        self.ax.set_title(f"{self.head}\nt = {self.t[k]:.2f} s (step {k})", fontsize=TITLE_PT)

    def set_blitting(self, on: bool) -> None:
        """Exclude the overlay from full draws (``on``), or make it a plain figure again."""
        for artist in self.overlay:
            artist.set_animated(on)
        if not on:
            self.background = None

    def render(self, k: int) -> Image.Image:
        """Frame ``k`` as an RGB image, by blitting (the figure is drawn once, the first time)."""
        canvas = self.fig.canvas
        if self.background is None:
            self.set_blitting(True)
            canvas.draw()  # everything but the overlay
            self.background = canvas.copy_from_bbox(self.fig.bbox)
        self.show(k)
        canvas.restore_region(self.background)
        renderer = canvas.get_renderer()
        for artist in self.overlay:
            artist.draw(renderer)
        return self._image()

    def render_full(self, k: int) -> Image.Image:
        """Frame ``k`` as an RGB image drawn the plain way (the whole figure redrawn)."""
        self.set_blitting(False)
        self.show(k)
        self.fig.canvas.draw()
        return self._image()

    def _image(self) -> Image.Image:
        canvas = self.fig.canvas
        return Image.frombuffer("RGBA", canvas.get_width_height(), canvas.buffer_rgba(),
                                "raw", "RGBA", 0, 1).convert("RGB")


class _GifPalette:
    """One 256-colour palette for a GIF's frames, and the exact mapping of a frame to it.

    The palette is Pillow's median cut of sample frames. Each colour maps to its
    nearest palette entry (RGB distance), looked up once: Pillow's own mapping
    (``quantize(palette=...)``) works on 6-bit colour boxes and shifts e.g. the
    white background (mean error ~3 of 255 against ~0.1 here).
    """

    def __init__(self, samples: Sequence[Image.Image]) -> None:
        w, h = samples[0].size
        sheet = Image.new("RGB", (w, h * len(samples)))
        for i, im in enumerate(samples):
            sheet.paste(im, (0, i * h))
        quantized = sheet.quantize(256)  # median cut, for RGB images
        self.rgb = np.asarray(quantized.getpalette() or [0, 0, 0], dtype=np.int32).reshape(-1, 3)
        self._norm2 = (self.rgb.astype(float) ** 2).sum(axis=1)
        self.index = np.full(1 << 24, -1, dtype=np.int16)  # 0xRRGGBB -> entry; -1: not yet

    def __call__(self, frame: Image.Image) -> Image.Image:
        """``frame`` (RGB) as a palette image ("P")."""
        rgb = np.asarray(frame, dtype=np.int32)
        keys = (rgb[..., 0] << 16) | (rgb[..., 1] << 8) | rgb[..., 2]
        idx = self.index[keys]
        if (idx < 0).any():
            new = np.unique(keys[idx < 0])
            for chunk in np.array_split(new, -(-len(new) // 4096)):
                cols = np.stack((chunk >> 16, (chunk >> 8) & 255, chunk & 255), axis=-1)
                # |c - p|^2 less |c|^2 (the same for every p); exact: integers < 2^53
                dist = self._norm2 - 2.0 * (cols.astype(float) @ self.rgb.T.astype(float))
                self.index[chunk] = dist.argmin(axis=1)
            idx = self.index[keys]
        out = Image.frombytes("P", frame.size, idx.astype(np.uint8).tobytes())
        out.putpalette(self.rgb.astype(np.uint8).tobytes())
        return out
