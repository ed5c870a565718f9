"""The numba path of the improved VFH* gives the NumPy reference's exact bits.

``VFHStar(kernel=True)``, :func:`blend_fast`, :func:`wrap_angles` and the
scalar helpers of :mod:`dfcoa_opt.control.dfcoa.histogram` against :func:`vfh_step`,
:func:`blend`, :func:`dfcoa_opt.core.geometry.wrap_angle` and ``np.clip``.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from dfcoa_opt.control.base import Neighbours
from dfcoa_opt.control.dfcoa.histogram import (
    VFHParams,
    sector1,
    sector_index,
    wrap_angles,
)
from dfcoa_opt.control.dfcoa.vfh_star import VFHStar, blend, blend_fast
from dfcoa_opt.core.geometry import wrap_angle
from dfcoa_opt.core.scalar_kernels import clip1, wrap1
from dfcoa_opt.world.lidar import LaserScan

PI = math.pi


def same_bits(a, b) -> bool:
    """Equal shapes and bits (any NaN matches any NaN)."""
    a, b = np.asarray(a), np.asarray(b)
    if a.shape != b.shape or a.dtype != b.dtype:
        return False
    if a.dtype.kind != "f":
        return bool(np.array_equal(a, b))
    return bool(np.all((a.view(np.uint64) == b.view(np.uint64)) | (np.isnan(a) & np.isnan(b))))


def angle_samples(rng: np.random.Generator) -> np.ndarray:
    """Random angles plus every boundary the wrap and the sector rounding have."""
    mult = np.arange(-60, 61) * PI
    grid = np.arange(-120, 121) * (PI / 25)  # sector edges and centres for K = 25, 50
    edges = np.concatenate([mult, grid])
    special = [0.0, -0.0, np.inf, -np.inf, np.nan, 1e300, -1e300, 5e-324, -5e-324, 1e16, -1e16]
    return np.concatenate([special, edges, np.nextafter(edges, np.inf),
                           np.nextafter(edges, -np.inf), rng.uniform(-10, 10, 20000),
                           rng.uniform(-1e5, 1e5, 2000)])


def test_wrap_is_bit_identical_to_geometry():
    x = angle_samples(np.random.default_rng(0))
    with np.errstate(invalid="ignore"):
        want = wrap_angle(x)
        assert same_bits(wrap_angles(x), want)
        assert same_bits(wrap_angles(x.reshape(-1, 3)[:, 1]), want.reshape(-1, 3)[:, 1])
        assert same_bits(wrap_angles(x[7]), wrap_angle(x[7]))  # 0-d keeps its shape
        assert same_bits(np.array([wrap1(v) for v in x]), want)


@pytest.mark.parametrize("lo, hi", [(0.0, 1.0), (-1.5, 1.5), (0.0, 0.3), (-0.0, 0.0)])
def test_clip_is_np_clip(lo, hi):
    x = np.concatenate([angle_samples(np.random.default_rng(1))[:3000], [lo, hi, -lo, -hi]])
    got = np.array([clip1(v, lo, hi) for v in x])
    assert same_bits(got, np.clip(x, lo, hi))


@pytest.mark.parametrize("k", [25, 8, 36])
def test_sector_of_an_angle_is_sector_index(k):
    x = angle_samples(np.random.default_rng(2))
    x = x[np.isfinite(x) & (np.abs(x) < 1e6)]
    scale = k / (2.0 * np.pi)
    got = np.array([sector1(v, scale, k) for v in x])
    np.testing.assert_array_equal(got, sector_index(x, k))


# ------------------------------------------------------------- whole steps


def random_inputs(rng: np.random.Generator, n: int, beams: int, m: int, params: VFHParams,
                  exact: bool):
    """A scan with every kind of range, neighbours around and odd targets.

    ``exact``: ranges, neighbour offsets and targets from small sets, so that sums
    hit the thresholds, distances hit ``d_safe`` and targets hit sector edges exactly.
    """
    k = params.num_sectors
    if exact:
        ranges = rng.choice([0.5, 1.0, 2.0, 4.0], (n, beams))
    else:
        ranges = rng.uniform(0.0, 4.0, (n, beams))
    kinds = rng.integers(0, 12, (n, beams))
    ranges[kinds == 0] = np.inf
    ranges[kinds == 1] = -np.inf
    ranges[kinds == 2] = np.nan
    ranges[kinds == 3] = rng.uniform(0.0, 0.05, (kinds == 3).sum())  # below the lower limit
    ranges[kinds == 4] = 3.5  # exactly the upper limit
    fov = rng.choice([2 * PI, 1.5 * PI, PI])
    scan = LaserScan(-fov / 2, fov / beams, 0.03, 8.0, ranges)
    pose = np.column_stack((rng.uniform(-5, 5, (n, 2)), rng.uniform(-7, 7, n)))
    if exact:
        pose[:, :2] = rng.integers(-4, 5, (n, 2))
        pose[::2, 2] = rng.integers(-k, k + 1, len(pose[::2])) * (PI / k)
        off = rng.choice([0.0, params.d_safe, -params.d_safe, 3.0, -4.0], (n, m, 2))
    else:
        off = rng.normal(0.0, 3.0, (n, m, 2))
    pos = pose[:, None, :2] + off
    idx = np.where(rng.random((n, m)) < 0.8, rng.integers(0, n, (n, m)), -1)
    nb = Neighbours(idx, pos, np.zeros((n, m, 2)), np.hypot(off[..., 0], off[..., 1]))
    target = rng.uniform(-PI, PI, n)
    if exact:
        target = rng.integers(-k, k + 1, n) * (PI / k)  # sector centres and edges
    odd = rng.integers(0, 6, n)
    target[odd == 0] = np.nan
    target[odd == 1] = rng.uniform(-20, 20, (odd == 1).sum())  # unwrapped
    target[odd == 2] = PI
    target[odd == 3] = -PI
    return scan, nb, pose, target


PARAMS = [
    VFHParams(robot_radius=0.2),
    VFHParams(robot_radius=0.2, use_turning_mask=False, num_sectors=36),
    VFHParams(robot_radius=0.15, min_turning_radius=0.5, histogram_thresholds=(1.0, 3.0),
              obstacle_weight=0.0, previous_weight=0.0, d_safe=2.0),
    VFHParams(obstacle_weight=1.7, target_weight=3.3, current_weight=0.7, previous_weight=1.9,
              repulsive_gain=0.3, d_safe=3.0, histogram_thresholds=(1.0, 4.0)),
    VFHParams(num_sectors=8, target_weight=0.0, current_weight=0.0, histogram_thresholds=(0.0,
                                                                                          0.0)),
]


def assert_same_result(a, b):
    for f in dataclasses.fields(a):
        assert same_bits(getattr(a, f.name), getattr(b, f.name)), f.name


@pytest.mark.filterwarnings("ignore:overflow encountered")  # thresholds (0, 0)
@pytest.mark.parametrize("params", PARAMS)
@pytest.mark.parametrize("with_neighbours", [True, False])
@pytest.mark.parametrize("exact", [True, False])
def test_kernel_step_is_the_reference_step(params, with_neighbours, exact):
    rng = np.random.default_rng([params.num_sectors, with_neighbours, exact])
    n, beams, m = 8, int(rng.choice([36, 120, 361])), 5
    fast, ref = VFHStar(params, n, kernel=True), VFHStar(params, n, kernel=False)
    for t in range(16):  # several steps: hysteresis and the previous direction matter
        scan, nb, pose, target = random_inputs(rng, n, beams, m, params, exact)
        nb = nb if with_neighbours else None
        rows = None
        if t % 3 == 2:  # a sub-observation of some robots, in another order
            rows = rng.permutation(n)[:4]
            scan, pose, target = scan.take(rows), pose[rows], target[rows]
            nb = None if nb is None else nb.take(rows)
        assert_same_result(fast.step(scan, nb, pose, target, rows),
                           ref.step(scan, nb, pose, target, rows))
        assert same_bits(fast.binary, ref.binary)
        assert same_bits(fast.previous_world, ref.previous_world)


def test_kernel_step_on_threshold_and_distance_ties():
    """Histograms exactly at the thresholds, neighbours exactly at d_safe, target at -pi."""
    p = VFHParams(histogram_thresholds=(1.0, 4.0), d_safe=2.0, repulsive_gain=0.5)
    fast, ref = VFHStar(p, 2, kernel=True), VFHStar(p, 2, kernel=False)
    pose = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, PI / 2]])
    nb = Neighbours(np.array([[1, -1], [0, 1]]), np.array([[[2.0, 0.0], [0.0, 0.0]],
                                                           [[1.0, -1.0], [1.0, 0.0]]]),
                    np.zeros((2, 2, 2)), np.ones((2, 2)))
    for d in (0.3, 0.5, 1.0, 0.5, 2.0, 1.0, 4.0):  # w = 1/d^2 crosses 4 and 1, and sits on them
        ranges = np.full((2, 8), np.inf)
        ranges[:, 0] = d
        scan = LaserScan(-PI, PI / 4, 0.0, 8.0, ranges)
        assert_same_result(fast.step(scan, nb, pose, [-PI, 0.0]),
                           ref.step(scan, nb, pose, [-PI, 0.0]))


def test_kernel_step_without_scan_and_bad_rows():
    p = VFHParams()
    fast, ref = VFHStar(p, 2), VFHStar(p, 2, kernel=False)
    pose = np.array([[0.0, 0.0, 0.3], [1.0, 1.0, -3.0]])
    assert_same_result(fast.step(None, None, pose, [0.2, np.nan]),
                       ref.step(None, None, pose, [0.2, np.nan]))
    scan = LaserScan(-PI, PI / 2, 0.0, 8.0, np.ones((3, 4)))
    with pytest.raises(ValueError, match="same number of rows"):
        fast.step(scan, None, pose, [0.0, 0.0])


def test_blend_fast_is_blend():
    rng = np.random.default_rng(5)
    n = 4000
    u = rng.normal(0.0, 1.0, (n, 2))
    u[::7] = -0.0
    u[3::11, 0] = np.nan
    th = rng.uniform(-4, 4, n)
    th[::5] = np.nan
    th[1::13] = 0.0
    danger = rng.uniform(-0.5, 1.5, n)
    danger[::3] = rng.choice([0.0, 1.0, -0.0], n)[::3]
    for p in (VFHParams(), VFHParams(avoid_speed=0.0, w_max=0.2, heading_gain=7.0)):
        assert same_bits(blend_fast(u, th, danger, p), blend(u, th, danger, p))
