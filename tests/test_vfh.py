"""Tests for the improved VFH* module (dfcoa_opt.control.dfcoa.histogram), paper 000 Algorithm 1."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dfcoa_opt.control.base import Neighbours
from dfcoa_opt.control.dfcoa.histogram import (
    VFHParams,
    binary_histogram,
    polar_histogram,
    repulsion_histogram,
    sector_centres,
    sector_index,
    select_direction,
    turning_mask,
)
from dfcoa_opt.control.dfcoa.vfh_star import VFHStar, blend, danger_level, vfh_step
from dfcoa_opt.core.errors import ScenarioError
from dfcoa_opt.core.params import build
from dfcoa_opt.scenario.schema import LidarSpec
from dfcoa_opt.world.grid import OccupancyGrid
from dfcoa_opt.world.lidar import LaserScan, Lidar

P = VFHParams(robot_radius=0.2)  # the simulator's default body radius
K = P.num_sectors
DTH = 2 * math.pi / K


def grid_with(blocks, size=(8.0, 8.0), res=10) -> OccupancyGrid:
    """ASCII grid with '#' rectangles ``(x0, y0, x1, y1)`` in m (cell-aligned)."""
    w, h = round(size[0] * res), round(size[1] * res)
    rows = [["."] * w for _ in range(h)]
    for x0, y0, x1, y1 in blocks:
        for r in range(round(y0 * res), round(y1 * res)):
            for c in range(round(x0 * res), round(x1 * res)):
                rows[h - 1 - r][c] = "#"  # ASCII is top row first
    return OccupancyGrid.from_ascii("\n".join("".join(r) for r in rows), res)


def lidar(grid: OccupancyGrid, beams: int = 120) -> Lidar:
    return Lidar(LidarSpec(beams=beams, range_max=8.0), grid)


def no_neighbours(n: int) -> Neighbours:
    return Neighbours(np.full((n, 0), -1), np.zeros((n, 0, 2)), np.zeros((n, 0, 2)),
                      np.zeros((n, 0)))


def one_return(d: float, angle: float, beams: int = 360) -> LaserScan:
    """A scan with a single return at ``angle`` (a beam direction) and range ``d``."""
    amin, inc = -math.pi, 2 * math.pi / beams
    r = np.full((1, beams), np.inf)
    r[0, round((angle - amin) / inc)] = d
    return LaserScan(amin, inc, 0.0, 10.0, r)


def step(scan, pose, target, params=P, nb=None, prev=None):
    n = len(pose)
    prev_b = np.zeros((n, params.num_sectors), bool) if prev is None else prev
    return vfh_step(scan, nb, pose, target, params, prev_b, np.full(n, np.nan))


# ------------------------------------------------------------- real LiDAR scenes


def test_wall_ahead_blocks_forward_and_turns_away():
    # wall x in [3, 3.3], y in [1, 5]; robot 0.8 m in front of it, heading +x
    lid = lidar(grid_with([(3.0, 1.0, 3.3, 5.0)]))
    pose = np.array([[2.2, 3.0, 0.0]])
    res = step(lid.scan(pose), pose, [0.0])
    assert res.binary[0, 0] and res.masked[0, 0]  # straight ahead blocked
    assert res.found[0] and abs(res.direction[0]) > math.radians(30)
    assert res.min_distance[0] == pytest.approx(0.8)
    # the chosen sector is free and its direction is among the free sector centres
    assert not res.masked[0, sector_index(res.direction[0], K)]


def test_wall_longer_on_the_left_turns_right():
    lid = lidar(grid_with([(3.0, 2.5, 3.3, 7.5)]))  # robot at y = 3: wall mostly to the left
    pose = np.array([[2.2, 3.0, 0.0], [2.4, 3.0, 0.0]])  # 0.8 m and 0.6 m from it
    res = step(lid.scan(pose), pose, [0.0, 0.0])
    assert res.masked[:, 0].all() and np.all(res.direction < -math.radians(20))
    assert res.direction[1] < res.direction[0]  # closer: denser histogram, sharper turn


def test_rotated_robot_gives_the_same_robot_frame_answer():
    lid = lidar(grid_with([(3.0, 1.0, 3.3, 5.0)]))
    a = step(lid.scan(np.array([[2.2, 3.0, 0.0]])), np.array([[2.2, 3.0, 0.0]]), [0.0])
    # the same scene rotated by +90 deg: wall above the robot, robot heading +y
    lid_r = lidar(grid_with([(1.0, 3.0, 5.0, 3.3)]))
    pose_r = np.array([[3.0, 2.2, math.pi / 2]])
    b = step(lid_r.scan(pose_r), pose_r, [0.0])
    np.testing.assert_array_equal(a.masked, b.masked)
    assert abs(a.direction[0]) == pytest.approx(abs(b.direction[0]))


def test_free_space_steers_to_target_exactly():
    lid = lidar(OccupancyGrid.empty((8.0, 8.0), 10))
    pose = np.array([[4.0, 4.0, 0.3], [2.0, 2.0, -2.0], [6.0, 6.0, 3.0]])
    target = np.array([0.3, -2.5, 1.234])
    res = step(lid.scan(pose), pose, target, nb=no_neighbours(3))
    assert not res.masked.any() and np.all(res.histogram == 0.0)
    np.testing.assert_array_equal(res.direction, target)
    assert np.all(np.isinf(res.min_distance)) and np.all(res.danger == 0.0)


def test_closer_disc_gives_larger_histogram():
    lid = lidar(OccupancyGrid.empty((8.0, 8.0), 10))
    pose = np.array([[2.0, 4.0, 0.0], [2.0, 4.0, 0.0]])
    scan = lid.scan(pose, discs_xy=[[3.3, 4.0], [4.3, 4.0]], discs_r=[0.3, 0.3],
                    owner=[1, 0])  # robot 0 sees only the near disc, robot 1 the far one
    res = step(scan, pose, [0.0, 0.0])
    assert res.min_distance == pytest.approx([1.0, 2.0])
    assert res.histogram[0, 0] > 3.0 * res.histogram[1, 0] > 0.0


# ------------------------------------------------------------- histogram pieces


def test_single_return_has_weight_one_over_d_squared():
    for d in (0.4, 1.0, 2.5):
        h = polar_histogram(one_return(d, 0.0).ranges, one_return(d, 0.0).angles, P)
        assert h[0, 0] == pytest.approx(1.0 / d**2, rel=1e-15)
        assert set(np.unique(h)) <= {0.0, 1.0 / d**2}


def test_returns_outside_distance_limits_are_ignored_or_clamped():
    p = VFHParams(distance_limits=(0.1, 2.0))
    far = one_return(2.5, 0.0)
    assert not polar_histogram(far.ranges, far.angles, p).any()
    close = one_return(-np.inf, 0.0)  # REP-117: closer than range_min -> at the lower limit
    assert polar_histogram(close.ranges, close.angles, p).max() == pytest.approx(100.0)


@pytest.mark.parametrize("d", [0.25, 0.35, 0.6, 1.3, 3.0])
@pytest.mark.parametrize("beta", [0.0, 0.1, -1.0, 3.1])
def test_enlargement_blocks_the_sectors_the_enlarged_obstacle_touches(d, beta):
    scan = one_return(d, beta, beams=3600)
    b = scan.angles[np.isfinite(scan.ranges[0])][0]
    gamma = math.asin(min(1.0, 0.3 / d))  # r + s = 0.2 + 0.1
    got = np.nonzero(polar_histogram(scan.ranges, scan.angles, P)[0])[0]
    # oracle: sectors hit by densely sampled directions within gamma of the return
    phi = b + np.linspace(-gamma, gamma, 20001)
    assert set(got) == set(sector_index(phi, K).tolist())
    if abs(b) < 1e-12:  # centred return: 2 floor(gamma/dth + 1/2) + 1 sectors
        assert len(got) == 2 * math.floor(gamma / DTH + 0.5) + 1


def test_enlargement_is_half_circle_inside_robot_plus_safety():
    scan = one_return(0.2, 0.0)  # d < r + s: gamma = pi/2
    got = np.nonzero(polar_histogram(scan.ranges, scan.angles, P)[0])[0]
    assert len(got) == 2 * math.floor((math.pi / 2) / DTH + 0.5) + 1


def test_hysteresis_keeps_previous_value_between_thresholds():
    h = np.array([[25.0, 10.0, 2.0, 5.0, 20.0]])
    for prev in (np.zeros((1, 5), bool), np.ones((1, 5), bool)):
        b = binary_histogram(h, prev, (5.0, 20.0))
        assert b[0, 0] and not b[0, 2]
        np.testing.assert_array_equal(b[0, 1:2], prev[0, 1:2])
        np.testing.assert_array_equal(b[0, 3:], prev[0, 3:])  # equality keeps too


def test_hysteresis_through_the_stateful_wrapper():
    p = VFHParams(num_sectors=8, distance_limits=(0.05, 5.0), histogram_thresholds=(0.5, 2.0),
                  use_turning_mask=False)
    v = VFHStar(p, 1)
    pose = np.zeros((1, 3))
    near, mid = one_return(0.5, math.pi / 2, 8), one_return(1.0, math.pi / 2, 8)  # 4, 1
    assert not v.step(mid, None, pose, [0.0]).binary[0, 2]
    assert v.step(near, None, pose, [0.0]).binary[0, 2]
    assert v.step(mid, None, pose, [0.0]).binary[0, 2]  # 1 is between: stays blocked
    v.reset()
    assert not v.step(mid, None, pose, [0.0]).binary[0, 2]


def test_repulsion_hits_exactly_the_bearing_sector():
    pose = np.array([[1.0, 1.0, math.pi / 2], [0.0, 0.0, 0.0]])
    pos = np.array([[[1.0, 3.0], [1.0 - 3.0, 1.0], [0.0, 0.0]],   # ahead 2 m, left 3 m, pad
                    [[9.0, 0.0], [0.0, -8.5], [0.0, 0.0]]])      # both at d >= d_safe
    mask = np.array([[True, True, False], [True, True, False]])
    h = repulsion_histogram(pose, pos, mask, P)
    expect = np.zeros((2, K))
    expect[0, 0] = 3.5 * (8.5 - 2.0)
    expect[0, sector_index(math.pi / 2, K)] = 3.5 * (8.5 - 3.0)
    np.testing.assert_allclose(h, expect, rtol=1e-15)
    nb = Neighbours(np.where(mask, 1, -1), pos, np.zeros_like(pos), np.ones((2, 3)))
    res = step(None, pose, [0.0, 0.0], nb=nb)  # goes through vfh_step; no scan
    np.testing.assert_allclose(res.histogram, expect, rtol=1e-15)
    assert res.binary[0, 0] and res.direction[0] != 0.0  # 22.75 > 20: ahead is blocked


def test_turning_mask_blocks_beyond_a_close_side_obstacle():
    p = VFHParams(min_turning_radius=0.5, robot_radius=0.2)
    scan = one_return(0.6, -math.pi / 2)  # 0.6 m to the right, inside the right circle reach
    m = turning_mask(scan.ranges, scan.angles, p)[0]
    c = sector_centres(K)
    assert np.all(m[c - DTH / 2 < -math.pi / 2])  # every sector reaching right of it
    assert not m[np.abs(c) < 1.0].any() and not m[c > 0].any()
    assert not turning_mask(one_return(3.0, -math.pi / 2).ranges, scan.angles, p).any()


def test_no_candidate_gives_nan():
    d = select_direction(np.ones((2, K), bool), np.zeros((2, K)), [0.0, 1.0], [np.nan] * 2, P)
    assert np.all(np.isnan(d))


def test_cost_prefers_low_density_and_previous_direction():
    masked = np.ones((1, K), bool)
    masked[0, [3, K - 3]] = False  # two symmetric free sectors, target blocked
    h = np.zeros((1, K))
    h[0, 3] = 10.0
    assert select_direction(masked, h, [0.0], [np.nan], P)[0] == pytest.approx(-3 * DTH)
    h[0, 3] = 0.0
    assert select_direction(masked, h, [0.0], [0.6], P)[0] == pytest.approx(3 * DTH)


# ------------------------------------------------------------- distributedness


def test_rows_are_independent():
    lid = lidar(grid_with([(3.0, 1.0, 3.3, 5.0), (5.0, 5.5, 6.0, 7.0)]))
    pose = np.array([[2.2, 3.0, 0.1], [4.5, 4.5, 2.0], [2.6, 2.6, -0.5]])
    pos = pose[:, :2]
    scan = lid.scan(pose, pos, np.full(3, 0.2), np.arange(3))
    idx = np.array([[2, 1], [2, 0], [0, 1]])
    nb = Neighbours(idx, pos[idx], np.zeros((3, 2, 2)),
                    np.linalg.norm(pos[idx] - pos[:, None], axis=2))
    target = np.array([0.0, -1.0, 0.4])
    full = VFHStar(P, 3)
    alone = [VFHStar(P, 1) for _ in range(3)]
    for _ in range(3):  # several steps so the hysteresis state matters
        r = full.step(scan, nb, pose, target)
        for i in range(3):
            rows = np.array([i])
            ri = alone[i].step(scan.take(rows), nb.take(rows), pose[rows], target[rows])
            for name in ("direction", "min_distance", "danger", "histogram", "masked"):
                np.testing.assert_array_equal(getattr(ri, name)[0], getattr(r, name)[i])


# ------------------------------------------------------------- safety-layer blend


def test_danger_ramp():
    d = danger_level([np.inf, 1.0, 0.75, 0.5, 0.1], P)
    np.testing.assert_allclose(d, [0.0, 0.0, 0.5, 1.0, 1.0])


def test_blend_far_is_formation_and_close_is_vfh():
    u = np.array([[0.3, 0.2], [0.5, -0.4], [0.2, 0.1]])
    th = np.array([0.4, -1.2, np.nan])
    np.testing.assert_array_equal(blend(u, th, np.zeros(3), P), u)
    v = blend(u, th, np.ones(3), P)
    np.testing.assert_allclose(v[0], [0.3 * math.cos(0.4), 2.0 * 0.4])
    np.testing.assert_allclose(v[1], [0.3 * math.cos(1.2), -1.5])  # speed cap, w_max clip
    np.testing.assert_allclose(v[2], [0.0, 0.1])  # no candidate: stop, keep turning
    half = blend(u, th, np.full(3, 0.5), P)
    np.testing.assert_allclose(half, 0.5 * (u + v))


def test_blend_with_a_real_scan_near_and_far():
    lid = lidar(grid_with([(3.0, 1.0, 3.3, 5.0)]))
    pose = np.array([[2.6, 3.0, 0.0], [0.5, 3.0, 0.0]])  # 0.4 m and 2.5 m from the wall
    res = step(lid.scan(pose), pose, [0.0, 0.0])
    np.testing.assert_array_equal(res.danger, [1.0, 0.0])
    u = np.array([[0.3, 0.0], [0.3, 0.0]])
    out = blend(u, res.direction, res.danger, P)
    np.testing.assert_array_equal(out[1], u[1])
    assert abs(out[0, 1]) > 0.5 and out[0, 0] < 0.3


def test_params_validation_and_previous_direction_frame():
    with pytest.raises(ScenarioError, match="histogram_thresholds"):
        build(VFHParams, {"histogram_thresholds": [20, 5]}, "x.toml", "vfh")
    with pytest.raises(ScenarioError, match="blend_full"):
        build(VFHParams, {"blend_full": 2.0}, "x.toml")
    v = VFHStar(P, 1)
    v.step(None, None, np.array([[0.0, 0.0, 0.0]]), [0.5])
    assert v.previous_world[0] == pytest.approx(0.5)
    v.step(None, None, np.array([[0.0, 0.0, 1.0]]), [0.3])
    assert v.previous_world[0] == pytest.approx(1.3)
