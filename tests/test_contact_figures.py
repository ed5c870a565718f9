"""Contacts and outcomes in the single-run figures: who touched what, the marks, the titles."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from matplotlib.colors import to_rgb
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Circle as CirclePatch
from PIL import Image
from test_plotting import make_grid, make_log

from dfcoa_opt.metrics import contacts, outcome
from dfcoa_opt.scenario.schema import MetricSpec
from dfcoa_opt.sim.log import RunLog
from dfcoa_opt.viz import animation, layout, plotting
from dfcoa_opt.world.grid import OccupancyGrid

K = 10  # the step of the first contact


def bumping_log() -> RunLog:
    """The test_plotting run, with robot 1 dropping next to robot 0 (0.4 m < 2 x 0.3 m) at K."""
    log = make_log()
    log.clearance[:] = 5.0  # clear of the map (make_log's zeros would all be contacts)
    log.pose[K:, 1, 1] = log.pose[K:, 0, 1] + 0.4
    log.robot_contacts[K:] = 1
    log.collision_events[K] = 1
    return log


def _marks(fig: Figure) -> tuple[list[Line2D], list[CirclePatch]]:
    """The contact markers (``X`` lines) and the red rings of a figure's map."""
    ax = fig.axes[0]
    xs = [ln for ln in ax.lines if ln.get_marker() == "X"]
    red = np.asarray(to_rgb(plotting.CONTACT_COLOR))
    rings = [p for p in ax.patches if isinstance(p, CirclePatch) and not p.get_fill()
             and np.allclose(p.get_edgecolor()[:3], red)]
    return xs, rings


def _legend_texts(fig: Figure) -> list[str]:
    return [t.get_text() for leg in fig.legends for t in leg.get_texts()]


# ------------------------------------------------------------------ who touched what
def test_contacts_name_the_pair_the_obstacle_and_the_moving_disc_with_their_points() -> None:
    log = bumping_log()
    (c,) = contacts.contacts_at(log, K)
    x = log.pose[K, 0, 0]
    assert (c.kind, c.robot, c.other) == ("robot", 0, 1)
    assert np.allclose(c.point, (x, 3.2))  # halfway between the centres
    assert contacts.first_contact_step(log) == K
    assert contacts.describe([c]) == "robot 0 and robot 1"
    # robot 2 (y = 7) against the block of cells x, y in [12, 16), 0.25 m under it
    log.pose[K, 2, :2] = (13.0, 11.75)
    log.clearance[K, 2] = 0.25
    log.obstacle_contacts[K] = 1
    found = contacts.contacts_at(log, K, make_grid())
    assert [(c.kind, c.robot) for c in found] == [("robot", 0), ("obstacle", 2)]
    assert np.allclose(found[1].point, (13.0, 12.0))  # on the block's lower edge
    assert np.allclose(contacts.contacts_at(log, K)[1].point, (13.0, 11.75))  # no map: centre
    assert contacts.describe(found) == "robot 0 and robot 1, robot 2 and a static obstacle"
    # the moving disc (r = 0.4) over robot 0: 0.5 m < 0.3 + 0.4
    log.dyn_pos[K, 0] = log.pose[K, 0, :2] + (0.0, -0.5)
    found = contacts.contacts_at(log, K, make_grid())
    assert found[-1].describe() == "robot 0 and moving obstacle 0"
    assert np.allclose(found[-1].point, log.pose[K, 0, :2] + (0.0, -0.5 * 0.3 / 0.7))
    assert contacts.describe(found) == "robot 0 and robot 1, robot 2 and a static obstacle, +1 more"


def test_a_counted_contact_the_positions_do_not_show_goes_to_the_nearest_candidate() -> None:
    log = make_log()
    log.clearance[:] = 5.0
    assert contacts.contacts_at(log, K) == []  # nothing counted, nothing seen
    log.obstacle_contacts[K] = 1  # every clearance above the 0.3 m radius: robot 1 is nearest
    log.clearance[K] = (0.9, 0.5, 0.8)
    log.robot_contacts[K] = 1  # robots 2 m apart: the nearest pair is 0-1 (equal gaps: first)
    found = contacts.contacts_at(log, K)
    assert [(c.kind, c.robot, c.other) for c in found] == [("robot", 0, 1), ("obstacle", 1, -1)]


# ------------------------------------------------------------------ the run figure
def test_run_figure_marks_the_first_contact_and_titles_the_outcome_with_its_time() -> None:
    log = bumping_log()
    fig = plotting.run_figure(log, make_grid(), dpi=40)
    title = fig.axes[0].get_title()
    assert "unit - dfcoa - seed 7" in title
    assert "collision at t = 1.00 s (robot 0 and robot 1)" in title.replace("\n", " ")
    (mark,), rings = _marks(fig)
    assert np.allclose(np.column_stack(mark.get_data()), [(log.pose[K, 0, 0], 3.2)])
    assert sorted(tuple(np.round(r.center, 6)) for r in rings) == sorted(
        tuple(np.round(log.pose[K, i, :2], 6)) for i in (0, 1))  # both robots, where they met
    assert {"contact", "in contact"} <= set(_legend_texts(fig))
    assert mark.get_zorder() > max(ln.get_zorder() for ln in fig.axes[0].lines if ln is not mark)


def test_run_figure_without_contact_has_no_mark_and_names_its_outcome() -> None:
    log = make_log()
    fig = plotting.run_figure(log, make_grid(), dpi=40)
    assert _marks(fig) == ([], [])
    assert fig.axes[0].get_title().endswith("\ntimeout")
    assert "contact" not in _legend_texts(fig)
    log.meta["reached_goal"] = True
    assert plotting.run_figure(log, make_grid(), dpi=40).axes[0].get_title().endswith("success")


def test_the_title_is_the_outcome_code_s_with_the_scenario_s_metric_settings() -> None:
    log = make_log()
    log.pose[:] = log.pose[:1]  # nobody moves: stalled after any window shorter than the run
    log.leader[:] = log.leader[:1]
    short = MetricSpec(deadlock_window=0.5)
    end = outcome.classify(log, short)
    assert end["outcome"] == "deadlock"
    want = outcome.outcome_text(end["outcome"], end["first_contact_time"], end["deadlock_time"])
    assert want == "deadlock from t = 0.00 s"
    fig = plotting.run_figure(log, make_grid(), dpi=40, metrics=short)
    assert fig.axes[0].get_title().endswith(f"\n{want}")
    assert plotting.run_figure(log, make_grid(), dpi=40).axes[0].get_title().endswith(
        "\ntimeout")  # the default 10 s window is longer than the 2.9 s run


def test_every_robot_line_is_drawn_above_the_leader_s_path() -> None:
    fig = plotting.run_figure(make_log(), make_grid(), dpi=40)
    lines = {ln.get_label(): ln for ln in fig.axes[0].lines}
    robots = [lines[f"robot {i}"] for i in range(3)]
    assert lines["leader"].get_zorder() < min(ln.get_zorder() for ln in robots)
    anim = animation._RunAnimation(make_log(), make_grid(), None, None, (), None, 40.0)
    assert anim.lead_trail.get_zorder() < min(ln.get_zorder() for ln in anim.trails)


def test_a_long_title_is_wrapped_to_the_figure() -> None:
    log = bumping_log()
    log.meta["scenario"] = "a_scenario_with_a_rather_long_name"
    fig = plotting.run_figure(log, make_grid(), figsize=(5.0, 4.0), dpi=50)
    layout.png_bytes(fig)
    box = fig.axes[0].title.get_window_extent(fig.canvas.get_renderer())
    assert box.x0 >= 0 and box.x1 <= fig.bbox.x1 and box.y1 <= fig.bbox.y1
    assert len(fig.axes[0].get_title().split("\n")) >= 3


# ------------------------------------------------------------------ the animation
def _red_pixels(frame: Image.Image) -> int:
    rgb = np.asarray(frame.convert("RGB"), dtype=int)
    want = np.asarray(to_rgb(plotting.CONTACT_COLOR)) * 255
    return int((np.abs(rgb - want) < 25).all(-1).sum())


def test_gif_marks_the_contact_from_its_frame_on_and_titles_the_outcome(tmp_path: Path) -> None:
    log = bumping_log()
    figs: list[Figure] = []
    out = animation.animate_run(log, make_grid(), tmp_path / "a.gif", dpi=40, figure=figs)
    fig = figs[0]
    title = fig.axes[0].get_title()
    assert "collision at t = 1.00 s (robot 0 and robot 1)" in title.replace("\n", " ")
    assert title.endswith(f"t = {log.t[-1]:.2f} s (step {len(log.t) - 1})")
    legend = {t.get_text(): h for h, t in zip(fig.legends[0].legend_handles,
                                               fig.legends[0].get_texts(), strict=True)}
    assert legend["contact"].get_visible() and legend["in contact"].get_visible()
    with Image.open(out) as im:
        red = []
        for k in range(im.n_frames):
            im.seek(k)
            red.append(_red_pixels(im))
    before, after = red[:K], red[K:]
    assert max(before) == min(before) and min(after) > max(before) + 20, red
    anim = animation._RunAnimation(log, make_grid(), None, None, (), None, 40.0)
    anim.show(K - 1)
    assert anim.contact_marks and not any(a.get_visible() for a in anim.contact_marks)
    anim.show(K)
    assert all(a.get_visible() for a in anim.contact_marks)


@pytest.mark.parametrize("n_robots", [3, 12])
def test_gif_without_contact_has_no_marks(tmp_path: Path, n_robots: int) -> None:
    figs: list[Figure] = []
    animation.animate_run(make_log(n_steps=5, n_robots=n_robots), make_grid(),
                          tmp_path / "a.gif", dpi=30, figure=figs)
    assert "timeout" in figs[0].axes[0].get_title()
    assert "contact" not in _legend_texts(figs[0])


def test_static_contact_is_marked_on_the_obstacle() -> None:
    free = OccupancyGrid(np.zeros((20, 20), dtype=bool), resolution=1.0)
    log = make_log()
    log.clearance[:] = 5.0
    log.clearance[K:, 2] = 0.1  # robot 2 grazes the map's block from K on
    log.pose[K:, 2, :2] = (14.0, 11.9)
    log.obstacle_contacts[K:] = 1
    fig = plotting.run_figure(log, make_grid(), dpi=40)
    (mark,), rings = _marks(fig)
    assert np.allclose(np.column_stack(mark.get_data()), [(14.0, 12.0)])
    assert len(rings) == 1 and np.allclose(rings[0].center, (14.0, 11.9))
    assert "robot 2 and a static obstacle" in fig.axes[0].get_title().replace("\n", " ")
    assert contacts.contacts_at(log, K, free)[0].point == (14.0, 11.9)  # free map: the centre
