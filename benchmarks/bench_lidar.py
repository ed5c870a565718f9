"""Benchmark: 2-D LiDAR scans (dfcoa_opt.world.lidar) against simpler ray casters.

Run ``python -m benchmarks.bench_lidar``. Each row times one call with
``time.perf_counter`` after a warm-up call (numba compilation excluded), cycling
over the same random free poses for the simulator and its reference.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from dfcoa_opt.sim.schema import LidarSpec
from dfcoa_opt.world.grid import OccupancyGrid
from dfcoa_opt.world.lidar import Lidar
from dfcoa_opt.world.shapes import Rectangle

SIZE_M = 35.0
RESOLUTION = 10.0  # cells per metre -> 350 x 350 cells
N_RECTS = 15
BEAMS = 120
SAMPLES = 400


def make_grid(seed: int = 0) -> OccupancyGrid:
    """A 35 m x 35 m map at 10 cells/m with random rectangles."""
    rng = np.random.default_rng(seed)
    rects = []
    for _ in range(N_RECTS):
        x, y = rng.uniform(0.0, SIZE_M - 3.0, 2)
        w, h = rng.uniform(0.5, 3.0, 2)
        rects.append(Rectangle((x, y), (x + w, y + h)))
    return OccupancyGrid.from_shapes((SIZE_M, SIZE_M), RESOLUTION, rects)


def free_poses(grid: OccupancyGrid, n: int, seed: int = 1) -> np.ndarray:
    """``n`` random poses in free cells, ``(n, 3)``."""
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < n:
        p = np.r_[rng.uniform(0.0, SIZE_M, 2), rng.uniform(-np.pi, np.pi)]
        if not grid.is_occupied_at(p[:2]):
            out.append(p)
    return np.array(out)


def numpy_sampling_scan(grid: OccupancyGrid, pose: np.ndarray, angles: np.ndarray,
                        range_max: float) -> np.ndarray:
    """Reference: sample every beam at half-cell steps, first occupied sample wins (approximate)."""
    step = 0.5 * grid.cell_size
    t = np.arange(step, range_max + step, step)
    th = pose[2] + angles
    x = pose[0] + np.cos(th)[:, None] * t
    y = pose[1] + np.sin(th)[:, None] * t
    col = np.floor((x - grid.origin[0]) * grid.resolution).astype(np.intp)
    row = np.floor((y - grid.origin[1]) * grid.resolution).astype(np.intp)
    ok = (row >= 0) & (row < grid.shape[0]) & (col >= 0) & (col < grid.shape[1])
    hit = np.zeros(x.shape, dtype=bool)
    hit[ok] = grid.occupied[row[ok], col[ok]]
    first = hit.argmax(axis=1)
    return np.where(hit.any(axis=1), t[first], np.inf)


def time_calls(fn: Callable[[int], object], samples: int) -> np.ndarray:
    """Per-call times in us of ``fn(k)`` for ``k = 0 .. samples-1`` (after one warm-up)."""
    fn(0)
    out = np.empty(samples)
    for k in range(samples):
        t0 = time.perf_counter()
        fn(k)
        out[k] = time.perf_counter() - t0
    return out * 1e6


def print_rows(rows: list[dict]) -> None:
    """Print rows made by :func:`row`, one line each (``python -m benchmarks.bench_*``)."""
    for r in rows:
        print(f"{r['what']}: median {r['median_us']:.1f} us (min {r['min_us']:.1f}, "
              f"max {r['max_us']:.1f}, n={r['samples']}); {r['reference']}: "
              f"{r['ref_median_us']:.1f} us; ratio {r['ratio']:.2f}x")


def row(what: str, ours: np.ndarray, reference: str, ref: np.ndarray) -> dict:
    """One result row (medians, extremes and the speed-up ``ref / ours``)."""
    med, ref_med = float(np.median(ours)), float(np.median(ref))
    return {"what": what, "median_us": med, "min_us": float(ours.min()),
            "max_us": float(ours.max()), "samples": len(ours), "reference": reference,
            "ref_median_us": ref_med, "ratio": ref_med / med}


def run() -> list[dict]:
    """Time the scans; returns one dict per configuration."""
    grid = make_grid()
    poses = free_poses(grid, 64)
    singles = [poses[k:k + 1] for k in range(len(poses))]
    rows = []
    for rmax in (10.0, 50.0):
        lidar = Lidar(LidarSpec(beams=BEAMS, range_max=rmax), grid)
        angles = lidar.scan(poses[:1]).angles
        fast = time_calls(lambda k, lid=lidar: lid.scan(singles[k % len(singles)]), SAMPLES)
        plain = time_calls(lambda k, lid=lidar: lid.scan(singles[k % len(singles)], skip=False),
                           SAMPLES)
        ref = time_calls(lambda k, a=angles, r=rmax: numpy_sampling_scan(
            grid, poses[k % len(poses)], a, r), SAMPLES)
        what = f"lidar scan {BEAMS} beams, 350x350 grid, range_max {rmax:g} m"
        rows.append(row(what, fast, "numpy ray sampling (half-cell steps)", ref))
        rows.append(row(what, fast, "numba DDA without distance-field skipping", plain))

    # the simulator's use: 4 robots, their bodies (own one excluded) and 2 moving discs
    lidar = Lidar(LidarSpec(beams=BEAMS, range_max=10.0), grid)
    four = [poses[k:k + 4] for k in range(0, 60, 4)]
    extra = np.array([[10.0, 10.0], [20.0, 25.0]])
    discs = [np.vstack([p[:, :2], extra]) for p in four]
    radii = np.r_[np.full(4, 0.3), 0.5, 0.5]
    owner = np.r_[np.arange(4), -1, -1]
    fast = time_calls(lambda k: lidar.scan(four[k % 15], discs[k % 15], radii, owner), SAMPLES)
    plain = time_calls(lambda k: lidar.scan(four[k % 15], discs[k % 15], radii, owner,
                                            skip=False), SAMPLES)
    rows.append(row("lidar scan 4 robots + 6 discs, 120 beams, 350x350 grid, range_max 10 m",
                    fast, "numba DDA without distance-field skipping", plain))

    # a large swarm: 1000 robots and 1000 discs (every robot's body), 35 m and 300 m worlds
    body_r = np.full(1000, 0.3)
    body_owner = np.arange(1000)
    for side in (SIZE_M, 300.0):
        many = free_poses(grid, 1000) * [side / SIZE_M, side / SIZE_M, 1.0]
        xy = np.ascontiguousarray(many[:, :2])
        fast = time_calls(lambda k, p=many, c=xy: lidar.scan(p, c, body_r, body_owner), 15)
        plain = time_calls(lambda k, p=many, c=xy: lidar.scan(p, c, body_r, body_owner,
                                                              skip=False), 15)
        rows.append(row(f"lidar scan 1000 robots + 1000 discs, {side:g} m world, 350x350 grid",
                        fast, "numba DDA without distance-field skipping", plain))
    return rows


if __name__ == "__main__":
    print_rows(run())
