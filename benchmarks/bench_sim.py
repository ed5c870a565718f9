"""Simulator-step and neighbour-query benchmarks.

The step is timed on a 350 x 350 grid (35 m at 10 cells/m, the size of the
DFCOA S1 map) with 4 unicycles, each with a 120-beam LiDAR (range 10 m), under
``goto_slot``. The same-run reference is the identical simulation with the
LiDAR replaced by vectorised-numpy ray sampling (``bench_lidar``).
"""

from __future__ import annotations

import time

import numpy as np

from benchmarks.bench_lidar import make_grid, numpy_sampling_scan, print_rows, row, time_calls
from dfcoa_opt.control.registry import make_controller
from dfcoa_opt.sim import neighbours
from dfcoa_opt.sim.loader import scenario_from_dict
from dfcoa_opt.sim.simulator import Simulator
from dfcoa_opt.world.lidar import LaserScan

RUNS = 9


def _scenario():
    grid = make_grid()
    ascii_map = "\n".join("".join("#" if c else "." for c in r) for r in grid.occupied[::-1])
    rows, cols = np.nonzero(~grid.inflate(1.5).occupied)
    start = grid.cell_centers()[rows[0], cols[0]]
    return scenario_from_dict({
        "t_max": 30.0, "dt": 0.1,
        "world": {"map_ascii": ascii_map, "resolution": 10.0},
        "team": {"n": 4}, "formation": {"width": 1.0, "length": 1.0},
        "leader": {"start": list(start), "goal": [34.0, 34.0], "speed": 0.3},
        "sensors": {"lidar": {"beams": 120, "range_max": 10.0}},
    }, "<bench>")


def _per_step_us(sim: Simulator) -> np.ndarray:
    out = np.empty(RUNS)
    sim.run()  # warm-up (numba compile, caches)
    for k in range(RUNS):
        log = sim.run()
        out[k] = log.meta["wall_time"] / log.meta["steps"] * 1e6
    return out


def run() -> list[dict]:
    """Time the simulator step and the neighbour query; one dict per row."""
    sc = _scenario()
    sim = Simulator(sc, make_controller("goto_slot"))
    ours = _per_step_us(sim)
    ref_sim = Simulator(sc, make_controller("goto_slot"))
    grid, lidar = sc.world.grid, ref_sim.lidar

    def numpy_lidar(poses, *args, **kwargs):
        ang = lidar.scan(poses[:1]).angles
        r = np.array([numpy_sampling_scan(grid, p, ang, 10.0) for p in poses])
        return LaserScan(ang[0], ang[1] - ang[0], 0.0, 10.0, r)

    ref_sim.lidar = type("NumpyLidar", (), {"scan": staticmethod(numpy_lidar)})()
    ref = _per_step_us(ref_sim)
    rows = [row("simulator step, 4 unicycles with 120-beam LiDAR, 350x350 grid", ours,
                "same step with numpy-sampling LiDAR", ref)]
    rng = np.random.default_rng(0)
    for n in (16, 32, 48, 64, 128):
        pts = rng.uniform(0, np.sqrt(n) * 2.0, (n, 2))
        saved = neighbours.DENSE_MAX
        try:
            neighbours.DENSE_MAX = 10**9
            dense = time_calls(lambda k, p=pts: neighbours.proximity(p, 10.0, 10, 0.4), 300)
            neighbours.DENSE_MAX = 0
            tree = time_calls(lambda k, p=pts: neighbours.proximity(p, 10.0, 10, 0.4), 300)
        finally:
            neighbours.DENSE_MAX = saved
        rows.append(row(f"neighbour query N={n}, dense matrix", dense, "cKDTree", tree))
    return rows


if __name__ == "__main__":
    t0 = time.perf_counter()
    print_rows(run())
    print(f"{time.perf_counter() - t0:.1f} s")
