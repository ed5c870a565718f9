"""Several teams in one LiDAR call: each team sees its own robots, and its own grid."""

from __future__ import annotations

import numpy as np

from dfcoa_opt.scenario.schema import LidarSpec
from dfcoa_opt.world.grid import OccupancyGrid
from dfcoa_opt.world.lidar import Lidar

SIZE, RES, ORIGIN = (12.0, 9.0), 5.0, (-1.0, 0.5)


def noisy_grid(seed: int, size=SIZE, origin=ORIGIN) -> OccupancyGrid:
    """A grid of one geometry whose occupied cells follow ``seed``."""
    empty = OccupancyGrid.from_shapes(size, RES, [], origin)
    occupied = np.random.default_rng(seed).random(empty.shape) < 0.04
    return OccupancyGrid(occupied, RES, origin)


def team_poses(rng: np.random.Generator, teams: int, n: int) -> np.ndarray:
    x0, y0 = ORIGIN
    return np.c_[rng.uniform(x0, x0 + SIZE[0], teams * n), rng.uniform(y0, y0 + SIZE[1], teams * n),
                 rng.uniform(-np.pi, np.pi, teams * n)]


def test_teams_in_their_own_grids_get_each_grids_scan_bit_for_bit():
    spec = LidarSpec(beams=72, range_max=6.0, noise_std=0.02)
    lidars = [Lidar(spec, noisy_grid(s)) for s in range(3)]
    teams, n, radius = 5, 4, 0.2
    world = np.array([2, 0, 1, 2, 0])
    rng = np.random.default_rng(7)
    poses = team_poses(rng, teams, n)
    dyn = rng.uniform(0.0, 8.0, (teams, 2, 2))  # two moving discs per team
    dyn_r = np.array([0.3, 0.5])
    fields = Lidar.stack(lidars)
    assert fields is not None and fields.shape[0] == 3
    got = lidars[0].scan_teams(poses, n, dyn, dyn_r, radius,
                               [np.random.default_rng(s) for s in range(teams)], (fields, world))
    owners = np.r_[np.arange(n), -1, -1]
    for j in range(teams):
        rows = slice(j * n, (j + 1) * n)
        alone = lidars[world[j]].scan(poses[rows], np.vstack((poses[rows, :2], dyn[j])),
                                      np.r_[np.full(n, radius), dyn_r], owners,
                                      np.random.default_rng(j))
        assert np.array_equal(got.ranges[rows], alone.ranges)
    # the grids differ where the teams look: another grid gives other ranges
    other = lidars[0].scan_teams(poses, n, dyn, dyn_r, radius,
                                 [np.random.default_rng(s) for s in range(teams)])
    assert not np.array_equal(other.ranges[:n], got.ranges[:n])


def test_grids_of_another_geometry_or_layout_are_not_stacked():
    spec = LidarSpec(beams=36, range_max=4.0)
    base = Lidar(spec, noisy_grid(0))
    assert Lidar.stack([base, Lidar(spec, noisy_grid(1, origin=(0.0, 0.5)))]) is None
    assert Lidar.stack([base, Lidar(spec, noisy_grid(1, size=(12.0, 8.0)))]) is None
    assert Lidar.stack([base, Lidar(LidarSpec(beams=36, range_max=5.0), noisy_grid(1))]) is None
    assert Lidar.stack([base, Lidar(spec, noisy_grid(1))]) is not None
