"""The ``cbf`` filter and the distance-constraint builders it shares with ``nmpc``.

Oracles: shapely for the nearest points and signed distances, finite differences
for the barrier gradient, the run's own positions for the barrier guarantee,
and the qpsolvers path against the exact 2D solver.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import qpsolvers
from shapely.geometry import Point
from shapely.geometry import Polygon as ShapelyPolygon

from comparisons.constraints.distance import (
    StaticObstacles,
    barrier,
    disc_nearest,
    pair_geometry,
    polygon_nearest,
)
from dfcoa_opt import metrics
from dfcoa_opt.control.base import STATUS_FALLBACK, STATUS_SOLVER_FAIL
from dfcoa_opt.core.errors import ScenarioError
from dfcoa_opt.core.geometry import points_in_polygons
from dfcoa_opt.scenario.loader import load_scenario, scenario_from_dict
from dfcoa_opt.sim.simulator import run_scenario
from dfcoa_opt.world.shapes import Circle, Polygon, Rectangle
from tests.helpers import assert_distributed
from tests.test_orca_filter import swap_scenario

R = 0.3  # robot radius of swap_scenario, m
MARGIN = 0.05


# ------------------------------------------------------------------ builders
SHAPES = [Circle((2.0, 2.0), 1.0), Rectangle((5.0, 5.0), (7.0, 6.0)),
          Polygon(((0.0, 8.0), (3.0, 8.0), (3.0, 10.0), (2.0, 9.0), (0.0, 10.0)))]  # concave


def shapely_of(shape):
    if isinstance(shape, Circle):
        return Point(*shape.center).buffer(shape.radius, quad_segs=2048)
    return ShapelyPolygon(shape.to_polygon().as_array())


def test_nearest_points_and_signed_distances_match_shapely():
    """Every geometry: the signed distance is shapely's (negative inside), the nearest point
    lies on the boundary, ``q + delta n`` is the query point, and ``n`` is a unit vector."""
    rng = np.random.default_rng(3)
    pts = rng.uniform(-1.0, 11.0, (400, 2))
    near = StaticObstacles.from_shapes(SHAPES).nearest(pts, 3, np.inf)
    geoms = [shapely_of(s) for s in SHAPES]
    for i, p in enumerate(pts):
        ref = sorted(g.exterior.distance(Point(p)) * (-1.0 if g.contains(Point(p)) else 1.0)
                     for g in geoms)
        np.testing.assert_allclose(near.delta[i], ref, atol=2e-6)  # circle: 2048-gon
    np.testing.assert_allclose(near.point + near.delta[..., None] * near.normal,
                               np.broadcast_to(pts[:, None], near.point.shape), atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(near.normal, axis=-1), 1.0)
    on_boundary = [min(g.exterior.distance(Point(q)) for g in geoms)
                   for q in near.point.reshape(-1, 2)]
    assert max(on_boundary) < 2e-6


def test_reach_and_slot_count_leave_far_obstacles_out():
    near = StaticObstacles.from_shapes(SHAPES).nearest(np.array([[2.0, 3.5]]), 5, 1.0)
    assert near.mask.tolist() == [[True, False, False, False, False]]  # the circle, 0.5 m
    assert near.delta[0, 0] == pytest.approx(0.5) and np.isinf(near.delta[0, 1:]).all()


def test_no_obstacle_slots_fill_nothing_and_the_filter_runs():
    """max_obstacles = 0 is allowed: the kernel must not touch the empty slot arrays."""
    near = StaticObstacles.from_shapes(SHAPES).nearest(np.array([[2.0, 3.5], [0.0, 0.0]]), 0, 1.0)
    assert near.delta.shape == (2, 0) and near.mask.shape == (2, 0)
    sc = load_scenario(Path(__file__).resolve().parents[1] / "scenarios" / "example_obstacles.toml",
                       overrides={"t_max": 2.0, "controllers.cbf.max_obstacles": 0})
    assert run_scenario(sc, "goto_slot+cbf").n_steps == 21


def test_nearest_keeps_the_stable_order_of_every_shape():
    """The kernel's selection equals a stable sort of the per-shape builders' signed
    distances (discs first, then polygons; ties in that order), cut to K slots and reach.
    Mirrored shapes give exact ties with different points and normals on x = 0."""
    shapes = SHAPES + [Circle((-2.0, 2.0), 1.0), Rectangle((-7.0, 5.0), (-5.0, 6.0))]
    static = StaticObstacles.from_shapes(shapes)
    rng = np.random.default_rng(8)
    pts = np.concatenate([rng.uniform(-8.0, 11.0, (300, 2)),
                          np.column_stack((np.zeros(50), rng.uniform(-1.0, 11.0, 50)))])
    parts = [disc_nearest(pts, static.discs), polygon_nearest(pts, static.edge_a, static.edge_b)]
    q, delta, normal = (np.concatenate(x, axis=1) for x in zip(*parts, strict=True))
    assert (delta[300:, 0] == delta[300:, 1]).all()  # the ties are there
    order = np.argsort(delta, axis=1, kind="stable")
    rows = np.arange(len(pts))[:, None]
    for k, reach in ((2, np.inf), (5, 3.0), (7, 1.0)):
        near = static.nearest(pts, k, reach)
        top = order[:, :k]
        want = np.full((len(pts), k), np.inf)
        want[:, :top.shape[1]] = delta[rows, top]
        np.testing.assert_array_equal(near.mask, want <= reach)
        np.testing.assert_array_equal(near.delta, np.where(want <= reach, want, np.inf))
        found = top.shape[1]
        np.testing.assert_array_equal(near.point[:, :found], q[rows, top])
        np.testing.assert_array_equal(near.normal[:, :found], normal[rows, top])
        assert (near.normal[:, found:] == [1.0, 0.0]).all()


def test_polygon_points_on_the_boundary_follow_the_even_odd_rule():
    """On an edge, inside or outside is :func:`points_in_polygons`' decision (its strict
    ``x < x_at``): the normal is the edge's outward normal outside, its opposite inside.
    At a vertex, the first of its two edges gives the normal."""
    a = np.array([[[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]]])
    b = np.roll(a, -1, axis=1)
    mids = np.concatenate([0.5 * (a[0] + b[0]), a[0]])  # bottom, right, top, left; vertices
    outward = np.array([[0.0, -1.0], [1.0, 0.0], [0.0, 1.0], [-1.0, 0.0]])[[0, 1, 2, 3,
                                                                            0, 0, 1, 2]]
    inside = points_in_polygons(mids, a, b)[:, 0]
    _, delta, normal = polygon_nearest(mids, a, b)
    assert inside.any() and not inside.all()  # the rule is one-sided on vertical edges
    np.testing.assert_array_equal(normal[:, 0], np.where(inside[:, None], -outward, outward))
    np.testing.assert_array_equal(np.signbit(delta[:, 0]), inside)


def test_disc_builder_takes_shared_or_per_point_discs():
    pts = np.array([[0.0, 0.0], [3.0, 4.0]])
    shared = disc_nearest(pts, np.array([[3.0, 0.0, 1.0]]))
    own = disc_nearest(pts, np.array([[[3.0, 0.0, 1.0]], [[3.0, 0.0, 1.0]]]))
    for a, b in zip(shared, own, strict=True):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_allclose(shared[1][:, 0], [2.0, 3.0])
    np.testing.assert_allclose(shared[0][0, 0], [2.0, 0.0])


def test_polygon_inside_normal_points_out():
    a = np.array([[[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]]])
    q, delta, normal = polygon_nearest(np.array([[1.5, 1.0]]), a, np.roll(a, -1, axis=1))
    assert delta[0, 0] == pytest.approx(-0.5)
    np.testing.assert_allclose(normal[0, 0], [1.0, 0.0])
    np.testing.assert_allclose(q[0, 0], [2.0, 1.0])


def test_barrier_value_and_gradient_by_finite_differences():
    """h = ||p - q||^2 - D^2 outside, its gradient 2 (p - q); the same formula inside."""
    rng = np.random.default_rng(5)
    shapes = StaticObstacles.from_shapes(SHAPES[1:2])  # convex: smooth away from corners
    for p in rng.uniform(3.0, 9.0, (50, 2)):
        near = shapes.nearest(p[None], 1, np.inf)
        h, g = barrier(near.delta, near.normal, 0.4)
        eps = 1e-6
        num = [(barrier(shapes.nearest((p + e)[None], 1, np.inf).delta, near.normal, 0.4)[0]
                - barrier(shapes.nearest((p - e)[None], 1, np.inf).delta, near.normal, 0.4)[0])
               / (2 * eps) for e in (np.array([eps, 0.0]), np.array([0.0, eps]))]
        np.testing.assert_allclose(g[0, 0], np.ravel(num), atol=1e-5)
        if near.delta[0, 0] > 0:
            assert h[0, 0] == pytest.approx(np.sum((p - near.point[0, 0]) ** 2) - 0.16)


def test_pair_geometry_is_antisymmetric():
    pos = np.array([[0.0, 0.0], [3.0, 4.0]])
    d01, n01 = pair_geometry(pos[:1], pos[None, 1:])
    d10, n10 = pair_geometry(pos[1:], pos[None, :1])
    assert d01[0, 0] == d10[0, 0] == pytest.approx(5.0)
    np.testing.assert_allclose(n01, -n10)


# ------------------------------------------------------------------ the filter in runs
def min_gap(log):
    return float(log.min_inter_robot.min())


@pytest.mark.parametrize("mode", ["distributed", "centralized"])
def test_discrete_time_barrier_holds_between_robots(mode):
    """Single integrators, discrete-time mode: the pair barrier D = 2 r + margin is never
    crossed at a sampling instant (convex barrier, exact motion), in the 8-robot swap."""
    sc = swap_scenario(n=8, controllers={"cbf": {"mode": mode, "margin": MARGIN}})
    log = run_scenario(sc, "goto_slot+cbf")
    assert min_gap(log) >= 2 * R + MARGIN - 1e-7
    assert min_gap(log) < 2 * R + MARGIN + 0.02  # the barrier was active
    assert metrics.summary(log, sc)["collisions"] == 0
    plain = run_scenario(swap_scenario(n=8), "goto_slot")
    assert min_gap(plain) < 2 * R  # without the filter they collide


def test_exact_solver_agrees_with_the_qp_solver_on_every_step():
    """On every observation of a 6-robot swap (barriers active), the exact 2D solver and
    osqp give the same filtered velocity to 2e-5 m/s: the exact solver treats lines within
    RVO2's parallel test (|det| <= 1e-5) as parallel, which shows when the crowd stalls
    (~1e-5 m/s seen). Whole runs drift apart: the swap amplifies such differences."""
    from dfcoa_opt.control.registry import build_controller
    from dfcoa_opt.sim.simulator import Simulator
    from tests.helpers import Capture

    sc = swap_scenario(n=6)
    cap = Capture(build_controller("goto_slot+cbf", {}, "<t>"))
    Simulator(sc, cap).run()
    ctrls = [build_controller("goto_slot+cbf", {"cbf": {"solver": s}}, "<t>")
             for s in ("osqp", "exact")]
    for c in ctrls:
        c.reset(sc, np.random.default_rng(0))
    modified = 0
    for obs in cap.obs[::3]:
        a, b = (c.act(obs) for c in ctrls)
        np.testing.assert_allclose(a, b, atol=2e-5)
        modified += int((ctrls[1].last_result.status == 1).sum())
    assert modified > 20


def test_unicycles_keep_their_distance_and_obstacles():
    """Unicycles through the near-identity point, past a wall of a rectangle and a disc:
    no contact with robots or obstacles."""
    sc = swap_scenario(n=6, model="unicycle", controllers={"cbf": {"margin": MARGIN}},
                       world={"size": [20.0, 20.0], "resolution": 10, "obstacles": [
                           {"type": "circle", "center": [8.6, 10.0], "radius": 0.5},
                           {"type": "rectangle", "min": [11.2, 9.0], "max": [11.6, 9.6]}]})
    log = run_scenario(sc, "goto_slot+cbf")
    assert min_gap(log) >= 2 * R
    assert float((log.clearance - R).min()) >= 0.0
    assert metrics.summary(log, sc)["collisions"] == 0


def test_filter_is_distributed():
    """Distributed mode: robot i's filtered command uses row i of the observation only."""
    from dfcoa_opt.control.registry import build_controller
    from dfcoa_opt.sim.simulator import Simulator
    from tests.helpers import Capture

    sc = swap_scenario(n=6)
    cap = Capture(build_controller("goto_slot+cbf", {}, "<t>"))
    Simulator(sc, cap).run()
    ctrl = build_controller("goto_slot+cbf", {}, "<t>")
    ctrl.reset(sc, np.random.default_rng(0))
    assert_distributed(ctrl, cap.obs[40])  # mid-swap: the barriers are active


def squeezed(policy):
    """Three robots in a row 0.62 m apart with D = 2 r + 0.2 = 0.8 m: every pair is inside
    its barrier, so the middle robot must move away from both sides at once (infeasible)."""
    data = {"dt": 0.1, "t_max": 0.3, "world": {"size": [10.0, 10.0]},
            "robots": {"model": "single_integrator", "radius": R, "v_max": 1.0},
            "team": {"n": 3, "placement": "explicit",
                     "poses": [[4.38, 5.0, 0.0], [5.0, 5.0, 0.0], [5.62, 5.0, 0.0]]},
            "formation": {"shape": "offsets", "offsets": [[-1.0, 1.0], [0.0, 1.0], [1.0, 1.0]]},
            "leader": {"start": [5.0, 5.0], "goal": [5.5, 5.0], "speed": 0.01},
            "sensors": {"lidar": {"enabled": False}},
            "controllers": {"cbf": {"margin": 0.2, "infeasible": policy}}}
    return scenario_from_dict(data, "<squeezed>")


@pytest.mark.parametrize("policy", ["least_violation", "stop", "pass_through"])
def test_infeasible_programs_apply_the_policy_and_are_counted(policy):
    sc = squeezed(policy)
    log = run_scenario(sc, "goto_slot+cbf")
    fb = log.filter_status == STATUS_FALLBACK
    assert fb[0, 1] and not fb[0, 0] and not fb[0, 2]
    assert metrics.summary(log, sc)["filter_fallbacks"] == int(fb.sum())
    assert log.filter_slack[0, 1] > 0.1  # about 0.2 m/s short on each side
    nominal = log.slots[0, 1] - log.pose[0, 1, :2]  # goto_slot, kp = 1, leader at rest
    expected = {"stop": np.zeros(2), "pass_through": nominal}.get(policy)
    if expected is not None:
        np.testing.assert_allclose(log.command[0, 1], expected, atol=1e-3)
    else:  # least violation: no sideways push, the upward nominal kept within the box
        assert abs(log.command[0, 1, 0]) < 1e-4 and log.command[0, 1, 1] > 0.5


def test_keep_static_relaxes_the_walker_and_never_the_wall():
    """A robot inside its wall margin (must move right at 0.1 m/s) with a moving disc
    closing in from the right (must move left at 0.5 m/s): no velocity meets both rows.
    The least violation splits the violation, 0.3 m/s on each row, and drives the robot
    towards the wall at 0.2 m/s; ``keep_static`` keeps the wall's row hard, capped at 0
    (never nearer), and gives way to the disc alone."""
    from comparisons.cbf.qp import BarrierRows, solve_distributed_exact

    pairs = BarrierRows(np.zeros((1, 0, 2)), np.zeros((1, 0)), np.zeros((1, 0), bool),
                        np.zeros((1, 0), np.intp))
    rows = BarrierRows(np.array([[[1.0, 0.0], [-1.0, 0.0]]]), np.array([[0.1, 0.5]]),
                       np.ones((1, 2), bool), None)
    nominal = np.array([[0.0, 0.3]])
    least, st, slack = solve_distributed_exact(nominal, pairs, rows, 1.0, "exact",
                                               "least_violation", 1)
    assert st[0] == STATUS_FALLBACK and slack[0] == pytest.approx(0.3)
    assert least[0, 0] == pytest.approx(-0.2)  # towards the wall
    kept, st, slack = solve_distributed_exact(nominal, pairs, rows, 1.0, "exact",
                                              "keep_static", 1)
    assert st[0] == STATUS_FALLBACK and slack[0] == pytest.approx(0.5)
    assert kept[0, 0] == pytest.approx(0.0, abs=1e-12)  # not towards the wall
    # with static_rows = 0 no row is the wall's: the least violation again
    again, _, _ = solve_distributed_exact(nominal, pairs, rows, 1.0, "exact", "keep_static", 0)
    np.testing.assert_array_equal(again, least)


def test_solver_errors_are_counted_and_stop_the_robot(monkeypatch):
    """Every qpsolvers call raises: each robot that needed a solve is a counted solver
    failure and stops; the run completes."""

    def broken(*args, **kwargs):
        raise RuntimeError("injected")

    monkeypatch.setattr(qpsolvers, "solve_qp", broken)
    sc = swap_scenario(n=6, controllers={"cbf": {"infeasible": "stop", "solver": "osqp"}})
    log = run_scenario(sc, "goto_slot+cbf")
    failed = log.filter_status == STATUS_SOLVER_FAIL
    assert failed.any() and len(log.t) == 251
    assert metrics.summary(log, sc)["filter_solver_failures"] == int(failed.sum())
    np.testing.assert_array_equal(log.command[failed], 0.0)


@pytest.mark.parametrize(("table", "key"), [
    ({"mode": "centralized", "solver": "exact"}, "controllers.cbf.solver"),
    ({"solver": "osqpp"}, "controllers.cbf.solver"),
    ({"solver": "osqp", "infeasible": "keep_static"}, "controllers.cbf.infeasible"),
])
def test_bad_settings_are_scenario_errors(table, key):
    with pytest.raises(ScenarioError, match=key.replace(".", r"\.")):
        run_scenario(swap_scenario(n=2, controllers={"cbf": table}), "goto_slot+cbf")


def test_pinning_osqps_algebra_keeps_its_default_and_an_explicit_choice():
    """``Solver("osqp")`` fixes OSQP's backend lookup to the backend OSQP picks anyway."""
    from osqp import interface

    from comparisons.constraints.solvers import Solver, pin_osqp_algebra
    saved = interface.OSQP_ALGEBRA_BACKEND
    try:
        interface.OSQP_ALGEBRA_BACKEND = None
        default = interface.default_algebra()
        Solver("osqp")
        assert interface.OSQP_ALGEBRA_BACKEND == default
        interface.OSQP_ALGEBRA_BACKEND = "builtin-explicit"  # a user's setting stays
        pin_osqp_algebra()
        assert interface.OSQP_ALGEBRA_BACKEND == "builtin-explicit"
    finally:
        interface.OSQP_ALGEBRA_BACKEND = saved


@pytest.mark.parametrize(("mode", "used"), [("distributed", "exact"), ("centralized", "osqp")])
def test_the_default_solver_is_the_exact_one_where_it_applies(mode, used, monkeypatch):
    """'auto': the exact 2D solver in distributed mode, osqp for the centralized program."""
    calls = []
    real = qpsolvers.solve_qp
    monkeypatch.setattr(qpsolvers, "solve_qp", lambda *a, **k: calls.append(1) or real(*a, **k))
    sc = swap_scenario(n=6, controllers={"cbf": {"mode": mode}})
    log = run_scenario(sc, "goto_slot+cbf")
    assert (log.filter_status != 0).any()  # the filter did act
    assert bool(calls) == (used == "osqp")
    if mode == "distributed":
        exact = swap_scenario(n=6, controllers={"cbf": {"mode": mode, "solver": "exact"}})
        assert run_scenario(exact, "goto_slot+cbf").digest() == log.digest()
