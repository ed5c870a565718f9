"""Figure recipe ``astar_comparison``: traditional vs improved A* (paper 000 section 4.1).

No simulation: the planners run directly on the two DFCOA maps (with each
scenario's own start, goal and obstacle inflation) and on :data:`N_RANDOM`
seeded random maps. The table prints the paper's claims (-27 % planning time,
-35 % nodes) beside our measured change; the figure draws both planners'
paths on the DFCOA maps. Times are medians of :data:`REPEATS` runs on this
machine, so they change from run to run; nodes, lengths and clearances do not.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import Any

import numpy as np

from dfcoa_opt.bench.recipes import Artefact, recipe
from dfcoa_opt.core.atomic import atomic_write
from dfcoa_opt.planning.astar import AStarParams, plan
from dfcoa_opt.planning.improved_astar import (
    ImprovedAStarParams,
    Task,
    compare_planners,
    comparison_markdown,
    default_planners,
    random_tasks,
)
from dfcoa_opt.scenario.loader import load_scenario
from dfcoa_opt.viz import plotting
from dfcoa_opt.viz.layout import save_png

#: The DFCOA scenario files whose maps, starts and goals are planned on.
DFCOA_SCENARIOS = ("dfcoa_s1.toml", "dfcoa_s2.toml")
#: Random maps: count, seed, shape (cells, 1 m each), density and kind.
N_RANDOM, RANDOM_SEED, RANDOM_SHAPE, RANDOM_DENSITY = 50, 2026, (64, 64), 0.2
#: Timed runs per (map, planner); the median is reported.
REPEATS = 5


def dfcoa_tasks(scenarios: Path) -> tuple[list[Task], float]:
    """The DFCOA maps as planning tasks, and the scenarios' obstacle inflation (m).

    Both scenario files must use the same inflation (they do: 1.2 m); it is
    applied to every planner so that only the cost function differs.
    """
    tasks, inflations = [], set()
    for name in DFCOA_SCENARIOS:
        sc = load_scenario(scenarios / name)
        lead = sc.spec.leader
        opts = ImprovedAStarParams(**lead.planner_options)
        inflations.add(opts.inflate)
        tasks.append(Task(sc.name, sc.world.grid, tuple(lead.start), tuple(lead.goal)))
    if len(inflations) != 1:
        raise ValueError(f"DFCOA scenarios use different inflations {sorted(inflations)}")
    return tasks, inflations.pop()


def rows_csv(rows: list[dict[str, Any]]) -> str:
    """All comparison rows as CSV text (one row per map and planner)."""
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return buf.getvalue()


def _paths_figure(tasks: list[Task], planners: dict[str, AStarParams], path: Path) -> Path:
    """Every planner's final path on each DFCOA map, side by side."""
    fig = plotting.new_figure((6.0 * len(tasks), 6.5))
    axes = fig.subplots(1, len(tasks), squeeze=False)[0]
    colors = plotting.robot_colors(len(planners))
    for ax, task in zip(axes, tasks, strict=True):
        plotting.draw_world(ax, task.grid, goal=task.goal, start=task.start)
        for color, (name, params) in zip(colors, planners.items(), strict=True):
            res = plan(task.grid, task.start, task.goal, params)
            ax.plot(res.path[:, 0], res.path[:, 1], color=color, lw=1.5,
                    label=f"{name}: {res.length:.1f} m, {res.expanded} nodes")
        ax.set_title(task.name)
        ax.legend(fontsize="small", loc="upper center", bbox_to_anchor=(0.5, -0.1))
    return save_png(fig, path)


@recipe("astar_comparison",
        title="Paper 000 section 4.1: traditional vs improved A* (planning only)", budget=10)
def render_astar(scenarios: Path, dest: Path) -> list[Artefact]:
    """The comparison table (DFCOA maps and random maps), its CSV and the path figure."""
    tasks, inflate = dfcoa_tasks(scenarios)
    planners = default_planners(inflate)
    rows = compare_planners(tasks, planners, REPEATS)
    random = random_tasks(np.random.default_rng(RANDOM_SEED), N_RANDOM, RANDOM_SHAPE,
                          RANDOM_DENSITY, "blocks")
    rand_rows = compare_planners(random, default_planners(), REPEATS)
    parts = ["# Traditional vs improved A* (paper 000, section 4.1 and its ref. [31])", "",
             "The paper claims the improved A* cuts planning time by ~27 % and expanded nodes "
             "by ~35 % against traditional A*. Eq 13 alone (our reading, docs/methods/astar.md) "
             "cannot expand fewer nodes than A* with the same heuristic, and the rows "
             "\"eq 13 only\" say so; the default improved A* adds the flowchart's node "
             "optimisation (join the goal by line of sight), which is what expands fewer "
             "nodes where it does. Times are medians of "
             f"{REPEATS} runs on this machine (they vary between runs); nodes, lengths and "
             "clearances are deterministic. Clearance is to the un-inflated map.", ""]
    for task in tasks:
        parts += [f"## {task.name}: start {task.start} → goal {task.goal}, "
                  f"obstacles inflated by {inflate:g} m", "",
                  comparison_markdown([r for r in rows if r["map"] == task.name]), ""]
    parts += [f"## {N_RANDOM} random maps ({RANDOM_SHAPE[0]}×{RANDOM_SHAPE[1]} cells of 1 m, "
              f"{RANDOM_DENSITY:.0%} blocks, seed {RANDOM_SEED}, no inflation)", "",
              comparison_markdown(rand_rows), ""]
    atomic_write(dest / "astar_comparison.md", "\n".join(parts))
    atomic_write(dest / "astar_comparison.csv", rows_csv(rows + rand_rows))
    _paths_figure(tasks, planners, dest / "astar_paths.png")
    return [Artefact("astar_comparison.md", "paper 000 §4.1 claims (−27 % time, −35 % nodes)",
                     "planning time, nodes, length, clearance; DFCOA maps and random maps"),
            Artefact("astar_comparison.csv", "-", "every (map, planner) row of the table"),
            Artefact("astar_paths.png", "paper 000 Figs 4, 11, 16 (paths only)",
                     "traditional and improved A* paths on the S1 and S2 maps")]
