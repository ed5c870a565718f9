"""Hypothesis property tests across the toolkit (planning, sensing, ORCA, safe mode).

Each property is checked against an oracle that shares no code with the unit under
test: scipy's Dijkstra for A*, shapely distances to the original (unrasterised)
shapes for the LiDAR, the ``qpsolvers`` path for the exact ORCA solver, and pairwise
centre distances recomputed from the positions for the safe discrete-time mode.
"Every robot model respects its limits" lives in ``tests/test_robots.py``.

Two bugs these properties found are pinned by plain tests: the exact ORCA solver
on lines that coincide up to rounding, and the simulator's safe mode with fewer
neighbours in the table than robots within one step's reach.
"""

from __future__ import annotations

import math

import numba
import numpy as np
import pytest
import shapely
from hypothesis import assume, event, given, settings, target
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from comparisons.orca import safe
from comparisons.orca.crowd import goal_velocities
from comparisons.orca.ellipse import polygon_segments
from comparisons.orca.lp import FEASIBLE, LEAST_VIOLATION, SOLVER_FAIL, solve_lines
from comparisons.orca.neighbours import knn_within
from comparisons.orca.qp import solve_lines_qp
from comparisons.orca.velocities import orca_velocities
from dfcoa_opt.planning.astar import search
from dfcoa_opt.sim.loader import scenario_from_dict
from dfcoa_opt.sim.log import STATUS_FALLBACK
from dfcoa_opt.sim.schema import LidarSpec
from dfcoa_opt.sim.simulator import run_scenario
from dfcoa_opt.world.grid import OccupancyGrid
from dfcoa_opt.world.lidar import Lidar
from dfcoa_opt.world.shapes import Circle, Polygon, Rectangle
from tests.test_astar import assert_valid_moves, dijkstra_cost
from tests.test_orca_qp import _batch, _unique_minimax, _viol

TWO_PI = 2.0 * math.pi
HALF_DIAG = math.sqrt(0.5)  # half a cell diagonal, in cells
VEL_TOL = 1e-6  # m/s, ORCA solver agreement (tests/test_orca_qp.py)


@pytest.fixture(autouse=True, scope="module")
def _one_numba_thread():
    """Run the numba ``prange`` kernels on one thread in this module (restored after).

    The examples are tiny (<= 12 robots), and on a loaded 2-core machine every parallel
    region waits for a descheduled thread: measured 3 s with one thread against 24-84 s
    with two for the same 150 crowd examples. Rows are independent, so results agree.
    """
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    yield
    numba.set_num_threads(before)


# ------------------------------------------------------------------ 1. A* vs Dijkstra
@st.composite
def grid_problems(draw):
    """A bool map up to 20 x 20, a start and a goal cell (mostly free, sometimes blocked)."""
    shape = draw(st.tuples(st.integers(1, 20), st.integers(1, 20)))
    if draw(st.booleans()):  # hypothesis' own mix: open maps with a few blocked cells, etc.
        occ = draw(arrays(np.bool_, shape))
    else:  # every cell drawn, density 0 .. 60 %
        level = draw(st.integers(0, 6))
        occ = draw(arrays(np.int8, shape, elements=st.integers(0, 9), fill=st.nothing())) < level
    free = [(int(r), int(c)) for r, c in np.argwhere(~occ)] or [(0, 0)]
    anywhere = st.tuples(st.integers(0, shape[0] - 1), st.integers(0, shape[1] - 1))
    cell = st.one_of(st.sampled_from(free), st.sampled_from(free), anywhere)
    return occ, draw(cell), draw(cell)


@settings(max_examples=300, deadline=None)
@given(problem=grid_problems(), heuristic=st.sampled_from(["octile", "euclidean"]),
       corner_cutting=st.booleans())
def test_astar_path_is_free_and_as_short_as_dijkstra(problem, heuristic, corner_cutting):
    """A* finds a path iff Dijkstra does; the path has Dijkstra's cost, starts at the start,
    ends at the goal, stays inside the grid on free cells, moves between 8-neighbours
    without squeezing between (or, by default, cutting) blocked corners, and its summed
    step lengths equal the reported cost."""
    occ, s, g = problem
    res = search(occ, s, g, heuristic=heuristic, corner_cutting=corner_cutting)
    # a blocked start or goal has no path (scipy would give 0 for a blocked start == goal)
    ref = math.inf if occ[s] or occ[g] else dijkstra_cost(occ, s, g, corner_cutting)
    assert res.found == math.isfinite(ref)
    if not res.found:
        assert res.cells.shape == (0, 2) and math.isinf(res.cost)
        return
    cells = res.cells
    assert abs(res.cost - ref) <= 1e-9
    assert tuple(cells[0]) == s and tuple(cells[-1]) == g
    assert (cells >= 0).all() and (cells < np.array(occ.shape)).all()  # no negative wrap
    assert_valid_moves(occ, cells, corner_cutting=corner_cutting)
    assert len({tuple(c) for c in cells.tolist()}) == len(cells)  # optimal: no revisits
    length = float(np.hypot(*np.diff(cells, axis=0).T).sum())
    assert abs(length - res.cost) <= 1e-9


# ------------------------------------------------------------------ 2. LiDAR bounds
def _circle(origin, size):
    return st.builds(lambda fx, fy, r: Circle((origin[0] + fx * size[0],
                                               origin[1] + fy * size[1]), r),
                     st.floats(0.0, 1.0), st.floats(0.0, 1.0), st.floats(0.01, 1.5))


def _rectangle(origin, size):
    def build(fx, fy, w, h):
        x, y = origin[0] + fx * size[0], origin[1] + fy * size[1]
        return Rectangle((x, y), (x + w, y + h))

    return st.builds(build, st.floats(0.0, 1.0), st.floats(0.0, 1.0), st.floats(0.01, 2.0),
                     st.floats(0.01, 2.0))


@st.composite
def _polygon(draw, origin, size):
    """A counter-clockwise polygon, star-shaped about its centre (angular gaps < pi)."""
    k = draw(st.integers(3, 7))
    gaps = np.array(draw(st.lists(st.floats(1.0, 1.9), min_size=k, max_size=k)))
    ang = draw(st.floats(0.0, TWO_PI)) + np.cumsum(gaps) / gaps.sum() * TWO_PI
    rad = np.array(draw(st.lists(st.floats(0.02, 2.0), min_size=k, max_size=k)))
    cx = origin[0] + draw(st.floats(0.0, 1.0)) * size[0]
    cy = origin[1] + draw(st.floats(0.0, 1.0)) * size[1]
    pts = np.c_[cx + rad * np.cos(ang), cy + rad * np.sin(ang)]
    try:
        return Polygon(tuple(map(tuple, pts.tolist())))
    except ValueError:  # a rounding-level sliver
        assume(False)


@st.composite
def shape_worlds(draw):
    """Random discs, rectangles and polygons rasterised like the loader (``with_shapes``)."""
    res = draw(st.floats(1.0, 6.0))
    origin = (draw(st.floats(-5.0, 5.0)), draw(st.floats(-5.0, 5.0)))
    size = (draw(st.floats(3.0, 10.0)), draw(st.floats(3.0, 10.0)))
    one = st.one_of(_circle(origin, size), _rectangle(origin, size), _polygon(origin, size))
    shapes = draw(st.lists(one, min_size=1, max_size=5))
    grid = OccupancyGrid.empty(size, res, origin).with_shapes(shapes)
    return grid, shapes


def exact_distance(points: np.ndarray, shapes) -> np.ndarray:
    """Shapely distance from each point to the union of the original shapes (0 inside).

    Circles use ``distance(point, centre) - r`` (exact; a buffered polygon is not).
    """
    pts = shapely.points(np.asarray(points, dtype=float).reshape(-1, 2))
    out = np.full(len(pts), np.inf)
    for s in shapes:
        if isinstance(s, Circle):
            d = np.maximum(shapely.distance(pts, shapely.Point(s.center)) - s.radius, 0.0)
        else:
            d = shapely.distance(pts, shapely.Polygon(s.to_polygon().vertices))
        out = np.minimum(out, d)
    return out


lidar_specs = st.builds(
    lambda beams, fov, rmax, rmin: LidarSpec(beams=beams, fov=fov, range_max=rmax,
                                             range_min=min(rmin, rmax)),
    st.integers(1, 360), st.one_of(st.just(TWO_PI), st.floats(0.1, TWO_PI)),
    st.floats(0.3, 25.0), st.one_of(st.just(0.0), st.floats(0.0, 0.3)))
pose_fractions = st.lists(st.tuples(st.floats(-0.15, 1.15), st.floats(-0.15, 1.15),
                                    st.floats(-math.pi, math.pi)), min_size=1, max_size=4)


def world_poses(grid: OccupancyGrid, fractions) -> np.ndarray:
    x0, x1, y0, y1 = grid.extent
    f = np.array(fractions, dtype=float)
    return np.c_[x0 + f[:, 0] * (x1 - x0), y0 + f[:, 1] * (y1 - y0), f[:, 2]]


def assert_range_bounds(scan, lower: np.ndarray, spec: LidarSpec) -> float:
    """Finite ranges lie in ``[range_min, range_max]`` and above ``lower`` (one per pose).

    Returns the largest ``lower - range`` (how close the bound came to failing).
    """
    r = scan.ranges
    assert not np.isnan(r).any()
    fin = np.isfinite(r)
    assert np.all(r[fin] <= spec.range_max) and np.all(r[fin] >= spec.range_min)
    below = np.where(fin, lower[:, None] - r, -np.inf).max(initial=-np.inf)
    assert below <= 1e-9, (below, r, lower)
    return float(below)


@settings(max_examples=200, deadline=None)
@given(world=shape_worlds(), spec=lidar_specs, fractions=pose_fractions)
def test_lidar_range_within_max_and_above_exact_distance_minus_half_diagonal(world, spec,
                                                                              fractions):
    """Every finite range is <= range_max and >= the shapely distance from the sensor to the
    union of the original shapes minus half a cell *diagonal* (sqrt(2)/2 cell).

    Half a cell is not enough: a cell is occupied when its centre lies inside a shape
    (``with_shapes``), so its corners can be up to sqrt(2)/2 cell from the shape, and a
    beam arriving along the diagonal stops at such a corner. With ``0.5`` instead of
    sqrt(2)/2 this test fails within a few hundred examples (0.507 cell for a
    rectangle seen from the grid's corner); a rectangle whose corner lies just past a
    cell centre gives 0.693 cell, a tiny disc on a cell centre tends to 0.707 cell
    (:func:`test_half_cell_is_not_a_bound_but_half_a_diagonal_is`).
    """
    grid, shapes = world
    poses = world_poses(grid, fractions)
    dist = exact_distance(poses[:, :2], shapes)
    outside = dist > 1e-9
    assume(outside.any())
    poses, dist = poses[outside], dist[outside]
    scan = Lidar(spec, grid).scan(poses)
    assert scan.ranges.shape == (len(poses), spec.beams)
    slack = HALF_DIAG * grid.cell_size
    below = assert_range_bounds(scan, dist - slack, spec) + slack  # most a range is below dist
    if np.isfinite(below):  # steer the search towards the worst case
        target(below * grid.resolution, label="range below the exact distance, cells")


@pytest.mark.parametrize(("shape", "sensor", "beam"), [
    # a rectangle whose corner lies 0.01 cell past a cell centre, seen along the diagonal
    (Rectangle((1.49, 1.49), (3.0, 3.0)), (0.0, 0.0), 0.25 * math.pi),
    # a tiny disc on a cell centre: the gap tends to sqrt(2)/2 cell as r -> 0
    (Circle((0.5, 0.5), 1e-3), (2.5, 2.5), -0.75 * math.pi),
])
@pytest.mark.parametrize(("h", "origin"), [(1.0, (0.0, 0.0)), (0.5, (-1.3, 2.1))])
def test_half_cell_is_not_a_bound_but_half_a_diagonal_is(shape, sensor, beam, h, origin):
    """The bound above is tight: the occupied cell's corner sticks out of the shape by up
    to half a diagonal, and a beam along the diagonal stops there, more than half a cell
    short of the shape. (Cases in cells; scaled by ``h`` and shifted by ``origin``.)"""
    def world(xy):
        return (origin[0] + h * xy[0], origin[1] + h * xy[1])

    if isinstance(shape, Circle):
        shape = Circle(world(shape.center), h * shape.radius)
    else:
        shape = Rectangle(world(shape.min), world(shape.max))
    grid = OccupancyGrid.empty((4.0 * h, 4.0 * h), 1.0 / h, origin).with_shapes([shape])
    pose = [[*world(sensor), beam]]
    hit = Lidar(LidarSpec(beams=1, fov=1.0, range_max=10.0), grid).scan(pose).ranges[0, 0]
    # the beam ends on the corner of an occupied cell (which sticks out of the shape)
    u = np.array([math.cos(beam), math.sin(beam)])
    corner = np.array(world(sensor)) + hit * u
    cell_xy = (corner - np.array(origin)) / h
    np.testing.assert_allclose(cell_xy, np.round(cell_xy), atol=1e-9)
    assert grid.is_occupied_at(corner + 1e-6 * h * u) and not grid.is_occupied_at(
        corner - 1e-6 * h * u)
    gap = float(exact_distance(np.array(world(sensor)), [shape])[0]) - hit
    assert 0.5 * h < gap <= HALF_DIAG * h  # "minus half a cell" would fail here


@settings(max_examples=150, deadline=None)
@given(world=shape_worlds(), spec=lidar_specs, fractions=pose_fractions,
       body=st.floats(0.05, 0.5),
       discs=st.lists(st.tuples(st.floats(-0.15, 1.15), st.floats(-0.15, 1.15),
                                st.floats(0.02, 1.2)), min_size=1, max_size=6),
       with_map=st.booleans())
def test_lidar_disc_ranges_never_below_exact_distance(world, spec, fractions, body, discs,
                                                      with_map):
    """With robots' bodies and moving discs: a robot never sees its own body, and every
    finite range is >= the exact distance to the other discs (no half-cell slack for
    discs) and to the map (half a diagonal, as above), and <= range_max."""
    grid, shapes = world
    if not with_map:
        grid, shapes = OccupancyGrid.empty(grid.size, grid.resolution, grid.origin), []
    poses = world_poses(grid, fractions)
    x0, x1, y0, y1 = grid.extent
    dxy = np.array([(x0 + fx * (x1 - x0), y0 + fy * (y1 - y0)) for fx, fy, _ in discs])
    drad = np.array([r for *_, r in discs])
    # robots stand outside the moving discs, the shapes and each other's bodies
    keep = gap_to_discs(poses[:, :2], dxy, drad).min(axis=1) > 1e-9
    if shapes:
        keep &= exact_distance(poses[:, :2], shapes) > 1e-9
    for i in range(len(poses)):
        earlier = np.flatnonzero(keep[:i])
        if keep[i] and earlier.size:
            keep[i] = gap_to_discs(poses[i:i + 1, :2], poses[earlier, :2], body).min() > 1e-9
    assume(keep.any())
    poses = poses[keep]
    n = len(poses)
    xy = np.vstack((poses[:, :2], dxy))
    rad = np.r_[np.full(n, body), drad]
    owner = np.r_[np.arange(n), np.full(len(dxy), -1)]
    to_disc = gap_to_discs(poses[:, :2], xy, rad)
    to_disc[np.arange(n), np.arange(n)] = np.inf  # not the robot's own body
    d_map = exact_distance(poses[:, :2], shapes) if shapes else np.full(n, np.inf)
    scan = Lidar(spec, grid).scan(poses, xy, rad, owner)
    assert_range_bounds(scan, np.minimum(to_disc.min(axis=1),
                                         d_map - HALF_DIAG * grid.cell_size), spec)


def gap_to_discs(points: np.ndarray, centres: np.ndarray, radii) -> np.ndarray:
    """``(P, M)`` shapely centre distances minus the radii: exact distance to each disc."""
    d = shapely.distance(shapely.points(points)[:, None], shapely.points(centres)[None, :])
    return d - np.broadcast_to(np.asarray(radii, dtype=float), (len(centres),))[None, :]


# ------------------------------------------------------------------ 3. exact vs QP ORCA
def _unit(angle):
    return np.stack([np.cos(angle), np.sin(angle)], -1)


def _left(d):
    return np.stack([-d[..., 1], d[..., 0]], -1)


angles = st.floats(0.0, TWO_PI)


@st.composite
def orca_instances(draw):
    """One robot's lines ``(p, d, n_hard, pref, v_max, kind)``.

    Kinds: 'feasible' (every line keeps a strictly feasible ``v0`` inside the disc),
    'infeasible' (soft lines face away from a point with normals 'all round', so no
    velocity satisfies them) and 'random' (either). Hard lines always contain 0 (and
    ``v0``), as the solvers require.
    """
    kind = draw(st.sampled_from(["feasible", "infeasible", "random"]))
    v_max = draw(st.floats(0.5, 2.0))
    pref = _unit(draw(angles)) * v_max * draw(st.floats(0.0, 1.6))
    v0 = _unit(draw(angles)) * v_max * draw(st.floats(0.0, 0.8))
    if kind == "infeasible":
        v0 = np.zeros(2)
    n_hard = draw(st.integers(0, 3))
    hd = _unit(np.array(draw(st.lists(angles, min_size=n_hard, max_size=n_hard))))
    hn = _left(hd).reshape(-1, 2)
    eps = np.array(draw(st.lists(st.floats(1e-3, 0.3), min_size=n_hard, max_size=n_hard)))
    hp = (np.minimum(0.0, hn @ v0) - eps * v_max)[:, None] * hn
    if kind == "feasible":
        k = draw(st.integers(1, 8))
        d = _unit(np.array(draw(st.lists(angles, min_size=k, max_size=k))))
        n = _left(d)
        u = np.array(draw(st.lists(st.floats(0.0, 1.0), min_size=k, max_size=k)))
        m = np.maximum(n @ (v0 - pref), 0.0) * u + np.array(
            draw(st.lists(st.floats(1e-3, 0.2), min_size=k, max_size=k)))
        p = v0 - m[:, None] * n
    elif kind == "infeasible":
        k = draw(st.integers(3, 8))
        gaps = np.array(draw(st.lists(st.floats(1.0, 1.9), min_size=k, max_size=k)))
        n = _unit(draw(angles) + np.cumsum(gaps) / gaps.sum() * TWO_PI)  # gaps < pi
        d = np.stack([n[:, 1], -n[:, 0]], -1)  # allowed side n . v >= n . p
        c = _unit(draw(angles)) * v_max * draw(st.floats(0.0, 0.5))
        s = np.array(draw(st.lists(st.floats(0.05, 1.0), min_size=k, max_size=k)))
        p = c + (s * v_max)[:, None] * n
    else:
        k = draw(st.integers(1, 8))
        d = _unit(np.array(draw(st.lists(angles, min_size=k, max_size=k))))
        p = np.array(draw(st.lists(st.tuples(st.floats(-1.5, 1.5), st.floats(-1.5, 1.5)),
                                   min_size=k, max_size=k))) * v_max
    return np.vstack([hp, p]), np.vstack([hd.reshape(-1, 2), d]), n_hard, pref, v_max, kind


@settings(max_examples=150, deadline=None)
@given(instances=st.lists(orca_instances(), min_size=1, max_size=3))
def test_exact_orca_solver_agrees_with_qp_solver(instances):
    """The incremental LP and the qpsolvers path give the same status; on feasible lines
    the same velocity to 1e-6 m/s, all lines kept, inside the speed disc; on infeasible
    lines the same largest soft violation to 1e-6 m/s with the hard lines kept, and the
    same velocity whenever the least-violation optimum is unique (KKT check).

    Lines that coincide up to rounding are included (``lp.COINCIDENT``, pinned by the two
    tests below). Draws where the reference path gives up (its documented
    SOLVER_FAIL; seen on lines parallel to 1e-7 rad, ~0.1 % of the draws) have no verdict.
    """
    args = _batch([inst[:5] for inst in instances])
    v_lp, st_lp, sl_lp = solve_lines(*args)
    v_qp, st_qp, sl_qp = solve_lines_qp(*args)
    assume(SOLVER_FAIL not in st_qp.tolist())
    assert st_lp.tolist() == st_qp.tolist()
    assert np.abs(sl_lp - sl_qp).max() < VEL_TOL
    for r, (p, d, h, _, vm, kind) in enumerate(instances):
        assert kind != "feasible" or st_lp[r] == FEASIBLE
        assert kind != "infeasible" or st_lp[r] == LEAST_VIOLATION
        for v in (v_lp[r], v_qp[r]):
            assert np.linalg.norm(v) <= vm + 1e-9
            assert (_viol(p[:h], d[:h], v) < 1e-9).all()  # hard lines kept
        if st_lp[r] == FEASIBLE:
            event(f"feasible, on the speed circle: {np.linalg.norm(v_lp[r]) > vm - 1e-9}")
            assert np.abs(v_lp[r] - v_qp[r]).max() < VEL_TOL, (v_lp[r], v_qp[r])
            assert (_viol(p, d, v_lp[r]) < 1e-9).all()
            continue
        soft_lp, soft_qp = _viol(p, d, v_lp[r])[h:].max(), _viol(p, d, v_qp[r])[h:].max()
        assert soft_lp > 0.0 and abs(soft_lp - soft_qp) < VEL_TOL, (soft_lp, soft_qp)
        unique = _unique_minimax(p, d, h, v_lp[r], vm)
        event(f"least violation, unique optimum: {unique}")
        if unique:
            assert np.abs(v_lp[r] - v_qp[r]).max() < VEL_TOL, (v_lp[r], v_qp[r])


def test_exact_solver_with_a_repeated_hard_line_finds_the_least_violation():
    """One hard line given twice (two points of the same line) and the soft lines x >= 0.5,
    x <= -0.5: the least largest violation is 0.5 (at x = 0, allowed by the hard line);
    with the hard line given once the exact solver finds it."""
    n = np.array([math.cos(math.radians(42.0)), math.sin(math.radians(42.0))])
    d = np.array([n[1], -n[0]])  # allowed side: n . v >= -0.25
    p0 = -0.25 * n
    P = np.array([[p0, p0 + 0.3 * d, [0.5, 0.0], [-0.5, 0.0]]])
    D = np.array([[d, d, [0.0, -1.0], [0.0, 1.0]]])
    once = solve_lines(P[:, 1:], D[:, 1:], [3], [1], np.zeros((1, 2)), [1.0])
    assert once[1][0] == LEAST_VIOLATION and once[2][0] == pytest.approx(0.5, abs=1e-12)
    v, status, _ = solve_lines(P, D, [4], [2], np.zeros((1, 2)), [1.0])
    assert status[0] == LEAST_VIOLATION
    assert _viol(P[0], D[0], v[0])[2:].max() == pytest.approx(0.5, abs=VEL_TOL)


def test_exact_solver_next_to_a_polygon_vertex_projects_the_preferred_velocity():
    """A robot 0.35 m from a polygon vertex, heading at it at 1 m/s: the next-step lines
    of the two edges that meet there (:func:`comparisons.orca.safe.segment_safety_lines`)
    are the same line up to rounding, so the answer is the projection of ``pref`` onto
    it (0.59 m/s towards the vertex). With RVO2's rule (any negative offset between
    parallel lines is disjoint) the solver reported an infeasible program and returned
    -pref, full speed away, in 1.7 % of random near-vertex poses."""
    poly = np.array([[-0.3461204806526232, 1.3721200456761626],
                     [-0.5680939257997316, 1.3421475952636726],
                     [-2.1563531602437305, -0.40994689720298677],
                     [-0.18925762508166485, -2.5641901441184194]])
    pos = np.array([[-2.5025591146169472, -0.3776398859986534]])
    pref = np.array([[0.9956741710337624, -0.09291364343426692]])
    r, dt = 0.2, 0.25
    hp, hd, hc = safe.segment_safety_lines(pos, np.array([r]), np.array([1.0]), dt,
                                           polygon_segments([poly]).reshape(-1, 2, 2))
    assert hc[0] == 2
    np.testing.assert_allclose(hp[0, 0], hp[0, 1], atol=1e-15)
    # the constraint n . v >= (r - dist) / dt, with n from the vertex to the robot
    vertex = poly[2]
    dist = float(np.linalg.norm(pos[0] - vertex))
    n = (pos[0] - vertex) / dist
    expected = pref[0] + max(0.0, (r - dist) / dt - n @ pref[0]) * n
    assert np.linalg.norm(expected) < 1.0
    v, status, _ = solve_lines(hp, hd, hc, hc, pref, np.array([1.0]))
    assert status[0] == FEASIBLE
    np.testing.assert_allclose(v[0], expected, atol=1e-9)


# ------------------------------------------------------------------ 4. safe discrete mode
@st.composite
def crowds(draw):
    """``(start (N, 2), goals (N, 2), radius)``: equal discs on a jittered lattice, apart.

    Lattice spacing ``2 r (1 + gap)``; each robot moves by less than half the spare
    distance over sqrt 2 per axis, so no two start discs overlap. Goals cross: the
    mirror image through the centre, a permutation of the starts, or anywhere nearby.
    """
    n = draw(st.integers(2, 12))
    r = draw(st.floats(0.1, 0.5))
    m = math.ceil(math.sqrt(n))
    spacing = 2.0 * r * (1.0 + draw(st.floats(1e-3, 0.5)))
    cells = draw(st.permutations(range(m * m)))[:n]
    base = np.array([(c % m, c // m) for c in cells], dtype=float) * spacing
    jit = (spacing - 2.0 * r) / (2.0 * math.sqrt(2.0)) * 0.99
    noise = np.array(draw(st.lists(st.tuples(st.floats(-1, 1), st.floats(-1, 1)),
                                   min_size=n, max_size=n)))
    start = 10.0 + base - base.mean(axis=0) + jit * noise
    mode = draw(st.sampled_from(["mirror", "swap", "random"]))
    if mode == "mirror":
        goals = 2.0 * start.mean(axis=0) - start
    elif mode == "swap":
        goals = start[np.array(draw(st.permutations(range(n))))]
    else:
        goals = 10.0 + np.array(draw(st.lists(st.tuples(st.floats(-3, 3), st.floats(-3, 3)),
                                              min_size=n, max_size=n)))
    return start, goals, r


def min_pair_distance(pos: np.ndarray) -> float:
    """Smallest centre distance over all pairs of ``(..., N, 2)`` positions."""
    d = np.linalg.norm(pos[..., :, None, :] - pos[..., None, :, :], axis=-1)
    n = pos.shape[-2]
    d[..., np.arange(n), np.arange(n)] = np.inf
    return float(d.min())


@settings(max_examples=150, deadline=None)
@given(crowd=crowds(), v_max=st.floats(0.5, 2.0), dt=st.floats(0.1, 0.25),
       tau=st.floats(0.5, 10.0), max_neighbors=st.integers(1, 10))
def test_safe_mode_crowd_never_overlaps(crowd, v_max, dt, tau, max_neighbors):
    """RVO2-style crowd stepping (single integrator, ``p += v dt``) with the safe mode's
    hard lines (:func:`comparisons.orca.safe.robot_safety_lines`, symmetric radius query)
    before the ORCA lines and :func:`~comparisons.orca.safe.scale_into` after the solve:
    every new velocity keeps its hard lines and the speed limit, and after each of 40
    steps no two discs overlap (centre distance >= 2 r - 1e-9), however few ORCA
    neighbours each robot takes."""
    start, goals, r = crowd
    pos, vel = start.copy(), np.zeros_like(start)
    n = len(pos)
    radius, vmax = np.full(n, r), np.full(n, v_max)
    assert min_pair_distance(pos) >= 2 * r
    closest = math.inf
    for _ in range(40):
        idx, count = knn_within(pos, max_neighbors, 15.0)
        hp, hd, hc = safe.robot_safety_lines(pos, radius, vmax, dt)
        pref = goal_velocities(pos, goals) * v_max
        new, _, _ = orca_velocities(pos, vel, radius, np.take(pos, idx, axis=0),
                                    np.take(vel, idx, axis=0), np.full(idx.shape, r), count,
                                    pref, vmax, tau, dt, hp, hd, hc)
        new, _ = safe.scale_into(new, hp, hd, hc)
        assert (np.linalg.norm(new, axis=1) <= v_max + 1e-9).all()
        for i in range(n):
            assert (_viol(hp[i, :hc[i]], hd[i, :hc[i]], new[i]) <= 1e-12).all()
        pos, vel = pos + new * dt, new
        closest = min(closest, min_pair_distance(pos))
        assert closest >= 2 * r - 1e-9
    event(f"closest approach within 1 % of contact: {closest < 2.02 * r}")


def crowd_scenario(start, goals, r, v_max, dt, steps, max_neighbors, tau=2.0, seed=1):
    """A single-integrator team whose formation slots are ``goals`` (the leader barely
    moves: start (10, 10), 0.02 m/s), running ``goto_slot+orca`` in safe discrete mode."""
    lead = np.array([10.0, 10.0])
    data = {
        "name": "crowd", "dt": dt, "t_max": steps * dt, "seed": seed,
        "world": {"size": [20.0, 20.0], "resolution": 10},
        "robots": {"model": "single_integrator", "radius": r, "v_max": v_max, "w_max": 3.0},
        "team": {"n": len(start), "placement": "explicit",
                 "poses": [[float(x), float(y), 0.0] for x, y in start]},
        "formation": {"shape": "offsets",
                      "offsets": [[float(x), float(y)] for x, y in goals - lead]},
        "leader": {"start": [10.0, 10.0], "goal": [10.6, 10.0], "speed": 0.02,
                   "goal_radius": 0.1},
        "sensors": {"lidar": {"enabled": False}, "max_neighbors": max_neighbors},
        "controllers": {"orca": {"safe_discrete": True, "time_horizon": tau}},
    }
    return scenario_from_dict(data, "<crowd>")


@settings(max_examples=60, deadline=None)
@given(crowd=crowds(), v_max=st.floats(0.5, 2.0), dt=st.floats(0.1, 0.25),
       tau=st.floats(0.5, 10.0))
def test_safe_mode_in_the_simulator_never_overlaps(crowd, v_max, dt, tau):
    """``goto_slot+orca`` with ``safe_discrete = true`` on single integrators: at every
    logged step (``log.pose``, 40 steps) no two robots overlap and no speed exceeds
    ``v_max``, when every robot knows all others (``max_neighbors = N - 1``; the filter's
    pair lines come from the neighbour table, see the test below)."""
    start, goals, r = crowd
    sc = crowd_scenario(start, goals, r, v_max, dt, 40, max_neighbors=len(start) - 1, tau=tau)
    log = run_scenario(sc, "goto_slot+orca")
    assert log.pose.shape[0] == 41
    np.testing.assert_allclose(log.pose[0, :, :2], start, atol=1e-12)
    per_step = [min_pair_distance(pose[:, :2]) for pose in log.pose]
    closest = min(per_step)
    event(f"closest approach within 1 % of contact: {closest < 2.02 * r}")
    assert closest >= 2 * r - 1e-9
    np.testing.assert_allclose(log.min_inter_robot, per_step, rtol=0, atol=1e-12)
    assert np.linalg.norm(log.velocity, axis=-1).max() <= v_max + 1e-9
    # not log.collision_events: the simulator's contact test is a strict d < 2 r, and the
    # safe mode may leave two robots touching to rounding (d = 2 r - 4e-16 was seen)


def test_safe_mode_with_fewer_neighbours_than_robots_in_reach_never_overlaps():
    """Robots 0 - 1 - 2 on a line, max_neighbors = 1: robot 1's only neighbour is robot 2,
    so without a fallback only robot 0 keeps the 0-1 pair apart and robot 1 walked into it
    (0.52 m < 0.6 m after one step). A robot whose full table may hide a robot in reach
    now stops for the step, counted as a fallback."""
    r, dt = 0.3, 0.1
    start = np.array([[9.38, 10.0], [10.0, 10.0], [10.61, 10.0]])
    goals = np.array([[14.0, 10.0], [6.0, 10.0], [14.0, 10.0]])
    log = run_scenario(crowd_scenario(start, goals, r, 1.0, dt, 10, max_neighbors=1),
                       "goto_slot+orca")
    assert min(min_pair_distance(pose[:, :2]) for pose in log.pose) >= 2 * r - 1e-9
    assert (log.filter_status == STATUS_FALLBACK).any()
