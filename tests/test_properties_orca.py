"""Hypothesis property tests of ORCA: the exact solver against the QP solver, and the
safe discrete-time mode on random crowds (pairwise distances recomputed from the
positions).

Two bugs these properties found are pinned by plain tests: the exact ORCA solver
on lines that coincide up to rounding, and the simulator's safe mode with fewer
neighbours in the table than robots within one step's reach.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, event, given, settings
from hypothesis import strategies as st

from comparisons.orca import safe
from comparisons.orca.crowd import goal_velocities
from comparisons.orca.ivo.ellipse import polygon_segments
from comparisons.orca.lp import FEASIBLE, LEAST_VIOLATION, SOLVER_FAIL, solve_lines
from comparisons.orca.neighbours import knn_within
from comparisons.orca.qp import solve_lines_qp
from comparisons.orca.velocities import orca_velocities
from dfcoa_opt.control.base import STATUS_FALLBACK
from dfcoa_opt.scenario.loader import scenario_from_dict
from dfcoa_opt.sim.simulator import run_scenario
from tests.test_orca_qp import _batch, _unique_minimax, _viol

TWO_PI = 2.0 * math.pi
VEL_TOL = 1e-6  # m/s, ORCA solver agreement (tests/test_orca_qp.py)

pytestmark = pytest.mark.usefixtures("one_numba_thread")


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


def test_scale_into_shrinks_to_a_violated_line_and_leaves_a_line_that_excludes_the_origin():
    # robot 0: the line y <= 0.5 (allowed side on the left of direction (-1, 0)), v = (0, 2)
    # robot 1: a line that excludes v = 0 (y <= -0.5), with v parallel to it (a = 0)
    points = np.array([[[0.0, 0.5]], [[0.0, -0.5]]])
    directions = np.array([[[-1.0, 0.0]], [[-1.0, 0.0]]])
    vel = np.array([[0.0, 2.0], [1.0, 0.0]])
    with np.errstate(all="raise"):  # no division by zero on robot 1's row
        out, scaled = safe.scale_into(vel, points, directions, np.array([1, 1]))
    np.testing.assert_allclose(out[0], [0.0, 0.5])  # shrunk onto its line
    np.testing.assert_array_equal(out[1], vel[1])  # shrinking cannot help: left as it is
    assert scaled.tolist() == [True, True]
