"""Headless figures: an Agg canvas, one layout pass, atomic files, map-sized figures.

Every figure is a bare :class:`matplotlib.figure.Figure` with an Agg canvas
attached (:func:`new_figure`), so neither :mod:`matplotlib.pyplot` nor a GUI
backend is ever imported. A figure is laid out once and drawn once
(:func:`png_bytes`), and files are written atomically (a temporary file in the
target directory, then a rename). Map figures whose ``figsize`` is not given
are :data:`MAP_FIGURE_WIDTH` wide and as tall as the map needs
(:func:`map_figure`, :func:`fit_to_map`); teams of more than
:data:`MAX_LEGEND_ROBOTS` robots get a colour bar of indices, not a legend
entry per robot (:func:`legend_and_fit`). Sizes are in inches.
"""

from __future__ import annotations

import io
import os
import textwrap
import uuid
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.cm import ScalarMappable
from matplotlib.colors import BoundaryNorm, ListedColormap
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from dfcoa_opt.core.atomic import atomic_write

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.colorbar import Colorbar
    from matplotlib.legend import Legend

    from dfcoa_opt.world.grid import OccupancyGrid

#: Largest team (or number of time series) with a legend entry per robot (series);
#: larger ones get a colour bar of indices instead.
MAX_LEGEND_ROBOTS = 8
#: Width (in) of a map figure whose ``figsize`` is not given; its height follows the map.
MAP_FIGURE_WIDTH = 7.0


def new_figure(figsize: tuple[float, float] = (7.0, 6.0), dpi: float = 100.0,
               layout: str | None = "constrained") -> Figure:
    """Create a figure with an Agg canvas attached (no pyplot, no GUI backend).

    Args:
        figsize: ``(width, height)`` in inches.
        dpi: Pixels per inch; the saved image is ``figsize * dpi`` pixels.
        layout: Matplotlib layout engine name, or None.
    """
    fig = Figure(figsize=figsize, dpi=dpi, layout=layout)
    FigureCanvasAgg(fig)
    return fig


def freeze_layout(fig: Figure) -> None:
    """Lay ``fig`` out once with its layout engine, then remove the engine.

    The axes keep the computed positions. ``savefig`` of a figure that still
    has a layout engine (ours: constrained) draws it twice: once with output
    disabled, only to lay it out, then for real; a frozen figure is drawn once.
    """
    engine = fig.get_layout_engine()
    if engine is not None:
        engine.execute(fig)
        fig.set_layout_engine(None)  # (None unless matplotlibrc asks for autolayout)


def png_bytes(fig: Figure) -> bytes:
    """``fig`` rendered as PNG, laid out once (:func:`freeze_layout`), drawn once.

    The same image as ``fig.savefig``, which draws a laid-out figure twice.
    """
    freeze_layout(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()


def save_png(fig: Figure, path: str | Path) -> Path:
    """Write :func:`png_bytes` of ``fig`` to ``path`` atomically (folders are created)."""
    return atomic_write(path, png_bytes(fig))


def map_figure(grid: OccupancyGrid, figsize: tuple[float, float] | None,
                dpi: float) -> Figure:
    """A figure of ``figsize``, or :data:`MAP_FIGURE_WIDTH` wide and tall for the map."""
    if figsize is None:
        xmin, xmax, ymin, ymax = grid.extent
        aspect = (ymax - ymin) / (xmax - xmin) if xmax > xmin else 1.0
        width = MAP_FIGURE_WIDTH
        figsize = (width, float(np.clip(width * aspect + 1.5, 0.4 * width, 1.6 * width)))
    return new_figure(figsize, dpi)


def legend_and_fit(fig: Figure, ax: Axes, colors: Sequence[tuple[float, float, float]],
                    fit: bool, freeze: bool = False) -> None:
    """The figure legend (robots' entries, or a colour bar of their indices), then the fit.

    Up to :data:`MAX_LEGEND_ROBOTS` robots, the legend (robots and the other
    labelled artists) is right of the map; for more, the robots get a colour bar
    and the other artists a one-row legend under the map. With ``fit``, the
    figure is trimmed to the map (:func:`fit_to_map`, ``freeze`` passed on).
    """
    if len(colors) <= MAX_LEGEND_ROBOTS:
        legend = fig.legend(loc="outside right upper", fontsize="small")
    else:
        index_colorbar(fig, ax, colors, [str(i) for i in range(len(colors))], "robot")
        n_entries = len(ax.get_legend_handles_labels()[0])
        legend = fig.legend(loc="outside lower center", fontsize="small",
                            ncols=max(n_entries, 1))
    if fit:
        fit_to_map(fig, ax, legend, freeze)


def index_colorbar(fig: Figure, ax: Axes, colors: Sequence[tuple[float, float, float]],
                    labels: Sequence[str], title: str = "") -> Colorbar:
    """A colour bar right of ``ax``: one band per colour, some ticked with ``labels[i]``.

    About 0.15 in thick: its length (the axes' height) is guessed as the figure's
    height less 1.5 in of labels and title.
    """
    n = len(colors)
    norm = BoundaryNorm(np.arange(n + 1) - 0.5, n)
    length = max(float(fig.get_size_inches()[1]) - 1.5, 1.0)
    bar = fig.colorbar(ScalarMappable(norm, ListedColormap(list(colors))), ax=ax,
                       pad=0.02, aspect=length / 0.15)
    ticks = [int(v) for v in MaxNLocator(6, integer=True).tick_values(0, n - 1) if 0 <= v < n]
    bar.set_ticks(ticks, labels=[labels[i] for i in ticks])
    bar.minorticks_off()
    bar.ax.tick_params(labelsize="small")
    bar.set_label(title, fontsize="small")
    return bar


def fit_to_map(fig: Figure, ax: Axes, legend: Legend, freeze: bool = False) -> None:
    """Resize ``fig`` (same width or narrower) so that the map ``ax`` fills its layout box.

    Lays ``fig`` out with its layout engine with the map's aspect off, so
    the axes box is the space left by the decorations (labels, title, legend,
    colour bar; their size in inches barely depends on the figure's), then sets
    the height for which that box has the map's aspect (at most 1.6 times the
    width; for a taller map the width shrinks). The legend keeps room.

    Args:
        fig: The figure.
        ax: The map's axes.
        legend: The figure's legend.
        freeze: For a figure that is saved as it is: when the size has settled,
            keep the last pass's layout and remove the engine (:func:`freeze_layout`
            would lay it out a third time: a fifth of a failure snapshot's time,
            and the images differ by a few anti-aliased pixels). Without
            it the engine stays, for a figure that its caller may add to.
    """
    engine = fig.get_layout_engine()
    if engine is None:
        return
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    aspect = abs((y1 - y0) / (x1 - x0))
    width = float(fig.get_size_inches()[0])
    to_inches = fig.dpi_scale_trans.inverted()
    ax.set_aspect("auto")
    for _ in range(4):  # later passes correct for tick labels that came or went, and for
        # the colour bar, whose thickness follows the height
        engine.execute(fig)
        w, h = fig.get_size_inches()
        box = ax.get_position()
        deco_w, deco_h = w * (1.0 - box.width), h * (1.0 - box.height)
        leg = legend.get_window_extent(fig.canvas.get_renderer()).transformed(to_inches)
        new_h = float(np.clip(deco_h + (w - deco_w) * aspect, leg.height + 0.2, 1.6 * width))
        new_w = min(width, max(deco_w + (new_h - deco_h) / aspect, leg.width + 0.2))
        if max(abs(new_w - w), abs(new_h - h)) * fig.dpi < 0.5:
            if freeze:
                fig.set_layout_engine(None)
            break
        fig.set_size_inches(new_w, new_h)
    ax.set_aspect("equal")


#: Mean width of a character of the default font (DejaVu Sans), in ems (a generous guess).
CHAR_EM = 0.6


def wrap_text(text: str, width_in: float, fontsize_pt: float) -> str:
    """``text`` with each of its lines wrapped at spaces to fit ``width_in`` inches.

    A line holds about ``width_in * 72 / (CHAR_EM * fontsize_pt)`` characters (at
    least 12); a word longer than that stays whole.

    Args:
        text: The text; its own line breaks are kept.
        width_in: The width available, inches.
        fontsize_pt: The font size, points.
    """
    chars = max(12, int(width_in * 72.0 / (CHAR_EM * fontsize_pt)))
    return "\n".join(textwrap.fill(line, chars, break_long_words=False, break_on_hyphens=False)
                     or line for line in text.split("\n"))


def save_atomic(path: str | Path, write: Callable[[str], object], suffix: str) -> Path:
    """Call ``write(tmp)`` on a temporary file next to ``path``, then rename it to ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = str(path.with_name(f".{path.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.tmp{suffix}"))
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path
