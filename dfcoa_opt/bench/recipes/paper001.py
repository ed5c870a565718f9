"""Figure recipes of paper 001: Table I (Figs 5-6) and Table II (Fig. 8).

``paper001_ivo`` runs the ORCA navigator (``orca_nav``) on the Table I crossing
with the static obstacles handled three ways: RVO2's obstacle lines
(``obstacles = "orca"``, the paper's "conventional ORCA"), the paper's
improved VO (``"ivo"``) and none (reference). ``paper001_consensus`` runs the
consensus protocol with the IVO term (``consensus_ivo``, eq 15, both readings
of eq 17) and without it (``consensus``, eq 14) on the Table II formation.
Each table puts what the paper reports beside what we measured; the figures
have the paper's panels. Layouts and choices: docs/reproduction.md.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.patches import Circle as CirclePatch

from dfcoa_opt import metrics
from dfcoa_opt.bench.recipes import Artefact, recipe
from dfcoa_opt.bench.report.plots import ok_runs, scenario_for_row
from dfcoa_opt.bench.results.store import ResultsStore
from dfcoa_opt.core.atomic import atomic_write
from dfcoa_opt.metrics.robots import leader_follower_position_error
from dfcoa_opt.sim.log import RunLog
from dfcoa_opt.viz import plotting
from dfcoa_opt.viz.layout import save_png

#: A robot has reached its target within this distance, m.
REACH_TOL = 0.1
#: What paper 001 reports for each obstacle mode of Table I (Figs 5-6).
PAPER_TABLE1 = {
    "orca": "clear of obstacles, but does not get around them or reach the target (Fig. 5)",
    "ivo": "reaches both targets; robot-obstacle and robot-robot distances > 0 (Fig. 6)",
    "none": "-",
}
#: What paper 001 reports for the Table II formation (Fig. 8).
PAPER_TABLE2 = ("robot spacing > 0 throughout (Fig. 8d); velocities converge to the desired one, "
                "with jitter when passing the obstacles (Fig. 8c); formation re-forms after "
                "the obstacle zone and reaches the target (Fig. 8e)")


def _radius(log: RunLog) -> float:
    return float(log.meta["robot_radius"])


def pair_distances(log: RunLog) -> tuple[np.ndarray, list[tuple[int, int]]]:
    """Centre distances ``(T, P)`` of every robot pair, and the pairs."""
    n = log.n_robots
    pairs = [(i, j) for i in range(n) for j in range(i + 1, n)]
    pos = log.pose[..., :2]
    dist = np.stack([np.linalg.norm(pos[:, i] - pos[:, j], axis=1) for i, j in pairs], axis=1)
    return dist, pairs


def run_summary(log: RunLog) -> dict[str, float]:
    """Numbers of one run that both paper-001 tables use.

    Returns:
        ``reached`` (robots within :data:`REACH_TOL` of their target at the
        end), ``t_reach`` (first time all are, s; NaN if never), ``min_obstacle_gap``
        and ``min_robot_gap`` (smallest surface distances, m; negative =
        overlap), ``contacts`` (contact events) and ``infeasible`` (robot-steps
        whose constraints had no common point or whose solver failed).
    """
    err = leader_follower_position_error(log)
    done = np.all(err <= REACH_TOL, axis=1)
    return {"reached": float(np.sum(err[-1] <= REACH_TOL)),
            "t_reach": float(log.t[np.argmax(done)]) if done.any() else float("nan"),
            "min_obstacle_gap": metrics.min_obstacle_clearance(log),
            "min_robot_gap": metrics.min_inter_robot_distance(log) - 2.0 * _radius(log),
            "contacts": float(np.sum(log.collision_events)),
            "infeasible": float(metrics.filter_counts(log)["filter_fallbacks"])}


def _num(value: float, fmt: str = "{:.2f}") -> str:
    return "—" if not np.isfinite(value) else fmt.format(value)


def _trajectories(ax, log: RunLog, row: dict[str, Any], title: str) -> None:
    """Map, exact obstacle outlines, trajectories, starts and targets."""
    sc = scenario_for_row(row)
    plotting.draw_world(ax, sc.world.grid, shapes=sc.world.shapes)
    colors = plotting.robot_colors(log.n_robots)
    r = _radius(log)
    for i, color in enumerate(colors):
        ax.plot(log.pose[:, i, 0], log.pose[:, i, 1], color=color, lw=1.5, label=f"robot {i + 1}")
        ax.plot(*log.pose[0, i, :2], "o", color=color, ms=4)
        ax.plot(*log.slots[-1, i], "x", color=color, ms=8)
        ax.add_patch(CirclePatch(log.pose[-1, i, :2], r, fill=False, edgecolor=color))
    ax.set_title(title)
    ax.legend(fontsize="small", loc="lower right")


def _gap_panels(axes, log: RunLog) -> None:
    """Smallest robot-obstacle gap per robot and robot-robot gap per pair over time."""
    r = _radius(log)
    colors = plotting.robot_colors(log.n_robots)
    for i, color in enumerate(colors):
        axes[0].plot(log.t, log.clearance[:, i] - r, color=color, lw=1, label=f"robot {i + 1}")
    axes[0].set_ylabel("obstacle gap (m)")
    if log.n_robots > 1:
        dist, pairs = pair_distances(log)
        for k, (i, j) in enumerate(pairs):
            axes[1].plot(log.t, dist[:, k] - 2 * r, lw=1, label=f"{i + 1}-{j + 1}")
    axes[1].set_ylabel("robot gap (m)")
    for ax in axes:
        ax.axhline(0.0, color="red", lw=0.8, ls="--")
        ax.grid(alpha=0.3)
        ax.legend(fontsize="small")
    axes[-1].set_xlabel("t (s)")


def _fig_table1(log: RunLog, row: dict[str, Any], path: Path, title: str) -> Path:
    """Figs 5-6: (a) trajectories, (b) obstacle gap, (c) robot-robot gap."""
    fig = plotting.new_figure((12.0, 5.5))
    grid = fig.add_gridspec(2, 2, width_ratios=(1.6, 1.0))
    _trajectories(fig.add_subplot(grid[:, 0]), log, row, f"(a) {title}")
    ax_b = fig.add_subplot(grid[0, 1])
    ax_c = fig.add_subplot(grid[1, 1], sharex=ax_b)
    _gap_panels([ax_b, ax_c], log)
    ax_b.set_title("(b) robot-obstacle surface distance")
    ax_c.set_title("(c) robot-robot surface distance")
    return save_png(fig, path)


@recipe("paper001_ivo", title="Paper 001: Table I crossing, ORCA vs improved VO (Figs 5-6)",
        sweep="sweeps/paper001_ivo.toml", budget=15)
def render_ivo(store: ResultsStore, dest: Path) -> list[Artefact]:
    """``table1.md`` and one Figs 5-6 like figure per obstacle mode (first seed)."""
    runs = ok_runs(store)
    lines = ["# Paper 001, Table I: two robots crossing a polygon field", "",
             "`orca_nav` (preferred velocity: full speed towards the target) with the static "
             "obstacles handled by RVO2's obstacle lines (`orca`, the paper's conventional "
             "ORCA), by the paper's improved VO (`ivo`) or not at all (`none`). Targets reached "
             f"within {REACH_TOL} m; gaps are surface distances (negative = overlap). Field "
             "layout: docs/reproduction.md.", "",
             "| obstacles | seed | paper | targets reached | time (s) | min obstacle gap (m) "
             "| min robot gap (m) | contacts | infeasible solves |",
             "|---|---|---|---|---|---|---|---|---|"]
    arts = [Artefact("table1.md", "paper 001 Table I, Figs 5-6", "outcome per obstacle mode")]
    drawn = set()
    for row, log in runs:
        mode = str((row.get("overrides") or {}).get("controllers.orca_nav.obstacles", "orca"))
        s = run_summary(log)
        lines.append(f"| {mode} | {row['seed']} | {PAPER_TABLE1.get(mode, '-')} | "
                     f"{int(s['reached'])}/{log.n_robots} | {_num(s['t_reach'])} | "
                     f"{_num(s['min_obstacle_gap'], '{:.3f}')} | "
                     f"{_num(s['min_robot_gap'], '{:.3f}')} | {int(s['contacts'])} | "
                     f"{int(s['infeasible'])} |")
        if mode not in drawn:
            drawn.add(mode)
            name = f"fig_{mode}.png"
            fig_no = {"orca": "paper 001 Fig. 5", "ivo": "paper 001 Fig. 6"}.get(mode, "-")
            _fig_table1(log, row, dest / name, f"obstacles = {mode!r}")
            arts.append(Artefact(name, fig_no, f"trajectories and distances, obstacles={mode}"))
    atomic_write(dest / "table1.md", "\n".join(lines) + "\n")
    return arts


def _variant(row: dict[str, Any]) -> tuple[str, str]:
    """(label, file tag) of a Table II run: controller, eq-17 law, next-step filter, speed."""
    ov = row.get("overrides") or {}
    law = ov.get("controllers.consensus_ivo.pref_law")
    safe = bool(ov.get("controllers.consensus_ivo.safe_discrete"))
    v_max = ov.get("robots.v_max")
    options = [f"pref_law={law}"] * bool(law) + ["safe_discrete"] * safe
    label = row["controller"] + (f" ({', '.join(options)})" if options else "")
    tag = row["controller"] + (f"_{law}" if law else "") + ("_safe" if safe else "")
    if v_max is not None:
        tag += f"_vmax{float(v_max):.2f}"
    return label, tag


def leader_arrival(log: RunLog) -> int:
    """Index of the first step at which the leader stands at its goal (last step if never)."""
    stopped = (log.leader[:, 3] == 0.0) & (np.arange(log.n_steps) > 0)
    return int(np.argmax(stopped)) if stopped.any() else log.n_steps - 1


def velocity_jitter(log: RunLog) -> float:
    """RMS step-to-step change of the robots' velocity, m/s (Fig. 8c's "jitter")."""
    return float(np.sqrt(np.mean(np.diff(log.velocity, axis=0) ** 2)))


def _fig8(log: RunLog, row: dict[str, Any], path: Path, title: str) -> Path:
    """Fig. 8 like panels: trajectories, velocity components, distances, formation error."""
    fig = plotting.new_figure((13.0, 9.0))
    grid = fig.add_gridspec(4, 2, width_ratios=(1.2, 1.0))
    _trajectories(fig.add_subplot(grid[:2, 0]), log, row, f"(a) {title}")
    lead_v = log.leader[:, 3:4] * np.stack((np.cos(log.leader[:, 2]),
                                            np.sin(log.leader[:, 2])), axis=1)
    colors = plotting.robot_colors(log.n_robots)
    axes = [fig.add_subplot(grid[k, 1]) for k in range(4)]
    for c, lab in enumerate(("v_x (m/s)", "v_y (m/s)")):
        ax = axes[c]
        for i, color in enumerate(colors):
            ax.plot(log.t, log.velocity[:, i, c], color=color, lw=0.8, label=f"robot {i + 1}")
        ax.plot(log.t, lead_v[:, c], "k--", lw=1, label="leader")
        ax.set_ylabel(lab)
        ax.grid(alpha=0.3)
    axes[0].set_title("(c) velocity components")
    axes[0].legend(fontsize="small", ncol=4)
    err = leader_follower_position_error(log)
    for i, color in enumerate(colors):
        axes[2].plot(log.t, err[:, i], color=color, lw=1)
    axes[2].set_ylabel("|x_i - x_L - Δ_i| (m)")
    axes[2].set_title("(b) formation error")
    axes[2].grid(alpha=0.3)
    dist, pairs = pair_distances(log)
    for k, (i, j) in enumerate(pairs):
        axes[3].plot(log.t, dist[:, k], lw=1, label=f"{i + 1}-{j + 1}")
    axes[3].axhline(2 * _radius(log), color="red", lw=0.8, ls="--", label="contact")
    axes[3].set_ylabel("distance (m)")
    axes[3].set_title("(d) inter-robot distances")
    axes[3].legend(fontsize="small", ncol=4)
    axes[3].grid(alpha=0.3)
    axes[3].set_xlabel("t (s)")
    ax_e = fig.add_subplot(grid[2:, 0])
    r = _radius(log)
    for i, color in enumerate(colors):
        ax_e.plot(log.t, log.clearance[:, i] - r, color=color, lw=1, label=f"robot {i + 1}")
    ax_e.axhline(0.0, color="red", lw=0.8, ls="--")
    ax_e.set_ylabel("robot-obstacle gap (m)")
    ax_e.set_xlabel("t (s)")
    ax_e.set_title("(e) distance to the obstacles")
    ax_e.grid(alpha=0.3)
    return save_png(fig, path)


@recipe("paper001_consensus", title="Paper 001: Table II consensus formation (Fig. 8)",
        sweep="sweeps/paper001_consensus.toml", budget=45)
def render_consensus(store: ResultsStore, dest: Path) -> list[Artefact]:
    """``table2.md`` and one Fig. 8 like figure per controller variant (first seed)."""
    runs = sorted(ok_runs(store), key=lambda rl: (*_variant(rl[0]), rl[0]["seed"]))
    lines = ["# Paper 001, Table II: consensus formation through a polygon field", "",
             f"Paper (one run, words only): {PAPER_TABLE2}.", "",
             "Formation error = |x_i − x_L − Δ_i| (eq 3-4 with the virtual leader); final = at "
             "the end of the run; velocity jitter = RMS change of a robot's velocity per "
             "step. Layout and readings of eq 15-17: docs/reproduction.md, "
             "docs/methods/consensus.md.", "",
             "| controller | v_max (m/s) | seed | RMS formation error (m) | max formation error "
             "when the leader stops (m) | all slots within 0.1 m at (s) | min obstacle gap (m) | "
             "min robot gap (m) | contacts | infeasible solves | velocity jitter (m/s) |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    arts = [Artefact("table2.md", "paper 001 Table II, Fig. 8", "outcome per controller")]
    drawn = set()
    for row, log in runs:
        s = run_summary(log)
        err = leader_follower_position_error(log)
        name, tag = _variant(row)
        v_max = float((row.get("overrides") or {}).get("robots.v_max",
                                                       scenario_for_row(row).spec.robots.v_max))
        lines.append(f"| {name} | {v_max:.3f} | {row['seed']} | "
                     f"{float(np.sqrt(np.mean(err**2))):.3f} | "
                     f"{float(np.max(err[leader_arrival(log)])):.3f} | {_num(s['t_reach'])} | "
                     f"{_num(s['min_obstacle_gap'], '{:.3f}')} | "
                     f"{_num(s['min_robot_gap'], '{:.3f}')} | {int(s['contacts'])} | "
                     f"{int(s['infeasible'])} | {velocity_jitter(log):.4f} |")
        if tag not in drawn:
            drawn.add(tag)
            fname = f"fig8_{tag}.png"
            _fig8(log, row, dest / fname, f"{name}, v_max {v_max:.2f} m/s")
            arts.append(Artefact(fname, "paper 001 Fig. 8",
                                 f"panels of {name}, v_max {v_max:.2f} m/s"))
    atomic_write(dest / "table2.md", "\n".join(lines) + "\n")
    return arts
