"""Static polygon obstacles (RVO2's obstacle ORCA lines) against RVO2 (``pyrvo``) and by hand."""

import numpy as np
import pytest

from comparisons.orca.crowd import OrcaCrowd, goal_velocities
from comparisons.orca.obstacles import obstacle_lines, prepare_obstacles

pyrvo = pytest.importorskip("pyrvo")

#: RVO2's Blocks example: dt, set_agent_defaults(neighborDist, maxNeighbors, timeHorizon,
#: timeHorizonObst, radius, maxSpeed) and the four square obstacles (counter-clockwise).
DT, DEFAULTS = 0.25, (15.0, 10, 5.0, 5.0, 2.0, 2.0)
BLOCKS = [[(-10.0, 40.0), (-40.0, 40.0), (-40.0, 10.0), (-10.0, 10.0)],
          [(10.0, 40.0), (10.0, 10.0), (40.0, 10.0), (40.0, 40.0)],
          [(10.0, -40.0), (40.0, -40.0), (40.0, -10.0), (10.0, -10.0)],
          [(-10.0, -40.0), (-10.0, -10.0), (-40.0, -10.0), (-40.0, -40.0)]]
#: Obstacles whose k-d tree RVO2 builds by splitting edges (9 extra vertices), with a
#: two-vertex segment and a concave pentagon.
MIXED = [[(0.0, 0.0), (10.0, 0.0), (5.0, 8.0)], [(-5.0, 3.0), (20.0, 4.0)],
         [(12.0, -6.0), (30.0, -5.0), (20.0, 10.0)], [(3.3, -2.0), (7.1, 12.7)],
         [(-30.0, -30.0), (-10.0, -30.0), (-10.0, -10.0), (-20.0, -20.0), (-30.0, -10.0)]]


def _f32(a):
    return a.astype(np.float32).astype(np.float64)


def _positions(sim, n):
    return np.array([sim.get_agent_position(i).to_tuple() for i in range(n)])


def _simulator(obstacles, defaults=DEFAULTS):
    sim = pyrvo.RVOSimulator()
    sim.set_time_step(DT)
    sim.set_agent_defaults(*defaults)
    for poly in obstacles:
        sim.add_obstacle(poly)
    sim.process_obstacles()
    return sim


def _blocks_agents():
    """Blocks' agents (four 5 x 5 groups) and their goals, in RVO2's order."""
    start, goals = [], []
    for i in range(5):
        for j in range(5):
            a, b = 55.0 + 10.0 * i, 55.0 + 10.0 * j
            start += [(a, b), (-a, b), (a, -b), (-a, -b)]
            goals += [(-75.0, -75.0), (75.0, -75.0), (-75.0, 75.0), (75.0, 75.0)]
    return np.array(start), np.array(goals)


def _edge_dist(pos, a, b):
    """Distance ``(N, E)`` from every point of ``pos`` (N, 2) to every segment a-b (E, 2)."""
    e = b - a
    rel = pos[:, None] - a
    s = np.clip((rel * e).sum(-1) / (e * e).sum(-1), 0.0, 1.0)
    return np.linalg.norm(rel - s[..., None] * e, axis=-1)


def _edges(polygons):
    a = np.array([p[k] for p in polygons for k in range(len(p))])
    b = np.array([p[(k + 1) % len(p)] for p in polygons for k in range(len(p))])
    return a, b


@pytest.fixture(scope="module")
def blocks_runs():
    """pyrvo's Blocks (no random perturbation) and OrcaCrowd with double / float32 state.

    Returns per run the max |position difference| per step, the clearance
    (distance from an agent's centre to the nearest obstacle edge) of our crowd
    per step, and how many obstacle lines excluded the preferred velocity.
    """
    steps = {False: 150, True: 240}
    start, goals = _blocks_agents()
    n = len(start)
    sim = _simulator(BLOCKS)
    for p in start:
        sim.add_agent(tuple(p))
    ref = []
    for _ in range(max(steps.values())):
        pref = goal_velocities(_positions(sim, n), goals)
        for i in range(n):
            sim.set_agent_pref_velocity(i, tuple(pref[i]))
        sim.do_step()
        ref.append(_positions(sim, n))
    a, b = _edges(BLOCKS)
    runs = {}
    for single in (False, True):
        crowd = OrcaCrowd(start.copy(), dt=DT, neighbor_dist=DEFAULTS[0],
                          max_neighbors=DEFAULTS[1], time_horizon=DEFAULTS[2],
                          radius=DEFAULTS[4], max_speed=DEFAULTS[5], obstacles=BLOCKS,
                          time_horizon_obst=DEFAULTS[3])
        dev, clearance, binding = [], [], 0
        for k in range(steps[single]):
            pref = goal_velocities(crowd.positions, goals)
            if single:  # store the state as RVO2 does (float), compute in double
                pref = _f32(pref)
            P, D, count = obstacle_lines(crowd.positions, crowd.velocities, DEFAULTS[4],
                                         DEFAULTS[5], DEFAULTS[3], crowd.obstacles)
            viol = (D[..., 0] * (P[..., 1] - pref[:, None, 1])
                    - D[..., 1] * (P[..., 0] - pref[:, None, 0]))
            binding += int(((viol > 1e-9) & (np.arange(P.shape[1]) < count[:, None])).sum())
            crowd.step(pref)
            if single:
                crowd.positions, crowd.velocities = _f32(crowd.positions), _f32(crowd.velocities)
            dev.append(np.abs(ref[k] - crowd.positions).max())
            clearance.append(_edge_dist(crowd.positions, a, b).min())
        runs[single] = np.array(dev), np.array(clearance), binding
    return runs


def test_blocks_matches_rvo2_with_double_state(blocks_runs):
    """1e-3 m over 150 steps (measured: 3.6e-4 m at 100 steps, 5.4e-4 m at 150)."""
    dev, _, binding = blocks_runs[False]
    assert dev[:100].max() < 5e-4
    assert dev.max() < 1e-3
    assert binding > 100  # the obstacle lines really constrain agents in this window


def test_blocks_with_single_precision_state_agrees_to_float_rounding(blocks_runs):
    """Below one float ulp for 100 steps, a few ulps until 150, 1e-4 m over 240 steps.

    Measured: bit-identical positions for the first 146 steps, 7.6e-6 m at 200,
    5e-5 m at 240. Later (around step 250) agents pressed against a wall and
    each other amplify the remaining ulp differences (1.4e-3 m at step 252).
    """
    dev, _, binding = blocks_runs[True]
    assert dev[:100].max() < 1e-6
    assert dev[:150].max() < 1e-5
    assert dev.max() < 1e-4
    assert binding > 500


def test_blocks_agents_never_penetrate_obstacles(blocks_runs):
    """Obstacle lines are hard: every agent keeps its radius clear of every edge.

    Also over 800 steps of our crowd alone, where (without RVO2's random
    perturbation) the four groups jam in the crossing and many agents slide
    along the walls, touching them (measured minimum clearance: exactly the radius).
    """
    for single in (False, True):
        _, clearance, _ = blocks_runs[single]
        assert clearance.min() >= DEFAULTS[4] - 1e-6
    start, goals = _blocks_agents()
    crowd = OrcaCrowd(start, dt=DT, neighbor_dist=DEFAULTS[0], max_neighbors=DEFAULTS[1],
                      time_horizon=DEFAULTS[2], radius=DEFAULTS[4], max_speed=DEFAULTS[5],
                      obstacles=BLOCKS, time_horizon_obst=DEFAULTS[3])
    a, b = _edges(BLOCKS)
    touching = 0
    for _ in range(800):
        crowd.step(goal_velocities(crowd.positions, goals))
        dist = _edge_dist(crowd.positions, a, b).min(axis=1)
        assert dist.min() >= DEFAULTS[4] - 1e-9
        touching += int((dist < DEFAULTS[4] + 1e-3).sum())
    assert touching > 1000


@pytest.mark.parametrize("obstacles, span", [(BLOCKS, 60.0), (MIXED, 40.0)])
def test_obstacle_lines_match_rvo2_line_by_line(obstacles, span):
    """Random agents (no agent neighbours): the same edges in the same order, the same lines.

    Half the agents sit within 4 m of a vertex (overlaps, oblique views and
    equidistant edges in convex corners), half anywhere.
    """
    obs = prepare_obstacles(obstacles)
    rng = np.random.default_rng(3)
    n = 1500
    pos = rng.uniform(-span, span, (n, 2))
    pos[: n // 2] = obs.points[rng.integers(0, obs.n_edges, n // 2)] + \
        rng.uniform(-4.0, 4.0, (n // 2, 2))
    pos, vel = _f32(pos), _f32(rng.uniform(-2.0, 2.0, (n, 2)))
    sim = _simulator(obstacles, (15.0, 0, 5.0, 5.0, 2.0, 2.0))
    for i in range(n):
        sim.add_agent(tuple(pos[i]))
        sim.set_agent_velocity(i, tuple(vel[i]))
        sim.set_agent_pref_velocity(i, (0.0, 0.0))
    sim.do_step()  # computes the lines from the state set above
    P, D, count = obstacle_lines(pos, vel, 2.0, 2.0, 5.0, obs)
    assert count.sum() > n // 2 and (count >= 2).sum() > 10
    for i in range(n):
        assert sim.get_agent_num_orca_lines(i) == count[i]
        for k in range(count[i]):
            d, p = sim.get_agent_orca_line(i, k)
            np.testing.assert_allclose(D[i, k], d, atol=1e-5)
            np.testing.assert_allclose(P[i, k], p, atol=1e-5)


def test_rings_and_edge_splits_match_rvo2():
    obs = prepare_obstacles(MIXED)
    sim = _simulator(MIXED)
    assert sim.get_num_obstacle_vertices() == obs.n_edges == 24
    for k in range(obs.n_edges):
        assert sim.get_next_obstacle_vertex(k) == obs.next[k]
        assert sim.get_prev_obstacle_vertex(k) == obs.prev[k]
        np.testing.assert_array_equal(_f32(obs.points[k]), sim.get_obstacle_vertex(k).to_tuple())
    assert list(np.flatnonzero(~obs.convex)) == [13]  # the pentagon's reflex vertex
    blocks = prepare_obstacles(BLOCKS)
    assert blocks.n_edges == 16 and blocks.convex.all()  # axis-aligned squares: no splits


# A wall x = 3 (the edge of a square to its right, counter-clockwise), agent at the origin.
WALL = [[(3.0, 10.0), (3.0, -10.0), (23.0, -10.0), (23.0, 10.0)]]
R, TAU = 0.5, 2.0


def _lines(pos, vel, obstacles=WALL):
    P, D, count = obstacle_lines(np.array([pos], float), np.array([vel], float), R, 2.0, TAU,
                                 obstacles)
    return P[0, :count[0]], D[0, :count[0]]


def _allows(P, D, v):
    return bool(np.all(D[:, 0] * (P[:, 1] - v[1]) - D[:, 1] * (P[:, 0] - v[0]) <= 1e-12))


@pytest.mark.parametrize("vel", [(2.0, 0.0), (1.0, 0.5), (0.0, 0.0)])
def test_head_on_edge_gives_the_cut_off_line(vel):
    """Facing the wall: v_x <= (dist - r) / tau, a line parallel to the edge."""
    P, D = _lines((0.0, 0.0), vel)
    assert len(P) == 1
    np.testing.assert_allclose(D[0], [0.0, 1.0], atol=1e-15)
    assert P[0, 0] == pytest.approx((3.0 - R) / TAU)
    assert _allows(P, D, ((3.0 - R) / TAU - 1e-9, 5.0))
    assert not _allows(P, D, ((3.0 - R) / TAU + 1e-9, -5.0))


def test_velocity_clear_of_the_obstacle_is_not_constrained():
    P, D = _lines((0.0, 0.0), (-1.0, 0.3))  # moving away: the line does not cut it
    assert _allows(P, D, (-1.0, 0.3))
    P, D = _lines((-13.0, 0.0), (1.0, 0.0))  # out of range tau * v_max + r = 4.5 m
    assert len(P) == 0


def test_overlapping_an_edge_gives_the_move_away_line():
    P, D = _lines((2.8, 0.0), (1.0, 1.0))
    assert len(P) == 1
    np.testing.assert_array_equal(P[0], [0.0, 0.0])
    np.testing.assert_allclose(D[0], [0.0, 1.0])  # v_x <= 0
    assert _allows(P, D, (0.0, 1.0)) and not _allows(P, D, (1e-9, 0.0))


def test_overlapping_a_convex_corner_gives_one_line_away_from_the_vertex():
    """Both edges of the corner are equidistant; only one line (the other defers to it)."""
    P, D = _lines((2.8, 10.2), (0.0, 0.0))
    assert len(P) == 1
    np.testing.assert_array_equal(P[0], [0.0, 0.0])
    np.testing.assert_allclose(D[0], [np.sqrt(0.5), np.sqrt(0.5)])
    assert _allows(P, D, (-1.0, 1.0)) and not _allows(P, D, (1.0, -1.0))


def test_segment_obstacle_is_seen_from_both_sides():
    seg = [[(3.0, 10.0), (3.0, -10.0)]]
    for x, bound in ((0.0, (3.0 - R) / TAU), (6.0, (3.0 + R - 6.0) / TAU)):
        P, D = _lines((x, 0.0), (0.0, 0.0), seg)
        assert len(P) == 1
        assert abs(P[0, 0]) == pytest.approx(abs(bound)) and D[0, 0] == 0.0


def test_crowd_without_obstacles_is_unchanged():
    start, goals = _blocks_agents()
    plain = OrcaCrowd(start.copy(), radius=2.0, time_horizon=5.0)
    empty = OrcaCrowd(start.copy(), radius=2.0, time_horizon=5.0, obstacles=[])
    far = OrcaCrowd(start.copy(), radius=2.0, time_horizon=5.0,
                    obstacles=[[(1e3, 1e3), (1e3 + 1, 1e3), (1e3, 1e3 + 1)]])
    for _ in range(20):
        for crowd in (plain, empty, far):
            crowd.step(goal_velocities(crowd.positions, goals))
    np.testing.assert_array_equal(plain.positions, empty.positions)
    np.testing.assert_array_equal(plain.positions, far.positions)
