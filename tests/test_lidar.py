"""Tests for the 2-D LiDAR simulator (dfcoa_opt.world.lidar).

The grid oracle is shapely: the exact union of the occupied cell squares,
intersected with each beam segment. Discs are checked against the textbook
ray-circle formula.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

import dfcoa_opt.world.lidar as lidar_mod
from dfcoa_opt.scenario.schema import LidarSpec
from dfcoa_opt.world.grid import OccupancyGrid
from dfcoa_opt.world.lidar import LaserScan, Lidar, beam_layout, cast_grid
from dfcoa_opt.world.shapes import Polygon, Rectangle

# ----------------------------------------------------------------- helpers


def random_polygon(rng: np.random.Generator, centre, radius: float) -> Polygon:
    """A random star-shaped counter-clockwise polygon around ``centre``."""
    k = int(rng.integers(3, 8))
    ang = np.sort(rng.uniform(0.0, 2 * np.pi, k))
    rad = radius * rng.uniform(0.4, 1.0, k)
    pts = np.c_[centre[0] + rad * np.cos(ang), centre[1] + rad * np.sin(ang)]
    return Polygon(tuple(map(tuple, pts)))


def random_world(seed: int) -> tuple[OccupancyGrid, list]:
    """A grid from random rectangles and polygons plus random cell noise."""
    rng = np.random.default_rng(seed)
    res = [2.0, 3.7, 5.0, 1.3][seed % 4]
    origin = (float(rng.uniform(-5, 5)), float(rng.uniform(-5, 5))) if seed % 3 else (0.0, 0.0)
    size = (float(rng.uniform(6, 14)), float(rng.uniform(6, 14)))
    shapes: list = []
    for _ in range(int(rng.integers(2, 6))):
        x0 = origin[0] + rng.uniform(0, size[0] - 1)
        y0 = origin[1] + rng.uniform(0, size[1] - 1)
        w, h = rng.uniform(0.3, 3.0, 2)
        shapes.append(Rectangle((x0, y0), (x0 + w, y0 + h)))
    for _ in range(int(rng.integers(1, 4))):
        c = (origin[0] + rng.uniform(0, size[0]), origin[1] + rng.uniform(0, size[1]))
        shapes.append(random_polygon(rng, c, rng.uniform(0.5, 2.5)))
    grid = OccupancyGrid.from_shapes(size, res, shapes, origin)
    noise = rng.random(grid.shape) < 0.03
    return OccupancyGrid(grid.occupied | noise, res, origin), shapes


def cells_geometry(grid: OccupancyGrid):
    """Exact shapely union of the occupied cell squares."""
    rows, cols = np.nonzero(grid.occupied)
    h = grid.cell_size
    ox, oy = grid.origin
    boxes = shapely.box(ox + cols * h, oy + rows * h, ox + (cols + 1) * h, oy + (rows + 1) * h)
    return shapely.unary_union(boxes)


def beam_dirs(scan: LaserScan, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World beam directions ``(N, B)`` (same angle-sum form as the simulator)."""
    ca, sa = np.cos(scan.angles), np.sin(scan.angles)
    ct, st_ = np.cos(poses[:, 2:3]), np.sin(poses[:, 2:3])
    return ct * ca - st_ * sa, st_ * ca + ct * sa


def shapely_ranges(geom, poses: np.ndarray, ux: np.ndarray, uy: np.ndarray,
                   rmax: float) -> np.ndarray:
    """Distance to the nearest intersection of each beam segment with ``geom`` (inf: none)."""
    px = np.broadcast_to(poses[:, :1], ux.shape)
    py = np.broadcast_to(poses[:, 1:2], ux.shape)
    coords = np.stack([np.stack([px, py], -1), np.stack([px + rmax * ux, py + rmax * uy], -1)],
                      axis=-2).reshape(-1, 2, 2)
    segs = shapely.linestrings(coords)
    inter = shapely.intersection(geom, segs)
    d = shapely.distance(shapely.points(coords[:, 0]), inter)
    d = np.where(shapely.is_empty(inter), np.inf, d)
    return d.reshape(ux.shape)


def analytic_disc_ranges(poses, ux, uy, xy, r, owner):
    """Textbook nearest ray-circle hit per beam (0 inside a disc, inf on a miss)."""
    out = np.full(ux.shape, np.inf)
    for i in range(poses.shape[0]):
        for m in range(xy.shape[0]):
            if owner[m] == i:
                continue
            fx, fy = poses[i, 0] - xy[m, 0], poses[i, 1] - xy[m, 1]
            cc = fx * fx + fy * fy - r[m] ** 2
            if cc <= 0:
                out[i] = 0.0
                continue
            b = fx * ux[i] + fy * uy[i]
            disc = b * b - cc
            with np.errstate(invalid="ignore"):
                t = -b - np.sqrt(disc)
            hit = (disc >= 0) & (t >= 0)
            out[i] = np.where(hit, np.minimum(out[i], t), out[i])
    return out


def rep117(r: np.ndarray, rmin: float, rmax: float) -> np.ndarray:
    r = np.where(r > rmax, np.inf, r)
    return np.where(r < rmin, -np.inf, r)


def random_poses(rng, grid: OccupancyGrid, n: int, margin: float = 1.0) -> np.ndarray:
    x0, x1, y0, y1 = grid.extent
    return np.c_[rng.uniform(x0 - margin, x1 + margin, n), rng.uniform(y0 - margin, y1 + margin, n),
                 rng.uniform(-np.pi, np.pi, n)]


# ------------------------------------------------------------ grid oracle


@pytest.mark.parametrize("seed", range(8))
def test_grid_ranges_match_shapely(seed):
    grid, _ = random_world(seed)
    rng = np.random.default_rng(100 + seed)
    w, h = grid.size
    rmax = [0.8 * math.hypot(w, h), 3.0][seed % 2]
    fov = 4.0 if seed in (1, 3) else 2 * np.pi
    spec = LidarSpec(beams=[120, 37, 64, 90][seed % 4], fov=fov, range_max=rmax)
    lidar = Lidar(spec, grid)
    poses = random_poses(rng, grid, 25)
    scan = lidar.scan(poses)
    assert scan.ranges.shape == (25, spec.beams)
    ux, uy = beam_dirs(scan, poses)
    expected = shapely_ranges(cells_geometry(grid), poses, ux, uy, rmax)
    np.testing.assert_allclose(scan.ranges, rep117(expected, 0.0, rmax), rtol=0, atol=1e-9)
    assert np.isfinite(scan.ranges).any() and np.isinf(scan.ranges).any()


def test_grid_from_ascii_with_origin_matches_shapely():
    text = """
    ..........#.
    ..##......#.
    ..##..#.....
    ......#..###
    #...........
    """
    text = "\n".join(ln.strip() for ln in text.strip("\n").splitlines())
    grid = OccupancyGrid.from_ascii(text, resolution=2.5, origin=(-1.3, 0.7))
    lidar = Lidar(LidarSpec(beams=180, range_max=20.0), grid)
    rng = np.random.default_rng(3)
    poses = random_poses(rng, grid, 30, margin=2.0)
    scan = lidar.scan(poses)
    ux, uy = beam_dirs(scan, poses)
    expected = shapely_ranges(cells_geometry(grid), poses, ux, uy, 20.0)
    np.testing.assert_allclose(scan.ranges, expected, rtol=0, atol=1e-9)


@pytest.mark.parametrize("seed", range(4))
def test_hit_points_lie_near_original_shapes(seed):
    # A hit lies on an occupied cell whose centre is inside a shape (or is noise),
    # so it is within half a cell diagonal of the original geometry. Ranges to the
    # original polygons themselves can differ by far more for grazing beams, so
    # those are not compared.
    rng = np.random.default_rng(seed)
    grid0, shapes = random_world(seed)
    grid = OccupancyGrid.from_shapes(grid0.size, grid0.resolution, shapes, grid0.origin)
    lidar = Lidar(LidarSpec(beams=72, range_max=30.0), grid)
    poses = random_poses(rng, grid, 20)
    scan = lidar.scan(poses)
    ux, uy = beam_dirs(scan, poses)
    fin = np.isfinite(scan.ranges)
    hx = (poses[:, :1] + scan.ranges * ux)[fin]
    hy = (poses[:, 1:2] + scan.ranges * uy)[fin]
    exact = shapely.unary_union([shapely.Polygon(s.to_polygon().vertices) for s in shapes])
    d = shapely.distance(shapely.points(np.c_[hx, hy]), exact)
    assert fin.any()
    assert np.all(d <= grid.cell_size * math.sqrt(0.5) + 1e-9)


def test_skip_matches_plain_dda():
    for seed in range(6):
        grid, _ = random_world(seed)
        rng = np.random.default_rng(seed)
        lidar = Lidar(LidarSpec(beams=90, range_max=50.0), grid)
        poses = random_poses(rng, grid, 40)
        fast = lidar.scan(poses).ranges
        plain = lidar.scan(poses, skip=False).ranges
        np.testing.assert_allclose(fast, plain, rtol=0, atol=1e-9)
    # a big sparse map, where the jumps are long
    rng = np.random.default_rng(7)
    occ = rng.random((300, 300)) < 0.002
    grid = OccupancyGrid(occ, 10.0, (2.0, -3.0))
    lidar = Lidar(LidarSpec(beams=120, range_max=40.0), grid)
    poses = random_poses(rng, grid, 30)
    np.testing.assert_allclose(lidar.scan(poses).ranges, lidar.scan(poses, skip=False).ranges,
                               rtol=0, atol=1e-9)


def test_cast_grid_function():
    grid = OccupancyGrid.from_ascii("..#\n...\n...", resolution=1.0, origin=(1.0, 2.0))
    dist = np.where(grid.occupied, 0.0, grid.distance_field)
    for skip in (True, False):
        # from (1.5, 4.5) heading +x: the occupied cell starts at x = 3
        assert cast_grid(1.5, 4.5, 1.0, 0.0, 10.0, dist, 1.0, 2.0, 1.0, skip) == 1.5
        # from outside the grid, entering it
        assert cast_grid(-2.0, 4.5, 1.0, 0.0, 10.0, dist, 1.0, 2.0, 1.0, skip) == 5.0
        assert cast_grid(-2.0, 4.5, 1.0, 0.0, 4.0, dist, 1.0, 2.0, 1.0, skip) == np.inf
        assert cast_grid(3.5, 4.5, 0.0, 1.0, 10.0, dist, 1.0, 2.0, 1.0, skip) == 0.0
        assert cast_grid(1.5, 2.5, 0.0, -1.0, 10.0, dist, 1.0, 2.0, 1.0, skip) == np.inf


def test_empty_and_full_grids():
    empty = OccupancyGrid.empty((10, 10), 4.0)
    lidar = Lidar(LidarSpec(beams=16), empty)
    assert np.all(lidar.scan([[5.0, 5.0, 0.3], [50.0, -3.0, 1.0]]).ranges == np.inf)
    full = OccupancyGrid(np.ones((5, 5), bool), 1.0)
    assert np.all(Lidar(LidarSpec(beams=16), full).scan([[2.2, 2.7, 0.0]]).ranges == 0.0)
    assert np.all(Lidar(LidarSpec(beams=16, range_min=0.1), full)
                  .scan([[2.2, 2.7, 0.0]]).ranges == -np.inf)


# ----------------------------------------------------------------- discs


def test_discs_match_analytic_formula():
    rng = np.random.default_rng(11)
    grid = OccupancyGrid.empty((20, 20), 5.0)
    n, m = 12, 40
    poses = np.c_[rng.uniform(0, 20, (n, 2)), rng.uniform(-np.pi, np.pi, n)]
    xy = np.vstack([poses[:, :2], rng.uniform(0, 20, (m, 2))])
    r = np.r_[np.full(n, 0.35), rng.uniform(0.1, 1.2, m)]
    owner = np.r_[np.arange(n), np.full(m, -1)]
    for spec in (LidarSpec(beams=120, range_max=8.0), LidarSpec(beams=31, fov=2.5, range_max=30.0),
                 LidarSpec(beams=1, fov=1.0, range_max=30.0), LidarSpec(beams=2, range_max=30.0),
                 LidarSpec(beams=77, fov=6.2, range_max=30.0), LidarSpec(beams=3, range_max=9.0)):
        scan = Lidar(spec, grid).scan(poses, xy, r, owner)
        ux, uy = beam_dirs(scan, poses)
        expected = rep117(analytic_disc_ranges(poses, ux, uy, xy, r, owner), 0.0,
                          spec.range_max)
        assert np.array_equal(np.isfinite(scan.ranges), np.isfinite(expected))
        np.testing.assert_allclose(scan.ranges, expected, rtol=0, atol=1e-12)
        if spec.beams == 120:
            assert np.isfinite(scan.ranges).sum() > 50


def test_own_body_is_ignored_and_inside_disc_is_zero():
    grid = OccupancyGrid.empty((10, 10), 2.0)
    lidar = Lidar(LidarSpec(beams=60, range_max=10.0), grid)
    poses = np.array([[3.0, 3.0, 0.0], [5.0, 3.0, np.pi]])
    xy, r = poses[:, :2].copy(), np.array([0.3, 0.3])
    own = lidar.scan(poses, xy, r, np.array([0, 1])).ranges
    # each robot sees the other's body at 2 - 0.3 straight ahead (beam 30 = angle 0)
    assert own[0, 30] == pytest.approx(1.7, abs=1e-12)
    assert own[1, 30] == pytest.approx(1.7, abs=1e-12)
    alone = lidar.scan(poses[:1], xy[1:], r[1:]).ranges
    np.testing.assert_array_equal(own[:1], alone)
    # without owners both robots start inside a disc: every beam is 0 (or -inf)
    assert np.all(lidar.scan(poses, xy, r).ranges == 0.0)
    lid2 = Lidar(LidarSpec(beams=60, range_max=10.0, range_min=0.05), grid)
    assert np.all(lid2.scan(poses, xy, r).ranges == -np.inf)


def test_min_of_grid_and_discs():
    grid, _ = random_world(5)
    rng = np.random.default_rng(5)
    rmax = 12.0
    lidar = Lidar(LidarSpec(beams=90, range_max=rmax), grid)
    poses = random_poses(rng, grid, 15)
    x0, x1, y0, y1 = grid.extent
    xy = np.c_[rng.uniform(x0, x1, 25), rng.uniform(y0, y1, 25)]
    r = rng.uniform(0.1, 0.8, 25)
    owner = np.full(25, -1)
    scan = lidar.scan(poses, xy, r, owner)
    ux, uy = beam_dirs(scan, poses)
    g = shapely_ranges(cells_geometry(grid), poses, ux, uy, rmax)
    d = analytic_disc_ranges(poses, ux, uy, xy, r, owner)
    np.testing.assert_allclose(scan.ranges, rep117(np.minimum(g, d), 0.0, rmax), rtol=0,
                               atol=1e-9)
    assert (d < g).any() and (g < d).any()


def test_kdtree_candidates_match_direct(monkeypatch):
    rng = np.random.default_rng(2)
    grid = OccupancyGrid(rng.random((100, 100)) < 0.01, 1.0, (-10.0, -10.0))
    lidar = Lidar(LidarSpec(beams=45, range_max=6.0), grid)
    n, m = 150, 220
    poses = np.c_[rng.uniform(-20, 150, (n, 2)), rng.uniform(-np.pi, np.pi, n)]
    xy = np.vstack([poses[:, :2], rng.uniform(-20, 150, (m - n, 2))])
    r = rng.uniform(0.2, 1.0, m)
    owner = np.r_[np.arange(n), np.full(m - n, -1)]
    monkeypatch.setattr(lidar_mod, "CANDIDATES_MIN_PAIRS", 10**12)
    direct = lidar.scan(poses, xy, r, owner).ranges
    monkeypatch.setattr(lidar_mod, "CANDIDATES_MIN_PAIRS", 0)
    monkeypatch.setattr(lidar_mod, "CANDIDATES_MAX_FRACTION", np.inf)
    tree = lidar.scan(poses, xy, r, owner).ranges
    np.testing.assert_array_equal(direct, tree)
    assert np.isfinite(direct).any()


# ------------------------------------------------------ layout and REP-117


def test_beam_layout():
    assert beam_layout(4, 2 * np.pi) == (-np.pi, np.pi / 2)
    assert beam_layout(5, 2.0) == (-1.0, 0.5)
    assert beam_layout(1, 2.0) == (0.0, 0.0)
    grid = OccupancyGrid.empty((4, 4), 1.0)
    scan = Lidar(LidarSpec(beams=5, fov=2.0), grid).scan(np.zeros((2, 3)))
    np.testing.assert_allclose(scan.angles, [-1.0, -0.5, 0.0, 0.5, 1.0])
    full = Lidar(LidarSpec(beams=8), grid).scan(np.zeros((1, 3)))
    assert full.angles[0] == -np.pi and full.angles[-1] < np.pi - 1e-6
    assert full.take(np.array([0])).ranges.shape == (1, 8)


def test_beams_centred_on_heading():
    # a wall 3 m ahead (x in [6, 7)); the middle beam (angle 0) hits it at 3 - 0.5 = 2.5
    occ = np.zeros((10, 10), bool)
    occ[:, 6] = True
    grid = OccupancyGrid(occ, 1.0)
    for spec in (LidarSpec(beams=9, fov=1.0), LidarSpec(beams=8)):
        scan = Lidar(spec, grid).scan([[3.5, 5.2, 0.0], [5.2, 3.5, np.pi / 2]])
        k = int(np.argmin(np.abs(scan.angles)))
        assert scan.angles[k] == 0.0
        assert scan.ranges[0, k] == pytest.approx(2.5, abs=1e-12)
        assert scan.ranges[1, k] == np.inf  # facing +y along the free column 5


def test_range_limits_rep117():
    grid, _ = random_world(2)
    rng = np.random.default_rng(9)
    poses = random_poses(rng, grid, 20, margin=0.0)
    base = Lidar(LidarSpec(beams=60, range_max=100.0), grid).scan(poses).ranges
    cut = Lidar(LidarSpec(beams=60, range_min=0.7, range_max=2.5), grid).scan(poses).ranges
    fin = np.isfinite(base)
    near = fin & (base < 0.7)
    far = ~fin | (base > 2.5)
    assert near.any() and far.any()
    assert np.all(cut[near] == -np.inf)
    assert np.all(cut[far] == np.inf)
    mid = ~near & ~far
    np.testing.assert_array_equal(cut[mid], base[mid])


# ------------------------------------------------------------------ noise


def test_noise_is_deterministic_and_clipped():
    grid, _ = random_world(1)
    spec = LidarSpec(beams=60, range_min=0.2, range_max=4.0, noise_std=0.3)
    lidar = Lidar(spec, grid)
    poses = random_poses(np.random.default_rng(0), grid, 10, margin=0.0)
    a = lidar.scan(poses, rng=np.random.default_rng(42)).ranges
    b = lidar.scan(poses, rng=np.random.default_rng(42)).ranges
    c = lidar.scan(poses, rng=np.random.default_rng(43)).ranges
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    exact = Lidar(LidarSpec(beams=60, range_min=0.2, range_max=4.0), grid).scan(poses).ranges
    np.testing.assert_array_equal(np.isinf(a), np.isinf(exact))
    np.testing.assert_array_equal(a[np.isinf(a)], exact[np.isinf(exact)])
    fin = np.isfinite(a)
    assert np.all((a[fin] >= 0.2) & (a[fin] <= 4.0))
    assert np.any(a[fin] != exact[fin])
    # one normal draw over the whole (N, B) array
    g = np.random.default_rng(42)
    noise = g.normal(0.0, 0.3, size=a.shape)
    np.testing.assert_allclose(a[fin], np.clip(exact + noise, 0.2, 4.0)[fin], atol=0, rtol=0)
    with pytest.raises(ValueError, match="rng"):
        lidar.scan(poses)


def test_no_noise_leaves_rng_untouched():
    grid = OccupancyGrid.empty((4, 4), 1.0)
    g = np.random.default_rng(1)
    state = g.bit_generator.state
    Lidar(LidarSpec(beams=8), grid).scan(np.zeros((1, 3)), rng=g)
    assert g.bit_generator.state == state


def test_input_validation():
    lidar = Lidar(LidarSpec(beams=8), OccupancyGrid.empty((4, 4), 1.0))
    with pytest.raises(ValueError):
        lidar.scan(np.zeros((3, 2)))
    with pytest.raises(ValueError):
        lidar.scan([[np.nan, 0.0, 0.0]])
    with pytest.raises(ValueError):
        lidar.scan(np.zeros((1, 3)), discs_xy=np.zeros((1, 2)))
    with pytest.raises(ValueError):
        lidar.scan(np.zeros((1, 3)), np.zeros((1, 2)), np.array([-1.0]))
    assert lidar.scan(np.zeros((0, 3))).ranges.shape == (0, 8)


# ------------------------------------------------------------- property


_WORLDS = [random_world(s)[0] for s in range(4)]


@settings(max_examples=60, deadline=None)
@given(world=st.integers(0, 3), fx=st.floats(-0.1, 1.1), fy=st.floats(-0.1, 1.1),
       theta=st.floats(-math.pi, math.pi), rmax=st.floats(0.5, 30.0))
def test_ranges_bounded_by_clearance_and_range_max(world, fx, fy, theta, rmax):
    grid = _WORLDS[world]
    x0, x1, y0, y1 = grid.extent
    pose = np.array([[x0 + fx * (x1 - x0), y0 + fy * (y1 - y0), theta]])
    scan = Lidar(LidarSpec(beams=48, range_max=rmax), grid).scan(pose)
    r = scan.ranges[0]
    fin = np.isfinite(r)
    assert not np.any(r == -np.inf)
    assert np.all(r[fin] <= rmax)
    clear = float(grid.clearance(pose[:, :2], cap=1e3)[0])
    assert np.all(r[fin] >= clear - 1e-9)
    # every hit point lies on the boundary of an occupied square
    ux, uy = beam_dirs(scan, pose)
    hits = np.c_[pose[0, 0] + r[fin] * ux[0, fin], pose[0, 1] + r[fin] * uy[0, fin]]
    assert np.all(grid.clearance(hits, cap=1e3) <= 1e-9)


def test_disc_candidates_are_exactly_the_discs_within_reach():
    rng = np.random.default_rng(5)
    pts = rng.uniform(-30.0, 70.0, (300, 2))
    xy = np.vstack([pts[:100], rng.uniform(0.0, 40.0, (400, 2))])  # some points outside
    reach = 4.2
    ptr, idx = lidar_mod.disc_candidates(pts, xy, reach)
    d = np.linalg.norm(pts[:, None] - xy[None], axis=-1)
    for i in range(len(pts)):
        np.testing.assert_array_equal(idx[ptr[i]:ptr[i + 1]], np.flatnonzero(d[i] <= reach))
    assert ptr[-1] == (d <= reach).sum() > len(pts)
