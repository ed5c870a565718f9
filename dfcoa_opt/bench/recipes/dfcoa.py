"""Figure recipe ``dfcoa_paper``: paper 000 Table 5 and Figs 11-20 like panels.

The sweep (``scenarios/sweeps/dfcoa_paper.toml``) runs the ``dfcoa`` controller
on S1 and S2 with ``truth`` and with ``mcl`` localisation over several seeds.
Table 5 puts the paper's value beside our mean ± 95 % CI for each mode; the
figures show seed ``first_seed`` of each scenario and mode.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from dfcoa_opt import metrics, plotting
from dfcoa_opt.atomic import atomic_write
from dfcoa_opt.bench.plots import save_png, scenario_for_row
from dfcoa_opt.bench.recipes import Artefact, recipe
from dfcoa_opt.bench.report import aggregate
from dfcoa_opt.bench.store import ResultsStore
from dfcoa_opt.sim.log import RunLog

#: Table 5 rows: (summary key, label, unit as printed by the paper).
TABLE5_ROWS = (
    ("fce_rms", "FCE (RMS)", "m"), ("fce_mean", "FCE (Mean)", "m"),
    ("fce_max", "FCE (Max)", "m"), ("fce_x_rms", "FCE (X-RMS)", "m"),
    ("fce_y_rms", "FCE (Y-RMS)", "m"), ("fse_rms", "FSE (RMS)", "m (paper: m²)"),
    ("fse_mean", "FSE (Mean)", "m (paper: m²)"), ("stability_pct", "Formation Stability", "%"),
    ("vce_rms", "VCE (RMS)", "m/s"), ("v_rms", "RMS Linear Velocity", "m/s"),
    ("w_rms", "RMS Angular Velocity", "rad/s"), ("risk_mean", "Average Risk", "–"),
    ("risk_max", "Max Collision Risk", "–"),
    ("min_inter_robot_distance", "Min Safety Distance", "m"),
)
#: Extra rows the paper states in words (collision-free, goal reached) or not at all.
EXTRA_ROWS = (("risk_clip_pct", "Steps with the normalised risk at its clip (1)", "%", None),
              ("risk_raw_mean", "Average Risk, raw eq 11", "1/m²", None),
              ("collisions", "Collisions", "count", (0.0, 0.0)),
              ("loc_rmse", "Localisation RMSE", "m", None),
              ("time_to_goal", "Time to goal", "s", None))
SCENARIOS = ("dfcoa_s1", "dfcoa_s2")
MODES = ("truth", "mcl")


def _mode(row: dict[str, Any]) -> str:
    return str((row.get("overrides") or {}).get("localization.mode", "truth"))


def _cell(stat: dict[str, Any] | None) -> str:
    if not stat or not np.isfinite(stat["mean"]):
        return "—"
    ci = stat["ci95"]
    return f"{stat['mean']:.4f}" + (f" ± {ci:.4f}" if np.isfinite(ci) else "")


def _targets(stats: dict[tuple[str, str], dict[str, Any]]) -> list[str]:
    """The issue's acceptance targets, met or missed, per scenario and mode."""
    paper = metrics.PAPER_000_TABLE5
    lines = ["| target | " + " | ".join(f"{s} {m}" for s in SCENARIOS for m in MODES) + " |",
             "|---|" + "---|" * (len(SCENARIOS) * len(MODES))]
    checks = (
        ("collisions = 0", lambda g, i: g["collisions"]["mean"] == 0),
        ("stability ≥ paper", lambda g, i: g["stability_pct"]["mean"] >= paper["stability_pct"][i]),
        ("FCE RMS ≤ paper", lambda g, i: g["fce_rms"]["mean"] <= paper["fce_rms"][i]),
        ("min distance ≥ paper", lambda g, i: g["min_inter_robot_distance"]["mean"]
         >= paper["min_inter_robot_distance"][i]),
        ("RMS v within 10 % of 0.3 m/s", lambda g, i: abs(g["v_rms"]["mean"] - 0.3) <= 0.03),
    )
    for name, ok in checks:
        cells = []
        for i, s in enumerate(SCENARIOS):
            for m in MODES:
                g = stats.get((s, m))
                cells.append("—" if g is None else ("met" if ok(g, i) else "**missed**"))
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return lines


def _table5(store: ResultsStore, dest: Path) -> Path:
    rows = store.rows()
    keys = [k for k, _, _ in TABLE5_ROWS] + [k for k, *_ in EXTRA_ROWS]
    by_mode = [dict(r, overrides_hash=_mode(r)) for r in rows]
    groups = aggregate(by_mode, keys, by=("scenario", "overrides_hash"))
    stats = {(g["scenario"], g["overrides_hash"]): {**g["stats"], "_g": g} for g in groups}
    head = ["| metric | unit | S1 paper | S1 truth | S1 mcl | S2 paper | S2 truth | S2 mcl |",
            "|---|---|---|---|---|---|---|---|"]
    body = []
    paper = metrics.PAPER_000_TABLE5
    table = [(k, label, unit, paper[k]) for k, label, unit in TABLE5_ROWS] + list(EXTRA_ROWS)
    for key, label, unit, pv in table:
        cells = []
        for i, s in enumerate(SCENARIOS):
            cells.append("—" if pv is None else f"{pv[i]:g}")
            cells += [_cell(stats.get((s, m), {}).get(key)) for m in MODES]
        body.append(f"| {label} | {unit} | " + " | ".join(cells) + " |")
    runs = ", ".join(f"{s} {m}: {g['_g']['runs']} runs, {g['_g']['failed']} failed, goal "
                     f"reached {100 * g['_g']['reached_rate']:.0f} %, success (reached with no "
                     f"contact) {100 * g['_g']['success_rate']:.0f} %"
                     for (s, m), g in sorted(stats.items()))
    text = ["# Paper 000 Table 5: DFCOA in Scenarios 1 and 2", "",
            "Paper value beside ours: mean ± 95 % CI over seeds (Student t), with ground-truth "
            "poses (`truth`) and with Monte Carlo localization (`mcl`). The paper reports one run "
            "per scenario. Metric definitions: docs/metrics.md; scenario and parameter choices: "
            "docs/reproduction.md.", "", *head, *body, "", f"Runs: {runs}.", "",
            "## Acceptance targets (issue 4)", "", *_targets(stats), ""]
    return atomic_write(dest / "table5.md", "\n".join(text))


def _panels(log: RunLog, path: Path, title: str) -> Path:
    """Speed (commanded; dotted: over the ground), ω and steering per robot (Figs 12-13, 17-18).

    The ground speed includes any disturbance (S2's push on a1), which the
    commanded v does not show.
    """
    fig = plotting.new_figure((8.0, 7.0))
    axes = fig.subplots(3, 1, sharex=True)
    colors = plotting.robot_colors(log.n_robots)
    ground = np.linalg.norm(np.diff(log.pose[..., :2], axis=0), axis=2) / np.diff(log.t)[:, None]
    for i in range(log.n_robots):
        lab = f"a{i + 1}"
        axes[0].plot(log.t, log.twist[:, i, 0], color=colors[i], lw=1, label=lab)
        axes[0].plot(log.t[1:], ground[:, i], color=colors[i], lw=0.8, ls=":")
        axes[1].plot(log.t, log.twist[:, i, 1], color=colors[i], lw=1)
        axes[2].plot(log.t, log.steering[:, i], color=colors[i], lw=1)
    for ax, lab in zip(axes, ("v (m/s), dotted: ground", "ω (rad/s)", "steering (rad)"),
                       strict=True):
        ax.set_ylabel(lab)
        ax.grid(alpha=0.3)
    axes[0].legend(ncol=4, fontsize="small")
    axes[0].set_title(title)
    axes[2].set_xlabel("t (s)")
    return save_png(fig, path)


def _errors(log: RunLog, path: Path, title: str) -> Path:
    """Pose errors e_x, e_y of Algorithm 2 over time (Figs 14, 19)."""
    err = log.slots - log.pose[..., :2]
    fig = plotting.new_figure((8.0, 5.0))
    axes = fig.subplots(2, 1, sharex=True)
    colors = plotting.robot_colors(log.n_robots)
    for i in range(log.n_robots):
        for ax, c in zip(axes, (0, 1), strict=True):
            ax.plot(log.t, err[:, i, c], color=colors[i], lw=1, label=f"a{i + 1}")
    axes[0].set_ylabel("e_x (m)")
    axes[1].set_ylabel("e_y (m)")
    axes[1].set_xlabel("t (s)")
    axes[0].legend(ncol=4, fontsize="small")
    axes[0].set_title(title)
    return save_png(fig, path)


def _metric_panels(log: RunLog, spec: Any, path: Path, title: str) -> Path:
    """FCE, FSE, FStE, VCE and risk over time (Figs 15, 20)."""
    series = (("FCE (m)", metrics.formation_centroid_error(log)),
              ("FSE (m)", metrics.formation_shape_error(log)),
              ("FStE (m)", metrics.formation_stability_error(log, spec.fste_window)),
              ("VCE (m/s)", metrics.velocity_centroid_error(log)),
              ("risk", metrics.collision_risk_normalised(log, spec)))
    fig = plotting.new_figure((8.0, 9.0))
    axes = fig.subplots(len(series), 1, sharex=True)
    for ax, (lab, y) in zip(axes, series, strict=True):
        ax.plot(log.t[:len(y)], y, lw=1)
        ax.set_ylabel(lab)
        ax.grid(alpha=0.3)
    axes[0].set_title(title)
    axes[-1].set_xlabel("t (s)")
    return save_png(fig, path)


@recipe("dfcoa_paper", sweep="sweeps/dfcoa_paper.toml",
        title="Paper 000 (DFCOA): Table 5 and Figs 11-20, truth and MCL")
def render_dfcoa(store: ResultsStore, dest: Path) -> list[Artefact]:
    """Table 5 plus the figures of the first seed of each scenario and mode."""
    arts = [Artefact("table5.md", "paper 000 Table 5",
                     "every Table 5 metric, paper beside ours (truth and MCL), targets")]
    _table5(store, dest)
    rows = [r for r in store.rows() if r["status"] == "ok"]
    figs = {"dfcoa_s1": ("Fig. 11", "Figs 12-13", "Fig. 14", "Fig. 15"),
            "dfcoa_s2": ("Fig. 16", "Figs 17-18", "Fig. 19", "Fig. 20")}
    for scen, (f_map, f_v, f_err, f_met) in figs.items():
        for mode in MODES:
            pick = sorted((r for r in rows if r["scenario"] == scen and _mode(r) == mode),
                          key=lambda r: r["seed"])
            if not pick:
                continue
            row = pick[0]
            log = RunLog.load(store.root / row["log"])
            sc = scenario_for_row(row)
            tag = f"{scen}_{mode}_s{row['seed']}"
            title = f"{scen}, {mode}, seed {row['seed']}"
            plotting.plot_run(log, sc.world.grid, dest / f"map_{tag}.png", goal=sc.spec.leader.goal,
                              start=sc.spec.leader.start, shapes=sc.world.shapes, title=title)
            _panels(log, dest / f"velocity_{tag}.png", title)
            _errors(log, dest / f"pose_error_{tag}.png", title)
            _metric_panels(log, sc.spec.metrics, dest / f"metrics_{tag}.png", title)
            arts += [Artefact(f"map_{tag}.png", f"paper 000 {f_map}", "map, leader path, robots"),
                     Artefact(f"velocity_{tag}.png", f"paper 000 {f_v}", "v, ω, steering"),
                     Artefact(f"pose_error_{tag}.png", f"paper 000 {f_err}", "e_x, e_y"),
                     Artefact(f"metrics_{tag}.png", f"paper 000 {f_met}",
                              "FCE, FSE, FStE, VCE, risk over time")]
    return arts
