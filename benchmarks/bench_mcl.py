"""Benchmark: Monte Carlo localization (dfcoa_opt.sim.localization.mcl) on the DFCOA S1 map.

Run ``python -m benchmarks.bench_mcl``. The true poses of a whole S1 run
(``scenarios/dfcoa_s1.toml``, 4 robots, 120-beam LiDAR, ``goto_slot``) are
recorded once with ground-truth localization, and their scans (grid plus the
other robots' bodies) are cast in advance. Each row then times
``estimate()`` for the 4 robots at every step of that run, with
``time.perf_counter``, after one warm-up pass (numba compilation excluded). The
reference is the same estimator with its numba sensor-update kernel replaced by
the vectorised-numpy one below (:func:`numpy_sensor_update`). Two more rows
time the whole simulator step with MCL (reference: the same step with
``truth``), and the whole S1 run.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from benchmarks.bench_sim import scanning
from benchmarks.timing import REPS, print_rows, row
from dfcoa_opt.control.registry import make_controller
from dfcoa_opt.scenario.loader import load_scenario
from dfcoa_opt.sim.localization.mcl import MonteCarloLocalization
from dfcoa_opt.sim.localization.mcl import sensor as mcl_sensor
from dfcoa_opt.sim.simulator import Simulator
from dfcoa_opt.world.lidar import Lidar

ROOT = Path(__file__).resolve().parents[1] / "scenarios"
#: The estimator's own numba sensor update (the reference swaps it out).
NUMBA_SENSOR_UPDATE = mcl_sensor.sensor_update


def s1_path() -> Path:
    """The S1 scenario file (``scenarios/`` or, in older trees, ``scenarios/bench/``)."""
    for p in (ROOT / "dfcoa_s1.toml", ROOT / "bench" / "dfcoa_s1.toml"):
        if p.exists():
            return p
    raise FileNotFoundError("dfcoa_s1.toml not found under scenarios/")


def numpy_sensor_update(parts, w, ptr, upd, ex, ey, nvalid, table, outside, ox, oy, inv_h, amcl,
                        est):
    """Reference: :func:`dfcoa_opt.sim.localization.mcl.sensor.sensor_update` in vectorised numpy.

    Same arguments and in-place results (weights and estimates of robots ``upd``).
    """
    counts = np.diff(ptr)
    rid = np.repeat(np.arange(counts.size), counts)
    sel = upd[rid]
    if not sel.any():
        return
    p, r = parts[sel], rid[sel]
    c, s = np.cos(p[:, 2])[:, None], np.sin(p[:, 2])[:, None]
    bx, by = ex[r], ey[r]
    fx = (p[:, :1] + c * bx - s * by - ox) * inv_h
    fy = (p[:, 1:2] + s * bx + c * by - oy) * inv_h
    rows, cols = table.shape
    inside = (fx >= 0.0) & (fx < cols) & (fy >= 0.0) & (fy < rows)
    v = np.where(inside, table[np.clip(fy, 0, rows - 1).astype(np.intp),
                               np.clip(fx, 0, cols - 1).astype(np.intp)], outside)
    v = np.where(np.arange(bx.shape[1])[None, :] < nvalid[r][:, None], v, 0.0)
    ll = v.sum(axis=1)
    if amcl:
        ll = np.log1p(ll)
    with np.errstate(divide="ignore"):
        lw = np.log(w[sel]) + ll
    starts = np.flatnonzero(np.r_[True, r[1:] != r[:-1]])
    robots = r[starts]
    e = np.exp(lw - np.repeat(np.maximum.reduceat(lw, starts), np.diff(np.r_[starts, r.size])))
    e /= np.repeat(np.add.reduceat(e, starts), np.diff(np.r_[starts, r.size]))
    w[sel] = e
    est[robots, 0] = np.add.reduceat(e * p[:, 0], starts)
    est[robots, 1] = np.add.reduceat(e * p[:, 1], starts)
    est[robots, 2] = np.arctan2(np.add.reduceat(e * np.sin(p[:, 2]), starts),
                                np.add.reduceat(e * np.cos(p[:, 2]), starts))


def recorded_run() -> tuple:
    """``(scenario, true poses (T, 4, 3), scans)`` of one S1 run under ``goto_slot``."""
    sc = load_scenario(s1_path(), overrides={"localization.mode": "mcl"})
    truth = load_scenario(s1_path())
    log = Simulator(truth, make_controller("goto_slot")).run()
    lidar = Lidar(sc.spec.sensors.lidar, sc.world.grid)
    n = sc.spec.team.n
    radii, owner = np.full(n, sc.spec.robots.radius), np.arange(n)
    scans = [lidar.scan(p, p[:, :2], radii, owner) for p in log.pose]
    return sc, log.pose, scans


def time_estimates(est: MonteCarloLocalization, sc, poses: np.ndarray,
                   scans: list) -> np.ndarray:
    """Per-step times (us) of ``estimate()`` over the recorded run (one pass)."""
    twist = np.zeros((poses.shape[1], 2))
    out = np.empty(len(poses))
    est.reset(np.random.default_rng(0))
    for k, (p, scan) in enumerate(zip(poses, scans, strict=True)):
        t0 = time.perf_counter()
        est.estimate(p, twist, scan, sc.spec.dt)
        out[k] = time.perf_counter() - t0
    return out * 1e6


def _numpy_sensor(on: bool) -> None:
    """Swap the numba sensor update for :func:`numpy_sensor_update` (or back)."""
    mcl_sensor.sensor_update = numpy_sensor_update if on else NUMBA_SENSOR_UPDATE


def run() -> list[dict]:
    """Time MCL on S1; one dict per row, ours and the reference in alternate repetitions."""
    sc, poses, scans = recorded_run()
    est = MonteCarloLocalization(sc)
    ours, ref = [], []
    try:
        for use_numpy in (False, True):  # warm-up passes (numba compilation)
            _numpy_sensor(use_numpy)
            time_estimates(est, sc, poses, scans)
        for rep in range(REPS):
            for use_numpy in ((False, True) if rep % 2 == 0 else (True, False)):
                _numpy_sensor(use_numpy)
                (ref if use_numpy else ours).append(time_estimates(est, sc, poses, scans))
    finally:
        _numpy_sensor(False)
    rows = [row(f"mcl estimate, 4 robots, 120 beams, S1 map ({len(poses)} steps)", ours,
                "same with vectorised-numpy sensor update", ref)]
    sims = {"mcl": Simulator(sc, scanning("goto_slot")),  # the LiDAR runs with truth too
            "truth": Simulator(load_scenario(s1_path()), scanning("goto_slot"))}
    step: dict[str, list[np.ndarray]] = {k: [] for k in sims}
    whole: dict[str, list[np.ndarray]] = {k: [] for k in sims}
    for sim in sims.values():
        sim.run()  # warm-up
    for rep in range(REPS):
        for name in (list(sims) if rep % 2 == 0 else list(sims)[::-1]):
            t0 = time.perf_counter()
            log = sims[name].run()
            whole[name].append(np.array([time.perf_counter() - t0]) * 1e6)
            step[name].append(np.array([log.meta["wall_time"] / log.meta["steps"]]) * 1e6)
    rows.append(row("simulator step with mcl, 4 unicycles, 120-beam LiDAR, S1 map", step["mcl"],
                    "same step with truth localization", step["truth"]))
    rows.append(row("whole S1 run with mcl (goto_slot)", whole["mcl"],
                    "same run with truth localization", whole["truth"]))
    return rows


if __name__ == "__main__":
    print_rows(run())
