"""Paper 004's virtual-spring consensus formation: comparisons/virtual_spring/controller.py.

Oracles: hand evaluations of eq 4, 6, 7, 10-17; the composition of eq 8-10 in
the controller recomputed from the pure functions; smoke runs on a small
Table-1-like course (5 robots, two discs, one crossing obstacle robot).
"""

import math

import numpy as np
import pytest

from comparisons.virtual_spring import VirtualSpring, VirtualSpringBasic
from comparisons.virtual_spring.conflict import conflict_resolution, vo_conflict
from comparisons.virtual_spring.equations import (
    consensus_input,
    consistency_velocity,
    disc_normals,
    dynamic_speed_limit,
    error_trend,
    fig1_adjacency,
    laplacian,
    leader_velocity,
    polygon_normals,
    spring_force,
)
from dfcoa_opt.control.base import MovingObstacles, Observation
from dfcoa_opt.control.registry import available, build_controller, make_controller
from dfcoa_opt.core.errors import ScenarioError
from dfcoa_opt.core.geometry import rotate
from dfcoa_opt.scenario.loader import scenario_from_dict
from dfcoa_opt.sim.simulator import Simulator, run_scenario
from tests.helpers import Capture, assert_distributed, neighbours_from_lists

R = 0.15  # robot radius, m
V_MAX = 0.5  # m/s
E = np.array([[0.0, 0.0], [-1.5, 1.5], [-3.0, 1.5], [-1.5, -1.5], [-3.0, -1.5]])  # Table 1, n=5
START, GOAL = np.array([3.0, 3.0]), np.array([13.0, 13.0])
CIRCLES = (((6.2, 7.0), 0.3), ((8.0, 10.5), 0.3))
CROSSING = {"radius": 0.2, "speed": 0.3, "waypoints": [[12.0, 4.0], [4.0, 12.0]]}


def course(n=5, circles=CIRCLES, humans=(CROSSING,), controllers=None, polygons=(), offsets=E,
           **extra):
    """Leader robot 0 from (3, 3) to (13, 13), followers on Table 1's world-frame offsets.

    The scenario's offsets are in the virtual leader's frame (heading 45 deg):
    ``R(-45 deg) E``, which ``offset_frame = "world"`` turns back into E.

    Double integrators with a large a_max: the velocity command is eq 3 as
    printed. The virtual leader (speed 0.3 m/s) only ends the run, after the
    leader robot (0.5 m/s) has arrived.
    """
    poses = [[*(START + e), 0.0] for e in offsets[:n]]
    obstacles = [{"type": "circle", "center": list(c), "radius": r} for c, r in circles]
    obstacles += [{"type": "polygon", "vertices": v} for v in polygons]
    data = {"name": "vs_course", "dt": 0.1, "t_max": 60.0, "seed": 0,
            "world": {"size": [18.0, 18.0], "origin": [-2.0, -2.0], "resolution": 5,
                      "obstacles": obstacles, "dynamic_obstacles": list(humans)},
            "robots": {"model": "double_integrator", "radius": R, "v_max": V_MAX,
                       "a_max": 100.0},
            "team": {"n": n, "placement": "explicit", "poses": poses},
            "formation": {"shape": "offsets",
                          "offsets": rotate(np.asarray(offsets)[:n], -math.pi / 4).tolist()},
            "leader": {"start": START.tolist(), "goal": GOAL.tolist(), "speed": 0.3,
                       "wait_for_formation": False},
            "sensors": {"lidar": {"enabled": False}, "comm_radius": math.inf,
                        "obstacle_range": 3.0},
            "controllers": controllers or {}, **extra}
    return scenario_from_dict(data, "<vs_course>")


def ctrl(cid="virtual_spring", scenario=None, **params):
    c = make_controller(cid, params)
    c.reset(scenario or course(), np.random.default_rng(0))
    return c


def observation(pos, vel, nb, leader=(0.0, 0.0, 0.0, 0.0, 0.0), goal=(10.0, 0.0), humans=(),
                t=0.0):
    """A hand-made full observation; ``nb[i]`` = robot i's neighbour indices (rows of pos)."""
    pos, vel = np.asarray(pos, dtype=float), np.asarray(vel, dtype=float)
    n = len(pos)
    nbs = neighbours_from_lists(pos, vel, nb)
    m = max(len(humans), 1)
    hp, hv, hr = np.zeros((n, m, 2)), np.zeros((n, m, 2)), np.zeros((n, m))
    hm = np.zeros((n, m), dtype=bool)
    for j, (p, v, r) in enumerate(humans):
        hp[:, j], hv[:, j], hr[:, j], hm[:, j] = p, v, r, True
    pose = np.column_stack((pos, np.zeros(n)))
    return Observation(t, 0.1, np.arange(n), pose, vel, np.zeros((n, 2)), None, nbs,
                       MovingObstacles(hp, hv, hr, hm), np.asarray(leader, dtype=float),
                       np.asarray(goal, dtype=float), E[:n], pos.copy())


def follower_error(log):
    """``|p_i - p_leader - E_i|`` of the followers, ``(T, 4)`` m."""
    pos = log.pose[..., :2]
    return np.linalg.norm(pos - pos[:, :1] - E[None], axis=-1)[:, 1:]


# ------------------------------------------------------------------ registration
def test_both_ids_are_registered_with_their_defaults():
    assert {"virtual_spring", "virtual_spring_basic"} <= set(available())
    assert VirtualSpring.command == VirtualSpringBasic.command == "velocity"
    full, basic = build_controller("virtual_spring"), build_controller("virtual_spring_basic")
    assert isinstance(full, VirtualSpring) and isinstance(basic, VirtualSpringBasic)
    assert full.p.speed_limit and full.p.conflict_resolution
    assert not basic.p.speed_limit and not basic.p.conflict_resolution
    assert (full.name, basic.name) == ("virtual_spring", "virtual_spring_basic")
    # the basic model differs in these two defaults only
    same = {k: v for k, v in vars(full.p).items() if k not in ("speed_limit",
                                                              "conflict_resolution")}
    assert same == {k: v for k, v in vars(basic.p).items() if k in same}
    # scenario tables reach the parameters, bad keys name the table
    sc = course(controllers={"virtual_spring_basic": {"speed_limit": True, "beta": 0.1}})
    c = build_controller("virtual_spring_basic", sc.spec.controllers)
    assert c.p.speed_limit and c.p.beta == 0.1 and not c.p.conflict_resolution
    with pytest.raises(ScenarioError, match="controllers.virtual_spring.bta"):
        make_controller("virtual_spring", {"bta": 0.1})
    with pytest.raises(ValueError, match="leader_index = 5"):
        ctrl(leader_index=5)


# ---------------------------------------------------------------- eq 1-2, eq 4
def test_eq1_eq2_fig1_topology():
    want = np.array([[0, 0, 0, 0, 0],
                     [1, 0, 1, 0, 0],
                     [1, 1, 0, 1, 0],
                     [1, 0, 1, 0, 1],
                     [1, 0, 0, 1, 0]], dtype=float)
    np.testing.assert_array_equal(fig1_adjacency(5, 0), want)
    # leader in the middle: followers 0, 1, 3, 4 form the chain, each also hears robot 2
    a = fig1_adjacency(5, 2)
    assert [set(np.flatnonzero(row)) for row in a] == [{1, 2}, {0, 2, 3}, set(), {1, 2, 4},
                                                       {2, 3}]
    lap = laplacian(want)
    np.testing.assert_array_equal(np.diag(lap), [0, 2, 3, 3, 2])
    np.testing.assert_array_equal(lap.sum(axis=1), 0.0)


def test_eq4_by_hand():
    # follower at (1, 2), v (0.1, 0), E (-1.5, 1.5); leader (2, 0), v (0.5, 0), E 0;
    # adjacent follower (0, 3), v (0, 0.2), E (-3, 1.5):
    # leader term    (-1, 2) - (-1.5, 1.5) + (-0.4, 0)   = (0.1, 0.5)
    # follower term  (1, -1) - (1.5, 0)    + (0.1, -0.2) = (-0.4, -1.2)
    u = consensus_input([[1.0, 2.0]], [[0.1, 0.0]], [[-1.5, 1.5]],
                        [[[2.0, 0.0], [0.0, 3.0]]], [[[0.5, 0.0], [0.0, 0.2]]],
                        [[[0.0, 0.0], [-3.0, 1.5]]], [[1.0, 1.0]])
    np.testing.assert_allclose(u, [[0.3, 0.7]], atol=1e-12)
    # velocity weight k_v scales only the velocity differences: (-0.4, 0) + (0.1, -0.2)
    u2 = consensus_input([[1.0, 2.0]], [[0.1, 0.0]], [[-1.5, 1.5]],
                         [[[2.0, 0.0], [0.0, 3.0]]], [[[0.5, 0.0], [0.0, 0.2]]],
                         [[[0.0, 0.0], [-3.0, 1.5]]], [[1.0, 1.0]], velocity_weight=2.0)
    np.testing.assert_allclose(u2 - u, [[0.3, 0.2]], atol=1e-12)


def test_eq4_is_minus_the_laplacian_on_the_stacked_states():
    rng = np.random.default_rng(3)
    p, v = rng.normal(size=(5, 2)), rng.normal(size=(5, 2))
    a = fig1_adjacency(5, 0)
    everyone = np.broadcast_to(np.arange(5), (5, 5))
    u = consensus_input(p, v, E, p[everyone], v[everyone], E[everyone], a, 0.7)
    np.testing.assert_allclose(u, -laplacian(a) @ (p - E + 0.7 * v), atol=1e-12)


# ----------------------------------------------------------------------- eq 6
def test_eq6_leader_speed_is_alpha_d_capped_at_v_max():
    far = leader_velocity([[0.0, 0.0]], [3.0, 4.0], 0.2, V_MAX)  # alpha d = 1 > v_max
    np.testing.assert_allclose(far, [[0.3, 0.4]], atol=1e-12)
    near = leader_velocity([[0.0, 0.0]], [0.6, 0.8], 0.2, V_MAX)  # d = 1: 0.2 m/s
    np.testing.assert_allclose(near, [[0.12, 0.16]], atol=1e-12)
    np.testing.assert_array_equal(leader_velocity([[1.0, 1.0]], [1.0, 1.0], 0.2, V_MAX),
                                  [[0.0, 0.0]])


# ----------------------------------------------------------------------- eq 7
def test_eq7_inverse_cube_pointing_away_from_the_sources():
    # robot at the origin, sources at (1, 0) and (0, 2): (-1, 0)/1 + (0, -2)/8
    delta = np.array([[[-1.0, 0.0], [0.0, -2.0]]])
    np.testing.assert_allclose(spring_force(delta, [[True, True]]), [[-1.0, -0.25]])
    np.testing.assert_allclose(spring_force(delta, [[True, True]], 0.5), [[-0.5, -0.125]])
    np.testing.assert_allclose(spring_force(delta, [[False, True]]), [[0.0, -0.25]])
    # twice as far: a quarter of the force (|delta| / d^3 = 1/d^2)
    one = spring_force(np.array([[[0.0, 0.7]]]), [[True]])
    two = spring_force(np.array([[[0.0, 1.4]]]), [[True]])
    assert one[0, 1] == pytest.approx(4.0 * two[0, 1]) == pytest.approx(1.0 / 0.49)


def test_disc_and_polygon_sources():
    n_hat, s = disc_normals([[3.0, 4.0]], [[0.0, 0.0]], [1.0])
    np.testing.assert_allclose(n_hat, [[[0.6, 0.8]]])
    np.testing.assert_allclose(s, [[4.0]])
    square = [np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]])]
    n_hat, s = polygon_normals([[3.0, 1.0], [1.0, 0.4], [-1.0, -1.0]], square)
    np.testing.assert_allclose(n_hat[:, 0], [[1.0, 0.0], [0.0, -1.0],
                                             [-math.sqrt(0.5), -math.sqrt(0.5)]], atol=1e-12)
    np.testing.assert_allclose(s[:, 0], [1.0, -0.4, math.sqrt(2.0)], atol=1e-12)


def test_controller_spring_uses_body_clearance_range_and_every_source():
    square = [[[10.0, 10.0], [11.0, 10.0], [11.0, 11.0], [10.0, 11.0]]]
    sc = course(n=2, circles=(((0.0, 0.0), 0.5),), humans=(), polygons=square)
    c = ctrl(scenario=sc, spring_gain=0.02)
    # robot 0 at (1.2, 0): clearance 1.2 - 0.5 - R = 0.55 m from the disc; robot 1 far away
    obs = observation([[1.2, 0.0], [5.0, 5.0]], [[0.0, 0.0], [0.0, 0.0]], [[1], [0]])
    np.testing.assert_allclose(c.spring(obs), [[0.02 / 0.55**2, 0.0], [0.0, 0.0]], atol=1e-12)
    # beyond spring_range: nothing
    c2 = ctrl(scenario=sc, spring_range=0.5)
    np.testing.assert_array_equal(c2.spring(obs), 0.0)
    # a neighbour at 0.8 m (clearance 0.5) and a moving obstacle (radius 0.2) at 0.75 m
    obs = observation([[5.0, 5.0], [5.8, 5.0]], [[0.0, 0.0], [0.0, 0.0]], [[1], [0]],
                      humans=[((5.0, 4.25), (0.0, 0.0), 0.2)])
    f = c.spring(obs)
    np.testing.assert_allclose(f[0], [-0.02 / 0.5**2, 0.02 / 0.4**2], atol=1e-12)
    # the polygon: robot at (11.5, 10.5), clearance 0.5 - R from its right side
    obs = observation([[11.5, 10.5], [5.0, 5.0]], [[0.0, 0.0], [0.0, 0.0]], [[], []])
    np.testing.assert_allclose(c.spring(obs)[0], [0.02 / 0.35**2, 0.0], atol=1e-12)


# -------------------------------------------------------------- eq 8, 9, 10-11
def test_eq10_11_polar_form_is_beta_u():
    np.testing.assert_allclose(consistency_velocity([[3.0, 4.0]], 0.5), [[1.5, 2.0]])
    np.testing.assert_allclose(consistency_velocity([[0.0, -2.0]], 0.25), [[0.0, -0.5]],
                               atol=1e-15)
    np.testing.assert_array_equal(consistency_velocity([[0.0, 0.0]], 0.5), [[0.0, 0.0]])


def test_eq8_eq9_composition_in_the_controller():
    """Leader: eq 6 + f (eq 8); followers: v_leader + beta u (eq 4, 10) + f (eq 9)."""
    sc = course(n=3, circles=(((-1.2, 2.3), 0.3),), humans=())
    c = ctrl(scenario=sc, speed_limit=False, conflict_resolution=False)
    pos = np.array([[0.0, 0.0], [-1.2, 1.3], [-3.1, 1.4]])
    vel = np.array([[0.3, 0.1], [0.2, 0.0], [0.25, 0.05]])
    obs = observation(pos, vel, [[1, 2], [0, 2], [0, 1]], goal=(10.0, 0.0))
    cmd = c.act(obs)
    # only follower 1 is within 1 m of a source: the disc, clearance 1.0 - 0.3 - R = 0.55 m
    f1 = np.array([0.0, -0.02 / 0.55**2])
    np.testing.assert_allclose(cmd[0], [V_MAX, 0.0], atol=1e-12)  # eq 6 at v_max, no force
    u1 = consensus_input(pos[1:2], vel[1:2], E[1:2], pos[None, [0, 2]], vel[None, [0, 2]],
                         E[None, [0, 2]], [[1.0, 1.0]])
    u2 = consensus_input(pos[2:3], vel[2:3], E[2:3], pos[None, [0, 1]], vel[None, [0, 1]],
                         E[None, [0, 1]], [[1.0, 1.0]])
    np.testing.assert_allclose(cmd[1], vel[0] + 0.15 * u1[0] + f1, atol=1e-12)
    np.testing.assert_allclose(cmd[2], vel[0] + 0.15 * u2[0], atol=1e-12)
    # move the leader next to the disc: its eq 8 velocity gains the same kind of force
    pos[0] = [-0.3, 2.3 - 1.0]
    cmd = c.act(observation(pos, vel, [[1, 2], [0, 2], [0, 1]], goal=(10.0, 0.0)))
    v6 = leader_velocity(pos[:1], [10.0, 0.0], 0.2, V_MAX)[0]
    d = np.array([-0.3 + 1.2, -1.0])
    clear = np.hypot(*d) - 0.3 - R
    # follower 1 at 0.9 m (clearance 0.6) pushes back too
    d01 = pos[0] - pos[1]
    want = v6 + 0.02 * d / np.hypot(*d) / clear**2 \
        + 0.02 * d01 / np.hypot(*d01) / (np.hypot(*d01) - 2 * R) ** 2
    np.testing.assert_allclose(cmd[0], want * min(1.0, V_MAX / np.hypot(*want)), atol=1e-12)


def test_followers_fall_back_to_the_virtual_leader_and_turn_offsets_in_leader_frame():
    sc = course(n=2, circles=(), humans=())
    # the leader robot is out of range: the follower uses the virtual leader (x, y, th, v, w)
    c = ctrl(scenario=sc, speed_limit=False, conflict_resolution=False)
    lead = (2.0, 1.0, 0.0, 0.4, 0.0)
    pos, vel = np.array([[0.0, 0.0], [0.5, 2.5]]), np.zeros((2, 2))
    cmd = c.act(observation(pos, vel, [[], []], leader=lead))
    e = (pos[1] - [2.0, 1.0]) - E[1] + (vel[1] - [0.4, 0.0])  # eq 4 leader term only
    np.testing.assert_allclose(cmd[1], np.array([0.4, 0.0]) - 0.15 * e, atol=1e-12)
    # leader frame: E_1 = R(heading) o_1 with the scenario's leader-frame offset
    # o_1 = R(-45 deg) (-1.5, 1.5) = (0, 2.12); heading of the leader's velocity (+y)
    c = ctrl(scenario=sc, offset_frame="leader", speed_limit=False, conflict_resolution=False)
    p_l, v_l = np.array([5.0, 5.0]), np.array([0.0, 0.3])
    slot = p_l + np.array([-1.5 * math.sqrt(2.0), 0.0])  # R(90 deg) (0, 2.12)
    cmd = c.act(observation([p_l, slot], [v_l, v_l], [[1], [0]]))
    np.testing.assert_allclose(cmd[1], v_l, atol=1e-12)  # in formation: u = 0
    assert np.linalg.norm(ctrl(scenario=sc, speed_limit=False, conflict_resolution=False).act(
        observation([p_l, slot], [v_l, v_l], [[1], [0]]))[1] - v_l) > 0.1


# --------------------------------------------------------------------- eq 12-13
def test_eq12_13_functions_by_hand():
    np.testing.assert_allclose(error_trend([2.0, 1.0, 0.1], [1.0, 2.0, 0.05]),
                               [0.5, -1.0, 0.5])
    np.testing.assert_allclose(error_trend([0.1], [0.05], floor=0.2), [0.25])
    np.testing.assert_array_equal(error_trend([0.0], [0.0]), [0.0])
    np.testing.assert_allclose(dynamic_speed_limit([0.3, 0.3, 0.1], [0.5, -0.2, -1.0], V_MAX),
                               [0.5, 0.2, 0.0])
    np.testing.assert_allclose(dynamic_speed_limit([0.1], [-1.0], V_MAX, floor=0.05), [0.05])


def _two(err_x, t):
    """Leader at the origin moving +x; follower 1 at E_1 + (err_x, 0), commanded forwards."""
    pos = np.array([[0.0, 0.0], E[1] + [err_x, 0.0]])
    vel = np.array([[0.5, 0.0], [0.3, 0.0]])
    return observation(pos, vel, [[1], [0]], t=t)


@pytest.mark.parametrize("memory", ["limit", "speed"])
def test_eq12_13_limit_follows_the_error_trend(memory):
    sc = course(n=2, circles=(), humans=())
    c = ctrl(scenario=sc, conflict_resolution=False, limit_memory=memory, error_floor=0.0,
             min_speed_limit=0.0)
    base0 = V_MAX if memory == "limit" else 0.3
    c.act(_two(-0.4, 0.0))  # first step: no history, epsilon = 0
    assert c.last_limit[1] == pytest.approx(base0)
    assert c.last_limit[0] == V_MAX  # the leader has no eq 12-13 limit
    again = c.act(_two(-0.4, 0.0))  # same step again: same memory
    assert c.last_limit[1] == pytest.approx(base0)
    # error shrinks 0.4 -> 0.2 m: epsilon = -1, the limit drops by v_max (to 0)
    cmd = c.act(_two(-0.2, 0.1))
    want = max(0.0, base0 - V_MAX)
    assert c.last_limit[1] == pytest.approx(want)
    assert np.hypot(*cmd[1]) <= want + 1e-12
    # error grows 0.2 -> 0.25 m: epsilon = 0.2, the limit rises by 0.1 m/s from its base
    base = want if memory == "limit" else 0.3
    for _ in range(2):  # the memory moves on once per step, however often act is called
        c.act(_two(-0.25, 0.2))
        assert c.last_limit[1] == pytest.approx(min(base + 0.2 * V_MAX, V_MAX))
    assert np.hypot(*again[1]) > 0.0
    # without the limit the same steps are not capped
    free = ctrl(scenario=sc, conflict_resolution=False, speed_limit=False)
    free.act(_two(-0.4, 0.0))
    assert np.hypot(*free.act(_two(-0.2, 0.1))[1]) > 0.2


# --------------------------------------------------------------------- eq 15-17
def test_eq15_16_conflict_detection():
    d = np.array([2.0, 0.0])
    assert vo_conflict(d, [1.0, 0.0], 0.5)  # straight at it
    assert not vo_conflict(d, [0.0, 1.0], 0.5)  # sideways
    assert not vo_conflict(d, [-1.0, 0.0], 0.5)  # away
    assert not vo_conflict(d, [0.0, 0.0], 0.5)  # no relative motion
    # grazing: closest approach |(2, 0) - 2/1.04 (1, 0.2)| = 0.392 m
    assert vo_conflict(d, [1.0, 0.2], 0.4)
    assert not vo_conflict(d, [1.0, 0.2], 0.38)
    # far ahead: inside the infinite cone, beyond a 3 s horizon
    assert vo_conflict([10.0, 0.0], [1.0, 0.0], 0.5)
    assert not vo_conflict([10.0, 0.0], [1.0, 0.0], 0.5, horizon=3.0)
    assert vo_conflict([0.3, 0.0], [-1.0, 0.0], 0.5)  # already overlapping
    np.testing.assert_array_equal(vo_conflict(np.array([[d, d]]), np.array([[[1.0, 0.0],
                                                                              [0.0, 1.0]]]),
                                              np.array([[0.5, 0.5]])), [[True, False]])


def test_eq17_front_speeds_up_rear_slows_down():
    # same lane along +x: i at 0 with 0.5 m/s behind k at 1 m with 0.2 m/s; |v_i - v_k| = 0.3
    p = np.array([[0.0, 0.0], [1.0, 0.0]])
    v = np.array([[0.5, 0.0], [0.2, 0.0]])
    dv = conflict_resolution(p, v, p[[1, 0]][:, None], v[[1, 0]][:, None], [[True], [True]])
    np.testing.assert_allclose(dv, [[-0.15, 0.0], [0.15, 0.0]], atol=1e-12)
    np.testing.assert_allclose((v + dv)[0], (v + dv)[1])  # equal speeds: no more closing
    # no conflict: no change; share 2 (obstacle that does not cooperate): the whole 0.3
    np.testing.assert_array_equal(conflict_resolution(p[:1], v[:1], p[None, 1:], v[None, 1:],
                                                      [[False]]), [[0.0, 0.0]])
    np.testing.assert_allclose(conflict_resolution(p[:1], v[:1], p[None, 1:], v[None, 1:],
                                                   [[True]], 2.0), [[-0.3, 0.0]])
    # crossing: mean direction (1, 1)/sqrt 2; i is ahead along it and speeds up
    dv = conflict_resolution([[1.0, 1.0]], [[0.4, 0.0]], [[[0.0, 0.0]]], [[[0.0, 0.4]]],
                             [[True]])
    np.testing.assert_allclose(dv, [[0.2, 0.2]], atol=1e-12)  # |v_i - v_k|/2 = 0.2 sqrt 2


def test_controller_resolves_a_rear_end_conflict_and_an_obstacle_conflict():
    # follower 1's slot is 1.5 m ahead of the leader; it comes from 1 m behind at 0.45 m/s
    # while the leader, 0.5 m from its goal, slows down: both see the conflict
    sc = course(n=2, circles=(), humans=(), offsets=np.array([[0.0, 0.0], [1.5, 0.0]]))
    c = ctrl(scenario=sc, speed_limit=False)
    plain = ctrl(scenario=sc, speed_limit=False, conflict_resolution=False)
    pos = np.array([[1.0, 0.0], [0.0, 0.0]])
    vel = np.array([[0.05, 0.0], [0.45, 0.0]])
    obs = observation(pos, vel, [[1], [0]], goal=(1.5, 0.0))
    before, after = plain.act(obs), c.act(obs)
    np.testing.assert_array_equal(c.last_conflicts, [1, 1])
    np.testing.assert_array_equal(before[:, 1], 0.0)
    # eq 17 along +x: the leader (in front) + |v_0 - v_1|/2, the follower (behind) - the same
    lead_x = before[0, 0] + abs(before[0, 0] - 0.45) / 2
    fol_x = before[1, 0] - abs(before[1, 0] - 0.05) / 2
    np.testing.assert_allclose(after, [[lead_x, 0.0], [fol_x, 0.0]], atol=1e-12)
    assert after[0, 0] > before[0, 0] and after[1, 0] < before[1, 0]
    # a moving obstacle coming straight at a lone robot: it backs off (share 2)
    obs = observation([[0.0, 0.0], [9.0, 9.0]], [[0.0, 0.0], [0.0, 0.0]], [[], []],
                      goal=(5.0, 0.0), humans=[((2.0, 0.0), (-0.3, 0.0), 0.2)])
    v = c.act(obs)[0]
    assert c.last_conflicts[0] == 1
    assert v[0] < plain.act(obs)[0, 0]


# ----------------------------------------------------------------- distributed
@pytest.mark.parametrize("cid", ["virtual_spring", "virtual_spring_basic"])
def test_rows_are_distributed_with_the_eq12_memory(cid):
    sc = course()
    cap = Capture(build_controller(cid))
    Simulator(sc, cap).run()
    c = build_controller(cid)
    c.reset(sc, np.random.default_rng(0))
    for k, obs in enumerate(cap.obs[:200]):
        if k in (60, 130, 199):  # 199: the crossing obstacle is sensed
            assert_distributed(c, obs)
        else:
            c.act(obs)
    assert cap.obs[199].obstacles.mask.any()


# ------------------------------------------------------------------ smoke runs
def test_smoke_runs_improved_and_basic():
    """Both reach the goal without contacts; measured values in docs/methods/virtual_spring.md.

    Recorded finding, contrary to the paper's claim: on this course the two
    improvements keep the crossing obstacle robot farther away but raise the
    formation error (eq 12-13 lowers the followers' speed whenever their error
    shrinks; eq 17 makes robots back off along the common direction).
    """
    sc = course()
    logs = {cid: run_scenario(sc, cid) for cid in ("virtual_spring", "virtual_spring_basic")}
    near = {}
    for cid, log in logs.items():
        pos = log.pose[..., :2]
        gap = np.linalg.norm(pos[:, 0] - GOAL, axis=1)
        arrived = np.flatnonzero(gap <= 0.5)
        assert len(arrived) and log.t[arrived[0]] < 35.0, cid  # 14.1 m at <= 0.5 m/s: 31.6 s
        assert gap[-1] < 0.05
        assert log.collision_events.sum() == 0, cid
        assert log.min_inter_robot.min() > 2 * R + 0.3
        assert log.clearance.min() > R + 0.1
        err = follower_error(log)
        assert err.max() < 2.5 and err[-1].max() < 0.3, cid
        near[cid] = np.linalg.norm(pos[:, :, None] - log.dyn_pos[:, None], axis=-1).min()
        assert near[cid] < 1.0  # the obstacle robot does come close
        assert near[cid] > R + CROSSING["radius"] + 0.1
        lengths = np.linalg.norm(np.diff(pos, axis=0), axis=-1).sum(axis=0)
        assert lengths[0] == pytest.approx(np.hypot(*(GOAL - START)), abs=0.2)
    assert near["virtual_spring"] > near["virtual_spring_basic"] + 0.1
    mean = {cid: follower_error(log).mean() for cid, log in logs.items()}
    assert mean["virtual_spring"] > mean["virtual_spring_basic"]


def test_same_seed_same_bits():
    sc = course(team={"n": 5, "placement": "explicit", "start_noise": 0.05,
                      "poses": [[*(START + e), 0.0] for e in E]})
    a, b = (run_scenario(sc, "virtual_spring", seed=5) for _ in range(2))
    c = run_scenario(sc, "virtual_spring", seed=6)
    for name, arr in a.arrays().items():
        if name != "filter_time":
            np.testing.assert_array_equal(arr, b.arrays()[name], err_msg=name)
    assert not np.array_equal(a.pose, c.pose)
    assert a.digest() == b.digest() != c.digest()
