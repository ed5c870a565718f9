"""The text of ``scaling.md`` (:mod:`benchmarks.scaling`): tables, summary, findings."""

from __future__ import annotations

import datetime
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from benchmarks.scaling.report import TARGET_SLOPE, UPPER_FROM, fmt, loglog_slope
from benchmarks.scaling.samples import Summary
from benchmarks.scaling.scenario import AREA_PER_ROBOT, DT, LEADER_SPEED, model_of
from dfcoa_opt.core.runtime.provenance import machine, versions
from dfcoa_opt.sim import neighbours as sim_neighbours
from dfcoa_opt.world import lidar as lidar_module


def _table(summary: Summary, controllers: Sequence[str], sizes: Sequence[int], key: str,
           with_range: bool) -> list[str]:
    """Markdown table controller x N of ``<key>_median_ms`` (and min-max)."""
    head = ["| controller | model | " + " | ".join(f"N={n}" for n in sizes) + " |",
            "|---|---|" + "---|" * len(sizes)]
    body = []
    for cid in controllers:
        cells = []
        for n in sizes:
            r = next(r for r in summary.rows if r["controller"] == cid and r["n"] == n)
            cell = fmt(r[f"{key}_median_ms"])
            if with_range and math.isfinite(r[f"{key}_min_ms"]):
                cell += f" ({fmt(r[f'{key}_min_ms'], 2)}-{fmt(r[f'{key}_max_ms'], 2)})"
            cells.append(cell)
        body.append(f"| {cid} | {model_of(cid)['model']} | " + " | ".join(cells) + " |")
    return head + body


def measured_summary(summary: Summary, controllers: Sequence[str], sizes: Sequence[int],
                     sensing: Sequence[dict[str, float]]) -> list[str]:
    """Bullet points drawn from the numbers: target, worst slopes, the simulator's share."""
    sl = summary.slopes
    out = []
    act_up = {c: sl[c]["act_upper"] for c in controllers}
    step_up = {c: sl[c]["step_upper"] for c in controllers}
    if all(math.isfinite(v) for v in [*act_up.values(), *step_up.values()]):
        ok = all(v <= TARGET_SLOPE for v in [*act_up.values(), *step_up.values()])
        out.append(
            f"* Controller `act`, slope over N >= {UPPER_FROM}: {min(act_up.values()):.2f} to "
            f"{max(act_up.values()):.2f} (worst `{max(act_up, key=act_up.get)}`); whole "
            f"step: {min(step_up.values()):.2f} to {max(step_up.values()):.2f} (worst "
            f"`{max(step_up, key=step_up.get)}`). Target <= {TARGET_SLOPE}: "
            + ("met by every controller, act and whole step." if ok
               else "NOT met by every controller (see the slope table)."))
    else:
        out.append(f"* Too few sizes >= {UPPER_FROM} to fit the upper slopes.")
    if len(sizes) < 2:
        return out
    n_lo, n_hi = sizes[-2], sizes[-1]

    def med(n: int, key: str) -> float:
        return float(np.median([r[key] for r in summary.rows if r["n"] == n]))

    top = [r for r in summary.rows if r["n"] == n_hi]
    share = float(np.median([r["lidar_median_ms"] / r["step_median_ms"] for r in top]))
    q_share = float(np.median([r["query_median_ms"] / r["step_median_ms"] for r in top]))
    act_share = {r["controller"]: r["act_median_ms"] / r["step_median_ms"] for r in top}
    rest = {n: med(n, "sim_median_ms") - med(n, "lidar_median_ms") - med(n, "query_median_ms")
            for n in (n_lo, n_hi)}

    def local(key: str) -> float:
        return loglog_slope([n_lo, n_hi], [med(n_lo, key), med(n_hi, key)])

    out.append(
        f"* At N = {n_hi} the LiDAR scan takes {100 * share:.0f} % of a whole step (median "
        f"over controllers), the neighbour query {100 * q_share:.0f} %; the controller's own "
        f"share ranges from {100 * min(act_share.values()):.0f} % "
        f"(`{min(act_share, key=act_share.get)}`) to {100 * max(act_share.values()):.0f} % "
        f"(`{max(act_share, key=act_share.get)}`). Local slopes between N = {n_lo} and "
        f"{n_hi}: whole step {min(sl[c]['step_last'] for c in controllers):.2f} to "
        f"{max(sl[c]['step_last'] for c in controllers):.2f}; LiDAR "
        f"{local('lidar_median_ms'):.2f}, neighbour query {local('query_median_ms'):.2f}"
        f", rest of the simulator {loglog_slope([n_lo, n_hi], [rest[n_lo], rest[n_hi]]):.2f}.")
    if sensing:
        big = sensing[-1]
        upper = [r for r in sensing if r["n"] >= UPPER_FROM]
        lidar_up = loglog_slope([r["n"] for r in upper], [r["lidar_default"] for r in upper])
        path = ("bucket-grid candidate lists, whose construction alone takes "
                f"{fmt(big['lidar_candidates'])} ms of the {fmt(big['lidar_default'])} ms "
                f"scan (all pairs forced: {fmt(big['lidar_all_pairs'])} ms)"
                if big["lidar_kdtree_used"] else
                f"all robot-disc pairs tested in the kernel ({fmt(big['lidar_default'])} ms)")
        out.append(
            f"* LiDAR, sensing reference, slope over N >= {UPPER_FROM}: {lidar_up:.2f}. At "
            f"N = {big['n']} the scan uses {path}. `proximity` costs "
            f"{big['proximity'] / big['neighbour_table']:.1f}x the K-nearest table alone "
            "(second tree, closest pair, contacts).")
    return out


def markdown(summary: Summary, controllers: Sequence[str], sizes: Sequence[int],
             memory: dict[str, dict[str, float]], build: dict[int, float], cfg: dict[str, Any],
             elapsed: float, sensing: Sequence[dict[str, float]] = ()) -> str:
    """The text of ``scaling.md``."""
    upper_sizes = [n for n in sizes if n >= UPPER_FROM]
    lines = [
        f"# Scaling study ({datetime.date.today().isoformat()})", "",
        "Issue 7 (performance and scale): cost per step of every registered controller "
        f"at N = {', '.join(map(str, sizes))}. Generated by `python -m "
        "benchmarks.scaling`; do not edit by hand.", "",
        f"CPU: {machine()}; {versions()}.", "",
        "## Setup", "",
        f"* Open field, no obstacles, {AREA_PER_ROBOT:g} m^2 per robot (square, side "
        f"sqrt({AREA_PER_ROBOT:g} N) m: "
        + ", ".join(f"{math.sqrt(AREA_PER_ROBOT * n):.1f} m" for n in sizes)
        + "), 10 cells/m; grid formation, 1 m spacing, ceil(sqrt N) columns; virtual "
        f"leader on a straight line along +x at {LEADER_SPEED} m/s; dt {DT} s; 8 nearest "
        "neighbours within 5 m; LiDAR 36 beams, 4 m, on for every controller (`dfcoa` needs "
        "it), so the simulator's share is the same for all and is reported separately.",
        "* Robot model per controller (as its module documents): "
        + ", ".join(f"`{c}` {model_of(c)['model']}" for c in controllers) + ".",
        f"* Per (controller, N): {cfg['rounds']} interleaved round(s) of "
        f"{cfg['warmup']} warm-up + {cfg['steps']} measured steps; every controller ran "
        "once at N = 16 and 64 before timing (numba compile / cache load). Medians and "
        "min-max are over all measured steps of all rounds.",
        "* *controller* = the controller's `act` call; *whole step* = time between two "
        "successive `act` starts (simulator + controller); *simulator* = whole step - act "
        "(LiDAR, neighbour query, adapters, integration, contacts, logging).",
        f"* Slopes: least squares of log(median) on log N over all sizes, and over "
        f"N >= {UPPER_FROM} ({', '.join(map(str, upper_sizes))}), where the constant "
        f"per-call overhead no longer dominates. Target: <= {TARGET_SLOPE} (O(N log N): "
        f"N log N has a local slope of 1 + 1/ln N, {1 + 1 / math.log(256):.2f} at N = 256).",
        "* Ratio = median at N / median at the smallest N of the same controller, same "
        "process. The machine is noisy (2 cores, other jobs): compare ratios and slopes, "
        "not absolute times across runs. Round spread = largest / smallest per-round "
        "median of the same pair.", "",
        "## Controller cost per step, median ms (min-max)", "",
        *_table(summary, controllers, sizes, "act", True), "",
        "## Whole simulator step, median ms (min-max)", "",
        *_table(summary, controllers, sizes, "step", True), "",
        "## Fitted log-log slopes", "",
        f"*Last pair* = the local slope between N = {sizes[-2] if len(sizes) > 1 else '-'} "
        f"and N = {sizes[-1]} (two points, indicative only).", "",
        f"| controller | act, all N | act, N >= {UPPER_FROM} | act, last pair | step, all N | "
        f"step, N >= {UPPER_FROM} | step, last pair | act ratio N={sizes[-1]} / N={sizes[0]}"
        f" | act per robot at N={sizes[-1]} (us) | target met, N >= {UPPER_FROM} (act / step) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]

    def met(x: float) -> str:
        return "-" if not math.isfinite(x) else ("yes" if x <= TARGET_SLOPE else "NO")

    for cid in controllers:
        sl = summary.slopes[cid]
        last = next(r for r in summary.rows if r["controller"] == cid and r["n"] == sizes[-1])
        lines.append(f"| {cid} | {sl['act_all']:.2f} | {sl['act_upper']:.2f} | "
                     f"{sl['act_last']:.2f} | {sl['step_all']:.2f} | {sl['step_upper']:.2f} | "
                     f"{sl['step_last']:.2f} | {fmt(last['act_ratio_vs_smallest'])} | "
                     f"{fmt(last['act_us_per_robot'])} | {met(sl['act_upper'])} / "
                     f"{met(sl['step_upper'])} |")
    lines += ["", "## Simulator share, median ms over all controllers' steps", "",
              "| N | field side (m) | scenario build (s) | LiDAR scan | neighbour query | "
              "simulator (step - act) | worst round spread |", "|---|---|---|---|---|---|---|"]
    for n in sizes:
        mine = [r for r in summary.rows if r["n"] == n]
        spread = [r["round_spread"] for r in mine if math.isfinite(r["round_spread"])]
        lines.append(
            f"| {n} | {math.sqrt(AREA_PER_ROBOT * n):.1f} | {fmt(build.get(n, math.nan), 2)} |"
            f" {fmt(float(np.median([r['lidar_median_ms'] for r in mine])))} | "
            f"{fmt(float(np.median([r['query_median_ms'] for r in mine])))} | "
            f"{fmt(float(np.median([r['sim_median_ms'] for r in mine])))} | "
            f"{fmt(max(spread)) if spread else '-'} |")
    sim_slope = loglog_slope(list(sizes), [float(np.median(
        [r["sim_median_ms"] for r in summary.rows if r["n"] == n])) for n in sizes])
    sim_upper = loglog_slope(upper_sizes, [float(np.median(
        [r["sim_median_ms"] for r in summary.rows if r["n"] == n])) for n in upper_sizes])
    lines += ["", f"Simulator share slope: {sim_slope:.2f} over all N, {sim_upper:.2f} over "
                  f"N >= {UPPER_FROM}.", ""]
    if sensing:
        lidar_up = loglog_slope([r["n"] for r in sensing if r["n"] >= UPPER_FROM],
                                [r["lidar_default"] for r in sensing if r["n"] >= UPPER_FROM])
        lines += ["## Sensing references (same process)", "",
                  f"{cfg['sensing_calls']} calls each at the scenario's start poses, median ms. "
                  "LiDAR: the library's choice of disc candidates (all pairs in the kernel "
                  f"below {lidar_module.CANDIDATES_MIN_PAIRS:,} robot-disc pairs, a bucket grid "
                  "above when one sensing disc covers less than "
                  f"{lidar_module.CANDIDATES_MAX_FRACTION:g} of the team's bounding box), against "
                  "all pairs forced and the pair threshold set to 0 (the coverage condition "
                  "still applies, so this is all pairs too while the field is small: N <= 256 "
                  "here); *candidates* = the candidate-list step (`Lidar._discs`: the "
                  "bucket grid, `lidar.disc_candidates`) alone, as chosen. The module constant is "
                  "changed for these calls only. Neighbour query: the simulator's `proximity`"
                  " (K-nearest table + closest pair + contacts) against `neighbour_table` "
                  "alone.", "",
                  "| N | LiDAR as chosen | all pairs | pair threshold 0 | candidates | "
                  "chosen / all pairs | `proximity` | `neighbour_table` | proximity / table |",
                  "|---|---|---|---|---|---|---|---|---|"]
        for r in sensing:
            lines.append(
                f"| {r['n']} | {fmt(r['lidar_default'])} | {fmt(r['lidar_all_pairs'])} | "
                f"{fmt(r['lidar_kdtree'])} | {fmt(r['lidar_candidates'])} | "
                f"{r['lidar_default'] / r['lidar_all_pairs']:.2f} | "
                f"{fmt(r['proximity'])} | {fmt(r['neighbour_table'])} | "
                f"{r['proximity'] / r['neighbour_table']:.2f} |")
        lines += ["", f"LiDAR (as chosen) slope over N >= {UPPER_FROM}: {lidar_up:.2f}.", ""]
    if memory:
        mem_n, ref_n = cfg["memory_n"], cfg["memory_ref_n"]
        lines += [f"## Peak memory, N = {mem_n}", "",
                  f"Fresh subprocess per controller (`python -m benchmarks.scaling.memory`): a "
                  "4-robot run loads the numba kernels; the peak-RSS counter (`VmHWM`) is reset "
                  f"(`/proc/self/clear_refs`) before building the N = {mem_n} scenario and "
                  f"again before running it for {cfg['memory_steps']} steps after the first. "
                  "*Growth* = peak RSS of the phase minus the RSS before it (the build "
                  "includes the occupancy grid, its distance field and the leader path); "
                  "*process peak* = peak RSS of the whole process (interpreter, numpy, "
                  "scipy, numba/LLVM, scenario, run). The same child at N = "
                  f"{ref_n} is the reference. *tracemalloc* = peaks of Python and numpy "
                  "allocations of a second build and run in the same child (memory allocated "
                  "inside numba kernels is not traced). `ru_maxrss` is not used: Linux keeps "
                  "it across `execve`, so a child would report its parent's peak.", "",
                  f"| controller | build growth (MiB) | run growth (MiB) | run growth N={ref_n} "
                  "(MiB) | process peak (MiB) | tracemalloc build / run (MiB) | run (s) |",
                  "|---|---|---|---|---|---|---|"]
        for cid in controllers:
            m = memory.get(cid, {})
            if "process_peak_mb" not in m:
                lines.append(f"| {cid} | failed: {m.get('error', '?')} | | | | | |")
                continue
            lines.append(
                f"| {cid} | {m['build_growth_mb']:.1f} | {m['run_growth_mb']:.1f} | "
                f"{m.get('ref_run_growth_mb', math.nan):.1f} | {m['process_peak_mb']:.0f} | "
                f"{m.get('traced_build_mb', math.nan):.1f} / "
                f"{m.get('traced_run_mb', math.nan):.1f} | {m['seconds']:.2f} |")
        lines.append("")
    lines += ["## Summary (measured)", "", *measured_summary(summary, controllers, sizes,
                                                            sensing), ""]
    notes = [f"* `{r['controller']}` N={r['n']}: {r['notes']}" for r in summary.rows
             if r["notes"]]
    lines += ["## Caps and skips", "", *(notes or [
        f"None: every pair ran all its measured steps (budget {cfg['budget']:g} s per run)."]),
        "", "## Findings (code reading; nothing changed)", "",
        *[f"{k}. {text}" for k, text in enumerate(findings(), 1)], "",
        f"Worst measured slopes (act, N >= {UPPER_FROM}): " + ", ".join(
            f"`{c}` {summary.slopes[c]['act_upper']:.2f}" for c in sorted(
                controllers, key=lambda c: -np.nan_to_num(summary.slopes[c]["act_upper"]))[:3])
        + ".",
        "", f"Plot: `scaling.png`; data: `scaling.csv`. Whole run: {elapsed / 60:.1f} min "
        f"({elapsed:.0f} s).", ""]
    return "\n".join(lines)


def findings() -> list[str]:
    """All-pairs and per-obstacle work found by reading the code (file:function), as text."""
    dense, kernel = sim_neighbours.DENSE_MAX, sim_neighbours.KERNEL_MAX
    pairs = lidar_module.CANDIDATES_MIN_PAIRS
    frac = lidar_module.CANDIDATES_MAX_FRACTION
    return [
        f"`dfcoa_opt/sim/neighbours.py:neighbour_table` -- a dense N x N distance matrix "
        f"(`geometry.pairwise_distances`, numpy) for N <= DENSE_MAX = {dense}; `:proximity` "
        f"-- one compiled all-pairs loop for N <= KERNEL_MAX = {kernel}; a `cKDTree` above. "
        "O(N^2) only up to those bounds, so not an asymptotic problem. Above them "
        "`proximity` queries its one tree up to three times (the K-nearest table, `k = 2` for "
        "the closest pair when nobody has a neighbour in range, `query_pairs` for contacts; "
        "the 'proximity / table' column of 'Sensing references').",
        "`dfcoa_opt/world/lidar.py:Lidar._discs` / `_scan_kernel` -- every robot tests every "
        f"other robot's disc (all pairs, in numba) unless N * (N + M) >= CANDIDATES_MIN_PAIRS = "
        f"{pairs:,} (N >= {math.ceil(math.sqrt(pairs))} with no moving obstacles) and one "
        f"sensing disc covers less than {frac:g} of the discs' bounding box; then a bucket "
        "grid (`lidar.disc_candidates`, numba, O(N + pairs)) gives the candidates. Below "
        "that N the work is O(N^2), compiled, about a nanosecond per rejected pair; a dense "
        "team in a small field stays all-pairs at any N.",
        "`dfcoa_opt/sim/simulator.py:Simulator.run` and `:_moving_obstacles` -- (N, M) "
        "robot-to-moving-obstacle distances and (N, M, 2) padded obstacle arrays every step: "
        "O(N M). Linear in N for a fixed crowd, O(N^2) if the crowd grows with the team "
        "(none in this open scenario).",
        "`dfcoa_opt/scenario/scenario.py:World.clearance` (called every step by the simulator) -- "
        "one numba loop (`world/shape_clearance.py`) over every static circle and every "
        "polygon edge, with an even-odd test for the polygons whose box holds the robot: "
        "O(N (C + E)) per step, about 5 us for 4 robots in S1. "
        "O(N^2) when obstacles grow with the field (constant obstacle density); not measured "
        "here (open field).",
        "`comparisons/lf_vo/controller.py:LeaderFollowerVO.clearance` "
        "(numba `lf_vo.kernel.vo_clearance`)"
        " -- every robot rolls its samples out against every static circle "
        "(`scenario.world.circles`, not a local query): O(N C) per step, same caveat.",
        "`comparisons/virtual_spring/controller.py:VirtualSpring.spring` "
        "(numba `virtual_spring.kernels.spring_sources`) -- every robot against "
        "every static circle and "
        "polygon edge (edges built once at reset): O(N (C + E)) per step. "
        "`comparisons/virtual_spring/equations.py:fig1_adjacency` (called by `reset`) builds a "
        "dense N x N adjacency matrix with a Python loop: O(N^2) memory (8 MB at N = 1000, "
        "800 MB at N = 10 000) for a graph with 3 entries per row.",
        "`comparisons/orca/ivo/polygons.py:ivo_lines` (`consensus_ivo`, orca filter mode 'ivo') -- "
        "(N, S + C) distances to every obstacle segment and static disc (a circle is one "
        "exact disc, not 32 edges) and an argsort per robot: O(N (S + C) log(S + C)) per "
        "step; `comparisons/orca/safe.py:segment_safety_lines` (modes "
        "'next_step' and `safe_discrete`) is (N, E) likewise. Mode 'orca' "
        "(`orca/obstacles.py:obstacle_lines`) uses an obstacle tree and is fine.",
        "No controller does an all-pairs loop over robots: `consensus`, `consensus_ivo`, "
        "`lf_vo`, `virtual_spring*`, `dfcoa` (VFH* repulsion) and `orca_nav` read the "
        "simulator's K-nearest table (K = 8), i.e. O(N K) per step.",
    ]
