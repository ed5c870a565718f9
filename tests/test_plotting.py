"""Headless plotting: PNG summary, GIF animation, time series, backend independence."""

from __future__ import annotations

import io
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import matplotlib.image as mpimg
import numpy as np
import pytest
from matplotlib.colors import to_rgb
from matplotlib.figure import Figure
from PIL import Image

from dfcoa_opt.sim.log import RunLog
from dfcoa_opt.viz import animation, plotting
from dfcoa_opt.viz import layout as figure_layout
from dfcoa_opt.world.grid import OccupancyGrid
from dfcoa_opt.world.shapes import Circle, Rectangle

T, N, M = 30, 3, 1
ROBOT_Y = (3.0, 5.0, 7.0)  # robot i drives along y = ROBOT_Y[i]


def make_grid() -> OccupancyGrid:
    """20 x 20 m, 1 cell/m, one 4 x 4 m block in the upper right (x, y in [12, 16))."""
    occ = np.zeros((20, 20), dtype=bool)
    occ[12:16, 12:16] = True
    return OccupancyGrid(occ, resolution=1.0)


def make_log(n_steps: int = T, n_dyn: int = M, n_robots: int = N) -> RunLog:
    """Robots on straight lines from x = 2 to x = 14: three along y = 3, 5, 7, more spread
    over y in [2, 18]."""
    t = np.arange(n_steps) * 0.1
    s = np.linspace(0.0, 1.0, n_steps)
    x = 2.0 + 12.0 * s
    pose = np.zeros((n_steps, n_robots, 3))
    pose[:, :, 0] = x[:, None]
    pose[:, :, 1] = (np.asarray(ROBOT_Y) if n_robots == N
                     else np.linspace(2.0, 18.0, n_robots))[None, :]
    leader = np.zeros((n_steps, 5))
    leader[:, 0] = x + 0.5
    leader[:, 1] = 4.0  # between the robots, so its dashes hide no trajectory
    leader[:, 3] = 12.0 / t[-1] if n_steps > 1 else 0.0
    slots = pose[:, :, :2] + [0.5, 0.0]
    dyn_pos = np.zeros((n_steps, n_dyn, 2))
    if n_dyn:
        dyn_pos[:, 0, 0] = 10.0
        dyn_pos[:, 0, 1] = 1.0 + 8.0 * s
    zf = np.zeros((n_steps, n_robots))
    zi = np.zeros(n_steps, dtype=np.int32)
    return RunLog(
        t=t, pose=pose, pose_est=pose.copy(), velocity=np.zeros((n_steps, n_robots, 2)),
        twist=np.zeros((n_steps, n_robots, 2)), command=np.zeros((n_steps, n_robots, 2)),
        leader=leader, slots=slots, offsets=np.zeros((n_robots, 2)), clearance=zf.copy(),
        min_inter_robot=np.full(n_steps, 2.0), robot_contacts=zi.copy(),
        obstacle_contacts=zi.copy(), dynamic_contacts=zi.copy(), collision_events=zi.copy(),
        dyn_pos=dyn_pos, dyn_radius=np.full(n_dyn, 0.4),
        filter_status=np.zeros((n_steps, n_robots), dtype=np.int8), filter_slack=zf.copy(),
        filter_time=zf.copy(), steering=np.full_like(zf, np.nan),
        meta={"scenario": "unit", "controller": "dfcoa", "seed": 7, "robot_radius": 0.3},
    )


def _color_mask(img: np.ndarray, rgb: tuple[float, float, float], tol: float = 0.03) -> np.ndarray:
    return (np.abs(img[..., :3] - np.asarray(rgb)) < tol).all(axis=-1)


def test_robot_colors_distinct_and_not_grey() -> None:
    for n in (1, 3, 9, 12, 25):
        cols = np.array(plotting.robot_colors(n))
        assert cols.shape == (n, 3)
        assert len({tuple(c) for c in np.round(cols, 4)}) == n
        assert (np.ptp(cols, axis=1) > 0.05).all()  # no greys / black


def test_draw_world_orientation() -> None:
    grid = make_grid()
    fig = plotting.new_figure((4.0, 4.0), 100.0, layout=None)
    ax = fig.add_subplot()
    plotting.draw_world(ax, grid, goal=(18.0, 18.0), start=(1.0, 1.0))
    assert ax.get_xlim() == (0.0, 20.0) and ax.get_ylim() == (0.0, 20.0)
    assert ax.get_aspect() == 1.0
    fig.canvas.draw()
    img = np.asarray(fig.canvas.buffer_rgba())[..., :3] / 255.0
    height = img.shape[0]

    def pixel(x: float, y: float) -> np.ndarray:
        px, py = ax.transData.transform((x, y))
        return img[int(round(height - py)), int(round(px))]

    dark = np.asarray(to_rgb(plotting.OCCUPIED_COLOR))
    assert np.allclose(pixel(14.0, 14.0), dark, atol=0.02)  # the block, upper right
    assert np.allclose(pixel(14.0, 6.0), 1.0, atol=0.02)  # mirrored in y: free
    assert np.allclose(pixel(6.0, 14.0), 1.0, atol=0.02)  # mirrored in x: free


def test_draw_world_outlines_every_shape_in_one_collection_and_keeps_the_extent() -> None:
    fig = plotting.new_figure((4.0, 4.0), 100.0, layout=None)
    ax = fig.add_subplot()
    shapes = (Rectangle((12.0, 12.0), (16.0, 16.0)), Circle((4.0, 15.0), 1.0),
              Circle((30.0, 30.0), 2.0))  # outside the map: must not widen the view
    plotting.draw_world(ax, make_grid(), shapes=shapes)
    (outlines,) = ax.collections
    assert len(outlines.get_paths()) == 3 and not ax.patches
    assert outlines.get_facecolor().size == 0  # hollow
    assert np.allclose(outlines.get_edgecolor(), [0.0, 0.0, 0.0, 1.0])
    assert ax.get_xlim() == (0.0, 20.0) and ax.get_ylim() == (0.0, 20.0)
    fig.canvas.draw()
    img = np.asarray(fig.canvas.buffer_rgba())[..., :3] / 255.0
    px, py = ax.transData.transform((4.0, 16.0))  # the circle's top edge is drawn dark
    patch = img[int(round(img.shape[0] - py)) - 2:int(round(img.shape[0] - py)) + 3,
                int(round(px)) - 2:int(round(px)) + 3]
    assert patch.min() < 0.5


@pytest.fixture
def draws(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Counts ``Figure.draw`` calls (one entry per draw) while the test runs."""
    calls: list[int] = []
    real_draw = Figure.draw
    monkeypatch.setattr(Figure, "draw", lambda self, r: calls.append(1) or real_draw(self, r))
    return calls


def _boxplot_figure() -> Figure:
    fig = plotting.new_figure((6.0, 3.0), 80.0)
    axes = fig.subplots(1, 2)
    for k, ax in enumerate(axes):
        ax.boxplot([np.arange(5.0) + k, np.arange(7.0) * 2], widths=0.5)
        ax.set_xticks([1, 2], ["a long\nlabel", "b"], rotation=60, ha="right")
        ax.set_title(f"panel {k}")
    axes[0].set_ylabel("value (m)")
    fig.legend(["x"], loc="outside right upper")
    return fig


def test_png_bytes_draws_once_and_gives_savefigs_image(draws: list[int]) -> None:
    buf = io.BytesIO()
    _boxplot_figure().savefig(buf, format="png")
    assert len(draws) == 2  # savefig alone draws a laid-out figure twice
    fig = _boxplot_figure()
    data = figure_layout.png_bytes(fig)
    assert len(draws) == 3
    assert fig.get_layout_engine() is None
    ours = mpimg.imread(io.BytesIO(data))
    theirs = mpimg.imread(io.BytesIO(buf.getvalue()))
    assert ours.shape == theirs.shape and np.array_equal(ours, theirs)


def test_plot_run_png(tmp_path: Path) -> None:
    out = plotting.plot_run(make_log(), make_grid(), tmp_path / "sub" / "run.png",
                            goal=(15.0, 5.0), start=(2.5, 5.0), figsize=(6.0, 5.0), dpi=100)
    assert out == tmp_path / "sub" / "run.png" and out.is_file()
    assert sorted(p.name for p in out.parent.iterdir()) == ["run.png"]  # no temp left over
    img = mpimg.imread(out)
    assert img.shape[:2] == (500, 600)
    assert img[..., :3].var() > 0
    rows = []
    for rgb in plotting.robot_colors(N):
        mask = _color_mask(img, rgb)
        assert mask.sum() > 200, "trajectory colour missing"  # a legend line alone is << 200 px
        rows.append(np.median(np.nonzero(mask)[0]))
    # higher y is higher in the picture (smaller image row): map is not flipped
    assert rows[0] > rows[1] > rows[2]


def test_plot_run_no_moving_obstacles_custom_title_shapes(tmp_path: Path) -> None:
    log = make_log(n_dyn=0)
    log.meta.pop("robot_radius")
    shapes = (Rectangle((12.0, 12.0), (16.0, 16.0)), Circle((4.0, 15.0), 1.0))
    out = plotting.plot_run(log, make_grid(), tmp_path / "a.png", title="custom", dpi=50,
                            shapes=shapes)
    height, width = mpimg.imread(out).shape[:2]
    assert width == figure_layout.MAP_FIGURE_WIDTH * 50 and height < width  # height fits the map


def test_plot_run_overwrites_atomically(tmp_path: Path) -> None:
    target = tmp_path / "run.png"
    target.write_bytes(b"old")
    plotting.plot_run(make_log(), make_grid(), target, dpi=40)
    assert target.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert [p.name for p in tmp_path.iterdir()] == ["run.png"]


def _gif_frames(path: Path) -> list[np.ndarray]:
    with Image.open(path) as im:
        frames = []
        for k in range(im.n_frames):
            im.seek(k)
            frames.append(np.asarray(im.convert("RGB"), dtype=np.int16))
    return frames


@pytest.mark.parametrize("max_frames", [200, 10])
def test_animate_run_gif(tmp_path: Path, max_frames: int, draws: list[int]) -> None:
    out = animation.animate_run(make_log(), make_grid(), tmp_path / "run.gif", goal=(15.0, 5.0),
                               fps=12, max_frames=max_frames, figsize=(4.0, 3.0), dpi=50)
    assert out.is_file()
    assert [p.name for p in tmp_path.iterdir()] == ["run.gif"]
    with Image.open(out) as im:
        assert im.format == "GIF"
        assert im.size == (200, 150)
        assert im.n_frames == min(T, max_frames)
    assert len(draws) == 1  # the figure is drawn once; the frames are blitted over it
    frames = _gif_frames(out)
    for a, b in zip(frames, frames[1:], strict=False):
        assert np.abs(a - b).sum() > 0
    assert np.abs(frames[0] - frames[-1]).sum() > 1000  # robots moved, not just the title


def test_frame_indices() -> None:
    assert animation.frame_indices(30, 200).tolist() == list(range(30))
    idx = animation.frame_indices(1001, 200)
    assert len(idx) == 200 and idx[0] == 0 and idx[-1] == 1000
    assert (np.diff(idx) > 0).all() and np.ptp(np.diff(idx)) <= 1
    for n, m in [(7, 6), (5, 5), (2, 1), (1, 3)]:
        got = animation.frame_indices(n, m)
        assert len(got) == min(n, m) and len(set(got.tolist())) == len(got)
        assert got[-1] == n - 1
    with pytest.raises(ValueError):
        animation.frame_indices(0, 10)
    with pytest.raises(ValueError):
        animation.animate_run(make_log(), make_grid(), "unused.gif", max_frames=0)


def test_plot_timeseries(tmp_path: Path) -> None:
    log = make_log()
    series = {f"robot {i}": np.sin(log.t + i) for i in range(N)}
    out = plotting.plot_timeseries(log, series, tmp_path / "v.png", ylabel="v (m/s)", dpi=50)
    img = mpimg.imread(out)
    assert img.shape[:2] == (175, 350) and img[..., :3].var() > 0
    with pytest.raises(ValueError, match="shape"):
        plotting.plot_timeseries(log, {"bad": np.zeros(T + 1)}, tmp_path / "bad.png")


_SCRIPT = textwrap.dedent("""
    import sys
    sys.path.insert(0, {tests!r})
    from test_plotting import make_grid, make_log
    from dfcoa_opt.viz import animation, plotting
    log, grid = make_log(n_steps=5), make_grid()
    plotting.plot_run(log, grid, {png!r}, dpi=30)
    animation.animate_run(log, grid, {gif!r}, max_frames=3, dpi=30)
    plotting.plot_timeseries(log, {{"x": log.pose[:, 0, 0]}}, {ts!r}, dpi=30)
    assert "matplotlib.pyplot" not in sys.modules, "pyplot was imported"
""")


@pytest.mark.parametrize("backend", [None, "TkAgg"])
def test_works_without_display_under_any_backend(tmp_path: Path, backend: str | None) -> None:
    env = {k: v for k, v in os.environ.items()
           if k not in ("DISPLAY", "WAYLAND_DISPLAY", "MPLBACKEND")}
    if backend is not None:
        env["MPLBACKEND"] = backend
    files = {name: str(tmp_path / f"out.{name}") for name in ("png", "gif")}
    script = _SCRIPT.format(tests=str(Path(__file__).parent), ts=str(tmp_path / "ts.png"),
                            **files)
    proc = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True,
                          text=True, timeout=60, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    with Image.open(files["gif"]) as im:
        assert im.n_frames == 3
    assert mpimg.imread(files["png"]).shape[1] == figure_layout.MAP_FIGURE_WIDTH * 30


# ------------------------------------------------------------- legends and layout
def _legend_texts(fig: Figure) -> list[str]:
    """Texts of every legend of ``fig``: figure legends and Axes legends."""
    legends = [*fig.legends, *(ax.get_legend() for ax in fig.axes)]
    return [t.get_text() for leg in legends if leg is not None for t in leg.get_texts()]


@pytest.mark.parametrize("n_robots", [3, 8, 9, 20])
def test_per_robot_legend_up_to_8_robots_then_a_colour_bar(tmp_path: Path, n_robots: int) -> None:
    log, ends = make_log(n_steps=6, n_robots=n_robots), {"goal": (15.0, 5.0), "start": (2.5, 5.0)}
    fig = plotting.run_figure(log, make_grid(), dpi=40, **ends)  # type: ignore[arg-type]
    out: list[Figure] = []
    animation.animate_run(log, make_grid(), tmp_path / "a.gif", max_frames=2, dpi=30, figure=out,
                         **ends)  # type: ignore[arg-type]
    for f in (fig, out[0]):  # the summary figure and the animation's
        texts = _legend_texts(f)
        robots = [t for t in texts if t.startswith("robot")]
        assert {"start", "goal", "leader", "slots", "moving obstacle"} <= set(texts)
        if n_robots <= figure_layout.MAX_LEGEND_ROBOTS:
            assert robots == [f"robot {i}" for i in range(n_robots)]
            assert len(f.axes) == 1
        else:
            assert robots == []  # no entry per robot ...
            assert len(f.axes) == 2  # ... but a colour bar of their indices
            labels = [t.get_text() for t in f.axes[1].get_yticklabels()]
            assert "0" in labels and all(0 <= int(v) < n_robots for v in labels)


def _longest_blank(png: np.ndarray) -> tuple[int, int]:
    """Longest run of all-white rows, and of all-white columns, of an image (px)."""
    ink = (png[..., :3] < 0.97).any(axis=-1)

    def longest(has_ink: np.ndarray) -> int:
        edges = np.flatnonzero(np.diff(np.concatenate(([1], has_ink.astype(int), [1]))))
        return int(np.max(np.diff(edges)[::2], initial=0))  # lengths of the 0-runs

    return longest(ink.any(axis=1)), longest(ink.any(axis=0))


@pytest.mark.parametrize(("cells", "n_robots"), [((10, 40), 20), ((10, 40), 3), ((30, 12), 3),
                                                  ((20, 20), 12)])
def test_map_figure_is_sized_to_the_map(tmp_path: Path, cells: tuple[int, int],
                                        n_robots: int) -> None:
    """Default size: MAP_FIGURE_WIDTH wide, as tall as the map needs: no empty band.

    (Before, a fixed 7 x 6 in figure left 80-100 blank rows under a 40 x 10 m map.)
    """
    grid = OccupancyGrid(np.zeros(cells, dtype=bool), resolution=1.0)
    log = make_log(n_steps=6, n_robots=n_robots)
    for arr in (log.pose[..., 1], log.slots[..., 1], log.dyn_pos[..., 1]):
        arr *= cells[0] / 20.0  # keep everything inside the map
    log.leader[:, 1] = cells[0] / 2.0
    out = plotting.plot_run(log, grid, tmp_path / "m.png", dpi=50)
    png = mpimg.imread(out)
    height, width = png.shape[:2]
    assert width == figure_layout.MAP_FIGURE_WIDTH * 50
    assert height <= 1.6 * width
    rows, cols = _longest_blank(png)
    assert rows <= 10 and cols <= 10, (rows, cols)


def test_plot_timeseries_many_series_get_a_colour_bar(tmp_path: Path) -> None:
    log = make_log()
    series = {f"robot {i}": np.sin(log.t + i) for i in range(12)}
    captured: list[Figure] = []
    real = plotting.save_png

    def keep(fig: Figure, path: str | Path) -> Path:
        captured.append(fig)
        return real(fig, path)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(plotting, "save_png", keep)
        plotting.plot_timeseries(log, series, tmp_path / "many.png", dpi=40)
        plotting.plot_timeseries(log, dict(list(series.items())[:4]), tmp_path / "few.png",
                                 dpi=40)
    many, few = captured
    assert _legend_texts(many) == [] and len(many.axes) == 2
    assert "robot 0" in [t.get_text() for t in many.axes[1].get_yticklabels()]
    assert _legend_texts(few) == [f"robot {i}" for i in range(4)] and len(few.axes) == 1


# ------------------------------------------------------------- animation frames
@pytest.mark.parametrize("n_robots", [3, 12])
def test_animation_frames_are_the_full_redraw_pictures(tmp_path: Path, n_robots: int) -> None:
    """The GIF has a frame per step; each is the picture a full redraw of the figure gives."""
    log, grid = make_log(n_robots=n_robots), make_grid()
    args = dict(goal=(15.0, 5.0), start=(2.5, 5.0), shapes=(Circle((4.0, 15.0), 1.0),))
    out = animation.animate_run(log, grid, tmp_path / "run.gif", max_frames=12, dpi=50,
                               **args)  # type: ignore[arg-type]
    steps = animation.frame_indices(T, 12).tolist()
    frames = _gif_frames(out)
    assert len(frames) == len(steps) == 12
    # the same figure, drawn the plain way: every artist redrawn, for every frame
    old = animation._RunAnimation(log, grid, args["goal"], args["start"], args["shapes"],
                                 None, 50.0)
    for k, frame in zip(steps, frames, strict=True):
        full = np.asarray(old.render_full(k), dtype=np.int16)
        assert frame.shape == full.shape
        diff = np.abs(frame - full)
        assert diff.mean() < 2.0, (k, diff.mean())  # only the 256-colour palette differs
        assert (diff.max(axis=-1) > 32).mean() < 0.01
    # blitting itself is exact: the frames before quantisation are the full redraws
    for k in (steps[0], steps[5], steps[-1]):
        assert np.array_equal(np.asarray(old.render(k)), np.asarray(old.render_full(k)))


def test_a_frozen_fit_is_laid_out_twice_and_keeps_no_engine(monkeypatch) -> None:
    """A failure snapshot is saved as it is: once its size has settled, the fit keeps its
    last layout (two passes, not three with the save's); a figure a caller may add to keeps
    its engine and is laid out again when saved."""
    from matplotlib.layout_engine import ConstrainedLayoutEngine

    calls: list[int] = []
    execute = ConstrainedLayoutEngine.execute
    monkeypatch.setattr(ConstrainedLayoutEngine, "execute",
                        lambda self, fig: (calls.append(1), execute(self, fig))[1])
    sizes = []
    for freeze in (True, False):
        calls.clear()
        grid = make_grid()
        fig = figure_layout.map_figure(grid, None, 80.0)
        ax = fig.add_subplot()
        ax.plot([0.0, 20.0], [0.0, 10.0], label="path")
        ax.set_xlim(0.0, 20.0)
        ax.set_ylim(0.0, 10.0)
        figure_layout.legend_and_fit(fig, ax, [(0.0, 0.0, 1.0)], fit=True, freeze=freeze)
        assert (fig.get_layout_engine() is None) == freeze
        figure_layout.png_bytes(fig)
        assert len(calls) == (2 if freeze else 3)
        sizes.append(tuple(fig.get_size_inches()))
    assert sizes[0] == sizes[1]  # the same fit either way
