"""Results of the scaling study (:mod:`benchmarks.scaling`): summary, CSV, plot, stdout.

:func:`summarise` turns the pooled step times (:class:`~benchmarks.scaling.samples.Sample`)
into a :class:`~benchmarks.scaling.samples.Summary`, one row per (controller, N) with
medians, min-max, ratios and fitted log-log slopes; :func:`write_csv`, :func:`plot`
and :func:`print_summary` write it out (``scaling.md`` is
:mod:`benchmarks.scaling.markdown`).
"""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.scaling.samples import Sample, Summary, median_ms
from benchmarks.scaling.scenario import model_of
from dfcoa_opt.core.runtime.provenance import machine

#: The "upper" slope is fitted over the sizes at or above this N (small N = constant overhead).
UPPER_FROM = 64
#: Issue 7's target for the fitted log-log slope.
TARGET_SLOPE = 1.2


def summarise(samples: dict[tuple[str, int], Sample], controllers: Sequence[str],
              sizes: Sequence[int]) -> Summary:
    """Medians, min-max, ratios and fitted slopes."""
    rows: list[dict[str, Any]] = []
    slopes: dict[str, dict[str, float]] = {}
    for cid in controllers:
        ref = None
        for n in sizes:
            s = samples[(cid, n)]
            act, step = np.asarray(s.act) * 1e3, np.asarray(s.step) * 1e3
            med = float(np.median(act)) if len(act) else math.nan
            if ref is None and math.isfinite(med):
                ref = med
            spread = (max(s.rounds) / min(s.rounds)) if len(s.rounds) > 1 else math.nan
            rows.append({
                "controller": cid, "model": model_of(cid)["model"], "n": n,
                "steps": len(act),
                "act_median_ms": med,
                "act_min_ms": float(act.min()) if len(act) else math.nan,
                "act_max_ms": float(act.max()) if len(act) else math.nan,
                "step_median_ms": float(np.median(step)) if len(step) else math.nan,
                "step_min_ms": float(step.min()) if len(step) else math.nan,
                "step_max_ms": float(step.max()) if len(step) else math.nan,
                "sim_median_ms": float(np.median(step - act)) if len(step) else math.nan,
                "lidar_median_ms": median_ms(s.lidar), "query_median_ms": median_ms(s.query),
                "log_mean_step_ms": float(np.nanmean(s.log_step)) * 1e3
                if np.isfinite(s.log_step).any() else math.nan,
                "act_us_per_robot": med * 1e3 / n,
                "act_ratio_vs_smallest": med / ref if ref else math.nan,
                "round_spread": spread,
                "notes": "; ".join(s.notes),
            })
        mine = [r for r in rows if r["controller"] == cid]
        upper = [r for r in mine if r["n"] >= UPPER_FROM]
        slopes[cid] = {
            "act_all": loglog_slope([r["n"] for r in mine], [r["act_median_ms"] for r in mine]),
            "act_upper": loglog_slope([r["n"] for r in upper],
                                      [r["act_median_ms"] for r in upper]),
            "step_all": loglog_slope([r["n"] for r in mine],
                                     [r["step_median_ms"] for r in mine]),
            "step_upper": loglog_slope([r["n"] for r in upper],
                                       [r["step_median_ms"] for r in upper]),
            "act_last": loglog_slope([r["n"] for r in mine[-2:]],
                                     [r["act_median_ms"] for r in mine[-2:]]),
            "step_last": loglog_slope([r["n"] for r in mine[-2:]],
                                      [r["step_median_ms"] for r in mine[-2:]]),
        }
    return Summary(rows, slopes)


def loglog_slope(ns: Sequence[float], ts: Sequence[float]) -> float:
    """Least-squares slope of ``log t`` against ``log N`` (nan with fewer than 2 points)."""
    pts = [(n, t) for n, t in zip(ns, ts, strict=True) if t > 0 and math.isfinite(t)]
    if len(pts) < 2:
        return math.nan
    x, y = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
    return float(np.polyfit(x, y, 1)[0])


def fmt(x: float, digits: int = 3) -> str:
    """A number with ``digits`` significant digits, or ``-`` for nan."""
    if not math.isfinite(x):
        return "-"
    return f"{x:.{digits}g}" if abs(x) < 10 ** digits else f"{x:.0f}"


def plot(summary: Summary, controllers: Sequence[str], sizes: Sequence[int], path: Path) -> None:
    """Log-log plot of the medians: controller (left) and whole step (right)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(12, 5), sharex=True)
    for ax, key, title in ((axes[0], "act", "controller act() per step"),
                           (axes[1], "step", "whole simulator step")):
        tops = []
        for cid in controllers:
            mine = [r for r in summary.rows if r["controller"] == cid]
            ns = [r["n"] for r in mine]
            med = np.array([r[f"{key}_median_ms"] for r in mine])
            lo = np.array([r[f"{key}_min_ms"] for r in mine])
            hi = np.array([r[f"{key}_max_ms"] for r in mine])
            sl = summary.slopes[cid][f"{key}_upper"]
            ax.errorbar(ns, med, yerr=[med - lo, hi - med], marker="o", ms=4, capsize=2,
                        label=f"{cid} (slope {sl:.2f})")
            if np.isfinite(med[-1]):
                tops.append(med[-1])
        if tops:  # slope-1 reference through the geometric mean at the largest N
            anchor = float(np.exp(np.mean(np.log(tops))))
            n = np.array([sizes[0], sizes[-1]], dtype=float)
            ax.plot(n, anchor * n / sizes[-1], "k--", lw=1, label="slope 1 (O(N))")
            nl = np.geomspace(sizes[0], sizes[-1], 30)
            ax.plot(nl, anchor * nl * np.log(nl) / (sizes[-1] * math.log(sizes[-1])), "k:",
                    lw=1, label="N log N")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("robots N")
        ax.set_ylabel("median time per step (ms)")
        ax.set_title(f"{title} (slopes over N >= {UPPER_FROM})")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle(f"Scaling, open field, grid formation ({machine()})", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def write_csv(summary: Summary, path: Path) -> None:
    """One row per (controller, N); times in ms."""
    with path.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(summary.rows[0]))
        w.writeheader()
        for r in summary.rows:
            w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})


def print_summary(summary: Summary, controllers: Sequence[str], sizes: Sequence[int]) -> None:
    """The two median tables and the slopes on stdout."""
    print(f"\n{'controller':22s} " + " ".join(f"{'N=' + str(n):>16s}" for n in sizes)
          + "   slope all / upper")
    for key in ("act", "step"):
        print(f"-- {key} median ms")
        for cid in controllers:
            cells = [next(r for r in summary.rows if r["controller"] == cid and r["n"] == n)
                     for n in sizes]
            sl = summary.slopes[cid]
            print(f"{cid:22s} " + " ".join(f"{fmt(c[f'{key}_median_ms']):>16s}" for c in cells)
                  + f"   {sl[key + '_all']:.2f} / {sl[key + '_upper']:.2f}")
