"""Figure recipes of paper 004: Tables 2-4 and Figs 5-11, virtual-spring formation.

``paper004_tables`` runs the improved model (``virtual_spring``) on the 16
scenarios of ``scenarios/paper004/`` (n = 5, 10, 15, 20 robots with 0-3
dynamic obstacle robots) over 10 seeds, and writes Tables 2-4 with the
paper's values beside ours and the figures of the improved model (Figs 6, 7,
9, 10, 11). ``paper004_baseline`` runs the model "without improvement"
(``virtual_spring_basic``: spring force and consensus only) beside the
improved one for n = 5 (Figs 5 and 8). Errors (docs/reproduction.md, "Paper
004"):

* leader-follower error ``|p_i - p_L - E_i|`` (Figs 7, 10; Table 3), with the
  paper's constant world-frame errors ``E_i`` around the leader robot;
* actual-vs-ideal error ``|p_i - p*_i|`` (eq 14's square root; Fig. 11;
  Table 3), the ideal position being the formation slot around the virtual
  leader, which runs the obstacle-free straight route at ``v_max``.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.patches import Circle as CirclePatch

from dfcoa_opt.bench.recipes import Artefact, recipe
from dfcoa_opt.bench.report.plots import ok_runs, scenario_for_row
from dfcoa_opt.bench.results.store import ResultsStore
from dfcoa_opt.core.atomic import atomic_write
from dfcoa_opt.metrics.robots import (
    collisions_per_robot,
    leader_follower_position_error,
    leader_robot_target_error,
    path_length_per_robot,
)
from dfcoa_opt.sim.log import RunLog
from dfcoa_opt.viz import plotting
from dfcoa_opt.viz.layout import save_png

#: Formation sizes and dynamic-obstacle counts of the sweep.
SIZES = (5, 10, 15, 20)
DYNAMIC = (0, 1, 2, 3)
#: Table 2 (no dynamic obstacles), the paper's 10 runs per n: path lengths (m) of the
#: leader and the average, maximum and minimum of the followers.
PAPER_TABLE2 = {
    5: {"leader": (38.19, 38.19, 38.18, 38.19, 38.18, 38.20, 38.18, 38.19, 38.19, 38.20),
        "avg": (39.56, 39.60, 39.55, 39.56, 39.55, 39.56, 39.59, 39.60, 39.56, 39.55),
        "max": (40.02, 39.99, 40.00, 40.04, 40.01, 40.09, 40.01, 40.01, 40.00, 40.02),
        "min": (39.01, 39.00, 39.02, 39.01, 39.01, 39.06, 39.00, 39.04, 39.06, 39.02)},
    10: {"leader": (38.20, 38.19, 38.21, 38.20, 38.19, 38.21, 38.20, 38.19, 38.20, 38.18),
         "avg": (39.65, 39.66, 39.63, 39.70, 39.66, 39.71, 39.67, 39.68, 39.70, 39.71),
         "max": (41.12, 41.15, 41.13, 41.15, 41.14, 41.13, 41.14, 41.17, 41.16, 41.15),
         "min": (39.33, 39.29, 39.30, 39.31, 39.30, 39.29, 39.31, 39.28, 39.30, 39.29)},
    15: {"leader": (38.21, 38.19, 38.19, 38.20, 38.19, 38.19, 38.20, 38.19, 38.20, 38.19),
         "avg": (39.75, 39.76, 39.80, 39.79, 39.76, 39.80, 39.77, 39.78, 39.80, 39.81),
         "max": (41.22, 41.24, 41.25, 41.26, 41.24, 41.23, 41.24, 41.27, 41.26, 41.25),
         "min": (39.53, 39.23, 39.51, 39.50, 39.50, 39.49, 39.52, 39.49, 39.50, 39.49)},
    20: {"leader": (38.20, 39.19, 39.21, 39.20, 39.19, 39.18, 39.19, 39.21, 39.20, 39.21),
         "avg": (40.55, 40.56, 40.56, 40.59, 40.56, 40.57, 40.57, 40.58, 40.60, 40.61),
         "max": (42.02, 42.01, 42.02, 42.00, 42.03, 41.96, 41.94, 42.03, 42.06, 41.97),
         "min": (40.41, 40.38, 40.41, 40.35, 40.36, 40.39, 40.32, 40.39, 40.40, 40.39)},
}
#: Table 3 (dynamic obstacles): max leader-follower error, max actual-vs-ideal error, m,
#: and the sum of the path lengths, m.
PAPER_TABLE3 = {5: (1.65, 0.21, 198.38), 10: (3.05, 0.55, 399.28), 15: (4.07, 0.63, 598.12),
                20: (6.52, 0.64, 827.66)}
#: Table 4: per n and row, path lengths (m) with 0, 1, 2, 3 obstacle robots.
PAPER_TABLE4 = {
    5: {"leader": (38.19, 38.28, 38.42, 38.53), "avg": (39.57, 39.78, 39.99, 40.30),
        "max": (40.02, 41.10, 41.55, 41.87), "min": (39.02, 39.12, 39.18, 39.22)},
    10: {"leader": (38.20, 38.56, 38.83, 39.05), "avg": (39.65, 39.85, 40.05, 40.40),
         "max": (41.12, 41.32, 41.54, 41.82), "min": (39.33, 39.45, 39.50, 39.63)},
    15: {"leader": (38.20, 38.55, 38.82, 39.03), "avg": (39.57, 39.75, 39.95, 40.30),
         "max": (41.23, 41.50, 41.75, 41.85), "min": (39.52, 39.85, 40.01, 40.33)},
    20: {"leader": (38.20, 38.82, 39.16, 39.28), "avg": (40.55, 41.95, 42.70, 43.36),
         "max": (42.02, 43.93, 44.85, 45.15), "min": (40.41, 40.55, 40.71, 40.93)},
}
ROW_LABELS = {"leader": "Leader", "avg": "Average of followers", "max": "Maximum of followers",
              "min": "Minimum of followers"}
_NAME = re.compile(r"^vs_n(\d+)_dyn(\d+)$")


def frame_heading(log: RunLog) -> float:
    """Heading of the frame of the paper's constant errors E_i: the virtual leader's start, rad."""
    return float(log.leader[0, 2])


def run_numbers(log: RunLog) -> dict[str, float]:
    """Tables 2-4's numbers of one run (robot 0 = the leader robot).

    Returns:
        ``leader``, ``avg``, ``max``, ``min`` (path lengths of the leader and
        of the followers, m), ``sum`` (all robots, m), ``lf_max`` (largest
        leader-follower error, m), ``lf_start`` (the largest at t = 0: Table
        1's starts are up to 4.9 m off the formation), ``ideal_max`` (largest
        actual-vs-ideal error, m), ``collisions`` (contact onsets, robots
        summed).
    """
    length = path_length_per_robot(log)
    fol = length[1:]
    lf = leader_robot_target_error(log, frame_heading=frame_heading(log))[:, 1:]
    ideal = leader_follower_position_error(log)
    return {"leader": float(length[0]), "avg": float(fol.mean()), "max": float(fol.max()),
            "min": float(fol.min()), "sum": float(length.sum()), "lf_max": float(lf.max()),
            "lf_start": float(lf[0].max()),
            "ideal_max": float(ideal.max()),
            "collisions": float(collisions_per_robot(log).sum())}


Runs = list[tuple[dict[str, Any], RunLog]]


def _group(store: ResultsStore, controller: str) -> dict[tuple[int, int], Runs]:
    """Successful runs of one controller by (n, dynamic obstacles), in seed order."""
    out: dict[tuple[int, int], Runs] = {}
    for row, log in ok_runs(store):
        m = _NAME.match(str(row["scenario"]))
        if m and row["controller"] == controller:
            out.setdefault((int(m.group(1)), int(m.group(2))), []).append((row, log))
    for runs in out.values():
        runs.sort(key=lambda rl: rl[0]["seed"])
    return out


def _spread(values: list[float], fmt: str = "{:.2f}") -> str:
    """``mean [min, max]`` of a list (one value: the value)."""
    a = np.asarray(values, dtype=float)
    if a.size == 0:
        return "—"
    if a.size == 1:
        return fmt.format(a[0])
    return f"{fmt.format(a.mean())} [{fmt.format(a.min())}, {fmt.format(a.max())}]"


def _tables(groups: dict[tuple[int, int], Runs], dest: Path) -> Path:
    """tables.md: Tables 2, 3 and 4, the paper's value beside ours."""
    nums = {key: [run_numbers(log) for _, log in runs] for key, runs in groups.items()}
    lines = ["# Paper 004, Tables 2-4: virtual-spring formation (`virtual_spring`)", "",
             "Scenarios `scenarios/paper004/vs_n{n}_dyn{k}.toml` (Table 1; what the paper does "
             "not give: docs/reproduction.md, \"Paper 004\"). Ours: mean [min, max] over the "
             "seeds, which vary the starts by σ = 0.02 m. Path length = length of the logged "
             "trajectory, m.", "",
             "## Table 2: path lengths without dynamic obstacles", "",
             "| n | robot | paper (10 runs) | ours | runs |", "|---|---|---|---|---|"]
    for n in SIZES:
        runs = nums.get((n, 0), [])
        for key, label in ROW_LABELS.items():
            lines.append(f"| {n} | {label} | {_spread(list(PAPER_TABLE2[n][key]))} | "
                         f"{_spread([r[key] for r in runs])} | {len(runs)} |")
    lines += ["", "## Table 3: with the three dynamic obstacle robots", "",
              "Maximum over time, followers (and, for the ideal error, every robot) of one run; "
              "ours: mean [min, max] of that maximum over the seeds.", "",
              "| n | max leader-follower error, paper (m) | ours | ours at t = 0 | max "
              "actual-vs-ideal error, paper (m) | ours | sum of path lengths, paper (m) | ours | "
              "collisions (ours) |", "|---|---|---|---|---|---|---|---|---|"]
    for n in SIZES:
        runs = nums.get((n, 3), [])
        p = PAPER_TABLE3[n]
        ours = {key: _spread([r[key] for r in runs])
                for key in ("lf_max", "lf_start", "ideal_max", "sum")}
        lines.append(f"| {n} | {p[0]:.2f} | {ours['lf_max']} | {ours['lf_start']} | "
                     f"{p[1]:.2f} | {ours['ideal_max']} | {p[2]:.2f} | {ours['sum']} | "
                     f"{_spread([r['collisions'] for r in runs], '{:.1f}')} |")
    lines += ["", "## Table 4: path lengths with 0-3 dynamic obstacle robots (mean over runs)", "",
              "| n | robot | " + " | ".join(f"{k} obstacle robots paper | ours" for k in DYNAMIC)
              + " |", "|---|---|" + "---|---|" * len(DYNAMIC)]
    for n in SIZES:
        for key, label in ROW_LABELS.items():
            cells = []
            for k in DYNAMIC:
                runs = nums.get((n, k), [])
                ours = f"{np.mean([r[key] for r in runs]):.2f}" if runs else "—"
                cells.append(f"{PAPER_TABLE4[n][key][k]:.2f} | {ours}")
            lines.append(f"| {n} | {label} | " + " | ".join(cells) + " |")
    return atomic_write(dest / "tables.md", "\n".join(lines) + "\n")


def _trajectories(ax, log: RunLog, row: dict[str, Any], title: str) -> None:
    """Static dots, dynamic obstacle paths, robot trajectories."""
    sc = scenario_for_row(row)
    plotting.draw_world(ax, sc.world.grid, shapes=sc.world.shapes)
    colors = plotting.robot_colors(log.n_robots)
    for i, color in enumerate(colors):
        ax.plot(log.pose[:, i, 0], log.pose[:, i, 1], color=color, lw=1.0 if i else 2.0,
                label="leader" if i == 0 else None)
    for k in range(log.dyn_pos.shape[1]):
        ax.plot(log.dyn_pos[:, k, 0], log.dyn_pos[:, k, 1], "r--", lw=1,
                label="obstacle robots" if k == 0 else None)
        ax.add_patch(CirclePatch(log.dyn_pos[-1, k], 0.3, color="red", alpha=0.4))
    ax.set_title(title, fontsize="medium")
    ax.legend(fontsize="small", loc="lower right")


def _errors(ax, t: np.ndarray, err: np.ndarray, title: str, first: int) -> None:
    """One line per robot (columns from ``first``)."""
    colors = plotting.robot_colors(err.shape[1])
    for i in range(first, err.shape[1]):
        ax.plot(t, err[:, i], color=colors[i], lw=0.8)
    ax.set_title(title, fontsize="medium")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("error (m)")
    ax.grid(alpha=0.3)


def _four_panels(groups: dict[tuple[int, int], Runs], k: int, dest: Path, name: str,
                 what: str) -> Path:
    """One panel per formation size (first seed): trajectories, or an error over time."""
    fig = plotting.new_figure((12.0, 10.0))
    axes = fig.subplots(2, 2).ravel()
    for ax, n in zip(axes, SIZES, strict=True):
        runs = groups.get((n, k), [])
        if not runs:
            ax.set_title(f"n = {n}: no run")
            continue
        row, log = runs[0]
        if what == "trajectories":
            _trajectories(ax, log, row, f"n = {n}")
        elif what == "lf":
            _errors(ax, log.t, leader_robot_target_error(log, frame_heading=frame_heading(log)),
                    f"n = {n}: |p_i - p_L - E_i|", 1)
        else:
            _errors(ax, log.t, leader_follower_position_error(log),
                    f"n = {n}: actual vs ideal position", 0)
    return save_png(fig, dest / name)


@recipe("paper004_tables", title="Paper 004: Tables 2-4 and Figs 6, 7, 9-11, virtual-spring "
                                 "formation", sweep="sweeps/paper004.toml", budget=70)
def render_tables(store: ResultsStore, dest: Path) -> list[Artefact]:
    """``tables.md`` and the improved model's figures (first seed of each setting)."""
    groups = _group(store, "virtual_spring")
    _tables(groups, dest)
    figs = (("fig6_trajectories_static.png", 0, "trajectories", "paper 004 Fig. 6"),
            ("fig7_lf_error_static.png", 0, "lf", "paper 004 Fig. 7"),
            ("fig9_trajectories_dynamic.png", 3, "trajectories", "paper 004 Fig. 9"),
            ("fig10_lf_error_dynamic.png", 3, "lf", "paper 004 Fig. 10"),
            ("fig11_ideal_error_dynamic.png", 3, "ideal", "paper 004 Fig. 11"))
    arts = [Artefact("tables.md", "paper 004 Tables 2-4", "path lengths and errors")]
    for name, k, what, paper in figs:
        _four_panels(groups, k, dest, name, what)
        arts.append(Artefact(name, paper, f"n = 5, 10, 15, 20; {k} obstacle robots; {what}"))
    return arts


@recipe("paper004_baseline", title="Paper 004: the model without improvement (Figs 5 and 8)",
        sweep="sweeps/paper004_baseline.toml", budget=15)
def render_baseline(store: ResultsStore, dest: Path) -> list[Artefact]:
    """Figs 5 and 8 (trajectories, both errors) and a basic-vs-improved table, n = 5."""
    lines = ["# Paper 004: without improvement (Figs 5, 8) against the improved model, n = 5",
             "", "`virtual_spring_basic` = spring force and consensus only (no dynamic speed "
             "limit, no conflict resolution). Ours: mean [min, max] over the seeds. The paper "
             "gives, for the unimproved model, a maximum leader-follower error of 11.3 m "
             "(Fig. 5b, static) and 8.3 m (Fig. 8c, dynamic), and for the improved one 2.3 m "
             "(Fig. 7a) and 1.65 m (Table 3).", "",
             "| model | obstacle robots | paper max leader-follower error (m) | ours | ours at "
             "t = 0 | max actual-vs-ideal error (m) | leader path (m) | collisions |",
             "|---|---|---|---|---|---|---|---|"]
    paper = {("virtual_spring_basic", 0): "11.3", ("virtual_spring_basic", 3): "8.3",
             ("virtual_spring", 0): "2.3", ("virtual_spring", 3): "1.65"}
    arts = [Artefact("baseline.md", "paper 004 Figs 5, 7a, 8, 10a", "max errors, n = 5")]
    for cid in ("virtual_spring_basic", "virtual_spring"):
        groups = _group(store, cid)
        for k in (0, 3):
            runs = groups.get((5, k), [])
            nums = [run_numbers(log) for _, log in runs]
            lines.append(f"| {cid} | {k} | {paper[cid, k]} | "
                         f"{_spread([r['lf_max'] for r in nums])} | "
                         f"{_spread([r['lf_start'] for r in nums])} | "
                         f"{_spread([r['ideal_max'] for r in nums])} | "
                         f"{_spread([r['leader'] for r in nums])} | "
                         f"{_spread([r['collisions'] for r in nums], '{:.1f}')} |")
            if cid != "virtual_spring_basic" or not runs:
                continue
            row, log = runs[0]
            fig = plotting.new_figure((15.0, 4.8))
            ax = fig.subplots(1, 3)
            _trajectories(ax[0], log, row, "(a) trajectories")
            _errors(ax[1], log.t, leader_robot_target_error(
                log, frame_heading=frame_heading(log)), "(b) |p_i - p_L - E_i|", 1)
            _errors(ax[2], log.t, leader_follower_position_error(log),
                    "(c) actual vs ideal position", 0)
            fname = "fig5_basic_static.png" if k == 0 else "fig8_basic_dynamic.png"
            save_png(fig, dest / fname)
            arts.append(Artefact(fname, "paper 004 Fig. 5" if k == 0 else "paper 004 Fig. 8",
                                 f"without improvement, n = 5, {k} obstacle robots"))
    atomic_write(dest / "baseline.md", "\n".join(lines) + "\n")
    return arts
