"""Benchmark: 2-D LiDAR scans (dfcoa_opt.world.lidar) against simpler ray casters.

Run ``python -m benchmarks.bench_lidar``. Each row times one call with
``time.perf_counter`` after a warm-up call (numba compilation excluded), cycling
over the same random free poses for the simulator and its reference, in
interleaved repetitions (:mod:`benchmarks.timing`).
"""

from __future__ import annotations

import numpy as np

from benchmarks.timing import REPS, interleave, print_rows, row
from dfcoa_opt.world.grid import OccupancyGrid
from dfcoa_opt.world.lidar import Lidar, LidarSpec
from dfcoa_opt.world.shapes import Rectangle

SIZE_M = 35.0
RESOLUTION = 10.0  # cells per metre -> 350 x 350 cells
N_RECTS = 15
BEAMS = 120
SAMPLES = 400
#: Calls per interleaved repetition (REPS of them make SAMPLES).
PER_REP = SAMPLES // REPS


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


def run() -> list[dict]:
    """Time the scans; returns one dict per configuration."""
    grid = make_grid()
    poses = free_poses(grid, 64)
    singles = [poses[k:k + 1] for k in range(len(poses))]
    rows = []
    for rmax in (10.0, 50.0):
        lidar = Lidar(LidarSpec(beams=BEAMS, range_max=rmax), grid)
        angles = lidar.scan(poses[:1]).angles
        t = interleave({
            "fast": (lambda k, lid=lidar: lid.scan(singles[k % len(singles)]), PER_REP),
            "plain": (lambda k, lid=lidar: lid.scan(singles[k % len(singles)], skip=False),
                      PER_REP),
            "ref": (lambda k, a=angles, r=rmax: numpy_sampling_scan(
                grid, poses[k % len(poses)], a, r), PER_REP)})
        what = f"lidar scan {BEAMS} beams, 350x350 grid, range_max {rmax:g} m"
        rows.append(row(what, t["fast"], "numpy ray sampling (half-cell steps)", t["ref"]))
        rows.append(row(what, t["fast"], "numba DDA without distance-field skipping",
                        t["plain"]))

    # the simulator's use: 4 robots, their bodies (own one excluded) and 2 moving discs
    lidar = Lidar(LidarSpec(beams=BEAMS, range_max=10.0), grid)
    four = [poses[k:k + 4] for k in range(0, 60, 4)]
    extra = np.array([[10.0, 10.0], [20.0, 25.0]])
    discs = [np.vstack([p[:, :2], extra]) for p in four]
    radii = np.r_[np.full(4, 0.3), 0.5, 0.5]
    owner = np.r_[np.arange(4), -1, -1]
    t = interleave({
        "fast": (lambda k: lidar.scan(four[k % 15], discs[k % 15], radii, owner), PER_REP),
        "plain": (lambda k: lidar.scan(four[k % 15], discs[k % 15], radii, owner, skip=False),
                  PER_REP)})
    rows.append(row("lidar scan 4 robots + 6 discs, 120 beams, 350x350 grid, range_max 10 m",
                    t["fast"], "numba DDA without distance-field skipping", t["plain"]))

    # a large swarm: 1000 robots and 1000 discs (every robot's body), 35 m and 300 m worlds
    body_r = np.full(1000, 0.3)
    body_owner = np.arange(1000)
    for side in (SIZE_M, 300.0):
        many = free_poses(grid, 1000) * [side / SIZE_M, side / SIZE_M, 1.0]
        xy = np.ascontiguousarray(many[:, :2])
        t = interleave({
            "fast": (lambda k, p=many, c=xy: lidar.scan(p, c, body_r, body_owner), 3),
            "plain": (lambda k, p=many, c=xy: lidar.scan(p, c, body_r, body_owner, skip=False),
                      3)})
        rows.append(row(f"lidar scan 1000 robots + 1000 discs, {side:g} m world, 350x350 grid",
                        t["fast"], "numba DDA without distance-field skipping", t["plain"]))
    return rows


if __name__ == "__main__":
    print_rows(run())
