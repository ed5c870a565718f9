"""``lf_vo``: paper 002's leader-follower V formation with a sampled velocity obstacle."""

import math

import numpy as np
import pytest

from comparisons.lf_vo import LeaderFollowerVO
from comparisons.lf_vo.equations import (
    formation_target,
    path_clearance,
    reference_command,
    rollout,
    target_error,
    vo_cost,
)
from comparisons.lf_vo.kernel import vo_clearance
from dfcoa_opt.control.base import MovingObstacles, Neighbours, Observation
from dfcoa_opt.control.registry import available, make_controller
from dfcoa_opt.core.errors import ScenarioError
from dfcoa_opt.scenario.loader import scenario_from_dict
from dfcoa_opt.sim.simulator import Simulator, run_scenario
from tests.helpers import assert_distributed

R = 0.25  # robot radius (Table I wheelbase 0.5 m), m


def v_scenario(humans=(), circles=(), poses=None, **extra):
    """Three unicycles in a V (spacing 1 m, half-angle 30 deg) behind a leader going +x."""
    team = {"n": 3} if poses is None else {"n": 3, "placement": "explicit", "poses": poses}
    data = {
        "name": "lf_vo_test", "dt": 0.1, "t_max": 40.0, "seed": 1,
        "world": {"size": [20.0, 10.0], "resolution": 10,
                  "obstacles": [{"type": "circle", "center": list(c), "radius": r}
                                for c, r in circles],
                  "dynamic_obstacles": list(humans)},
        "robots": {"radius": R, "v_max": 0.65, "w_max": 1.0},
        "team": team,
        "formation": {"shape": "v", "spacing": 1.0, "angle": math.pi / 6},
        "leader": {"start": [2.0, 5.0], "goal": [16.0, 5.0], "speed": 0.4},
        "sensors": {"lidar": {"enabled": False}, "obstacle_range": 5.0},
        **extra,
    }
    return scenario_from_dict(data, "<lf_vo>")


HEAD_ON = {"radius": 0.3, "speed": 0.5, "waypoints": [[14.0, 5.0], [0.0, 5.0]]}


def ctrl(scenario=None, **params):
    c = make_controller("lf_vo", params)
    c.reset(scenario or v_scenario(), np.random.default_rng(0))
    return c


def observation(pose, slot, leader=(0.0, 0.0, 0.0, 0.0, 0.0), nb=None, humans=None):
    """A hand-made observation: ``nb`` = list of (index, pos, vel) per robot (same for all)."""
    pose = np.asarray(pose, dtype=float)
    n = len(pose)
    nb = nb or []
    k = max(len(nb), 1)
    idx = np.full((n, k), -1)
    pos, vel, dist = np.zeros((n, k, 2)), np.zeros((n, k, 2)), np.full((n, k), np.inf)
    for j, (i, p, v) in enumerate(nb):
        idx[:, j], pos[:, j], vel[:, j], dist[:, j] = i, p, v, 1.0
    humans = humans or []
    m = max(len(humans), 1)
    hp, hv, hr = np.zeros((n, m, 2)), np.zeros((n, m, 2)), np.zeros((n, m))
    hm = np.zeros((n, m), dtype=bool)
    for j, (p, v, r) in enumerate(humans):
        hp[:, j], hv[:, j], hr[:, j], hm[:, j] = p, v, r, True
    slot = np.asarray(slot, dtype=float)
    return Observation(0.0, 0.1, np.arange(n), pose, np.zeros((n, 2)), np.zeros((n, 2)), None,
                       Neighbours(idx, pos, vel, dist), MovingObstacles(hp, hv, hr, hm),
                       np.asarray(leader, dtype=float), np.zeros(2), np.zeros((n, 2)), slot)


def test_registered():
    assert "lf_vo" in available()
    assert LeaderFollowerVO.command == "unicycle"


def test_eq_5_to_11_by_hand():
    # eq 5-6: leader at (1, 2) heading 90 deg, d = 2, phi = -30 deg (left wing of the V)
    d, phi, th = 2.0, -math.pi / 6, math.pi / 2
    offset = [-d * math.cos(phi), -d * math.sin(phi)]  # = v_offsets' left follower, rank 2
    xt, yt = formation_target([1.0, 2.0, th], offset)
    assert xt == pytest.approx(1.0 - d * math.cos(th + phi))  # 1 - 2 cos 60 = 0
    assert yt == pytest.approx(2.0 - d * math.sin(th + phi))  # 2 - 2 sin 60
    assert (xt, yt) == pytest.approx((0.0, 2.0 - math.sqrt(3.0)))
    # eq 7-11: follower at (1, 1) heading 0, target (4, 5): l = 5, theta_T = atan2(4, 3)
    dist, theta_t, alpha = target_error([1.0, 1.0, 0.0], [4.0, 5.0])
    assert dist == pytest.approx(5.0)
    assert theta_t == pytest.approx(math.atan2(4.0, 3.0))
    assert alpha == pytest.approx(0.0 - math.atan2(4.0, 3.0))  # eq 11: theta_F - theta_T
    # eq 4: v = min(l / t, v_max); omega = 2 v sin(theta_T - theta) / l (turns left, to the target)
    v, w = reference_command(dist, alpha, 0.65, 1.0, 0.5)
    assert v == pytest.approx(0.65)
    assert w == pytest.approx(2 * 0.65 * 0.8 / 5.0)
    v, w = reference_command(0.1, 0.0, 0.65, 1.0, 0.5)
    assert (v, w) == pytest.approx((0.2, 0.0))
    # a target behind: turn in place towards it (decision), or plain eq 4 without it
    v, w = reference_command(1.0, -(math.pi - 0.1), 0.65, 1.0, 0.5)
    assert (v, w) == pytest.approx((0.0, 1.0))
    v, w = reference_command(1.0, -(math.pi - 0.1), 0.65, 1.0, 0.5, turn_when_behind=False)
    assert (v, w) == pytest.approx((0.65, 2 * 0.65 * math.sin(math.pi - 0.1)))


def test_eq_12_cost_by_hand_for_two_samples():
    # heading 0, target straight ahead (theta_T = 0), preferred (0.5, 0), tau = 1 s
    v = np.array([[0.5, 0.4]])
    w = np.array([[0.0, 0.5]])
    cost = vo_cost([0.0], v, w, [0.5], [0.0], [0.0], 1.0, 2.0, 3.0)
    # sample 1 is the preferred velocity, straight at the target: 0
    # sample 2: V = 0.4 (cos .5, sin .5); |V - (0.5, 0)| and shortfall 0.5 - 0.4 cos .5
    dv = math.hypot(0.4 * math.cos(0.5) - 0.5, 0.4 * math.sin(0.5))
    expected = 2.0 * dv + 3.0 * (0.5 - 0.4 * math.cos(0.5))
    np.testing.assert_allclose(cost, [[0.0, expected]], atol=1e-12)


def test_sample_into_a_static_disc_is_rejected_one_clear_of_it_accepted():
    pose = np.array([[0.0, 0.0, 0.0]])
    v = np.array([[0.5, 0.5]])
    w = np.array([[0.0, 1.0]])  # straight at the disc; turning left away from it
    pts = rollout(pose, v, w, 0.1, 30, 1.0)
    # straight: x = 0.5 t exactly
    np.testing.assert_allclose(pts[0, 0, :, 0], 0.05 * np.arange(1, 31), atol=1e-12)
    reach = np.array([[0.5 + R + 0.05]])  # disc radius + robot radius + margin
    clear = path_clearance(pts, 0.1, np.array([[[2.0, 0.0]]]), np.zeros((1, 1, 2)), reach,
                           np.array([[True]]))
    assert clear[0, 0] == pytest.approx(2.0 - 1.5 - 0.8)  # 1.5 m travelled in 3 s: inside
    assert clear[0, 0] < 0.0 < clear[0, 1]
    # the controller picks the accepted one although its target is behind the disc
    c = ctrl(v_scenario(circles=[((2.0, 0.0), 0.5)]), include_preferred=False)
    cmd = c.act(observation([[0.0, 0.0, 0.0]], [[4.0, 0.0]], leader=(4.0, 0.0, 0.0, 0.0, 0.0)))
    assert c.last_fallbacks == 0
    pts = rollout(np.array([[0.0, 0.0, 0.0]]), cmd[:, :1], cmd[:, 1:], 0.1, 30, 1.0)
    assert np.linalg.norm(pts[0, 0] - [2.0, 0.0], axis=-1).min() >= 0.8 - 1e-9
    assert abs(cmd[0, 1]) > 0.0


def test_fallback_when_every_sample_is_rejected():
    # a human right on top of the robot: every path starts inside it
    obs = observation([[0.0, 0.0, 0.0]], [[3.0, 0.0]], humans=[((0.3, 0.0), (0.0, 0.0), 0.3)])
    c = ctrl()
    cmd = c.act(obs)
    assert c.last_fallbacks == 1
    assert cmd[0, 0] == 0.0  # least penetration: not forwards into it
    c = ctrl(fallback="stop")
    np.testing.assert_array_equal(c.act(obs), [[0.0, 0.0]])
    assert c.last_fallbacks == 1


def test_followers_use_the_leader_robots_broadcast_state():
    # robot 0 at (5, 5) moving +y; the follower's V slot (left, rank 1) turns with it
    sc = v_scenario()
    c = ctrl(sc)
    off = sc.offsets
    obs = observation([[5.0, 5.0, 0.0], [3.0, 3.0, 0.0]], [[6.0, 5.0], [0.0, 0.0]],
                      leader=(6.0, 5.0, 0.0, 0.4, 0.0),
                      nb=[(0, (5.0, 5.0), (0.0, 0.5))])
    obs = Observation(obs.t, obs.dt, obs.robot_ids, obs.pose, obs.velocity, obs.twist, None,
                      obs.neighbours, obs.obstacles, obs.leader, obs.goal, off[:2], obs.slot)
    tg = c.targets(obs)
    np.testing.assert_allclose(tg[0], [6.0, 5.0])  # the leader robot: its slot
    np.testing.assert_allclose(tg[1], formation_target([5.0, 5.0, math.pi / 2], off[1]))
    c = ctrl(sc, follow="virtual")
    np.testing.assert_allclose(c.targets(obs), obs.slot)


def test_distributed_rows():
    sc = v_scenario(circles=[((6.0, 5.3), 0.3)], humans=[HEAD_ON])
    from tests.helpers import Capture

    cap = Capture(make_controller("lf_vo"))
    Simulator(sc, cap).run()
    c = ctrl(sc)
    for k in (0, 40, 80):
        assert_distributed(c, cap.obs[k])


def test_robots_are_checked_over_robot_horizon_humans_over_horizon():
    """The same approaching disc is in the VO as a human (5 s), not yet as a robot (2 s)."""
    c = ctrl()
    pose = [[0.0, 0.0, 0.0]]
    v, w = np.array([[0.5]]), np.array([[0.0]])  # straight on at 0.5 m/s
    # the other disc at (4, 0) comes at 0.5 m/s: contact (reach 0.55 m) after 3.45 s
    as_robot = observation(pose, [[9.0, 0.0]], nb=[(1, [4.0, 0.0], [-0.5, 0.0])])
    as_human = observation(pose, [[9.0, 0.0]], humans=[((4.0, 0.0), (-0.5, 0.0), R)])
    assert c.clearance(as_robot, v, w)[0, 0] == pytest.approx(4.0 - 2.0 - 0.55)
    assert c.clearance(as_human, v, w)[0, 0] < 0.0
    # a robot at its target holds its place: the other robots are not checked
    assert c.clearance(as_robot, v, w, hold=np.array([True]))[0, 0] == np.inf


def test_a_robot_at_its_target_stops_and_holds_its_place():
    v, w = reference_command([0.05, 0.5], [1.0, 1.0], 0.5, 1.0, 0.5, arrival_radius=0.1)
    np.testing.assert_array_equal(v[:1], [0.0])
    np.testing.assert_array_equal(w[:1], [0.0])
    assert v[1] == pytest.approx(0.5) and w[1] != 0.0
    # a neighbour heading straight at it: a robot at its target stays, one short of it yields
    nb = [(1, [1.0, 0.0], [-0.5, 0.0])]
    at = observation([[0.0, 0.0, 0.0]], [[0.05, 0.0]], nb=nb)
    short = observation([[0.0, 0.0, 0.0]], [[0.5, 0.0]], nb=nb)
    c = ctrl()
    np.testing.assert_array_equal(c.act(at), [[0.0, 0.0]])
    assert not np.array_equal(c.act(short), [[0.0, 0.0]])


def test_head_on_human_is_avoided_where_goto_slot_hits_it():
    sc = v_scenario(humans=[HEAD_ON], t_max=60.0)
    log = run_scenario(sc, "lf_vo")
    assert log.collision_events.sum() == 0
    gap = np.linalg.norm(log.pose[:, :, None, :2] - log.dyn_pos[:, None], axis=-1)
    assert gap.min() >= R + 0.3 - 1e-9
    assert log.meta["reached_goal"]
    assert run_scenario(sc, "goto_slot").collision_events.sum() > 0


def test_followers_reach_the_v_behind_the_leader_in_free_space():
    sc = v_scenario(poses=[[2.0, 5.0, 0.0], [0.5, 3.0, 0.5], [0.0, 7.0, -0.5]])
    log = run_scenario(sc, "lf_vo")
    assert log.meta["reached_goal"]
    assert log.collision_events.sum() == 0
    # the shape relative to robot 0 (what the followers track) is the V, each robot lagging
    # its target by about v * reach_time = 0.4 m/s * 0.5 s along the heading (+x)
    rel = log.pose[-1, 1:, :2] - log.pose[-1, 0, :2]
    want = sc.offsets[1:] - sc.offsets[0]
    np.testing.assert_allclose(rel[:, 1], want[:, 1], atol=0.05)
    np.testing.assert_allclose(rel[:, 0], want[:, 0] - 0.2, atol=0.05)
    err = np.linalg.norm(log.pose[-1, :, :2] - log.slots[-1], axis=1)
    assert err.max() < sc.spec.leader.settle_tolerance
    start_err = np.linalg.norm(log.pose[0, :, :2] - log.slots[0], axis=1)
    assert start_err[1:].min() > 1.0


def test_same_seed_same_digest():
    sc = v_scenario(humans=[HEAD_ON], team={"n": 3, "start_noise": 0.05})
    a, b = run_scenario(sc, "lf_vo", seed=4), run_scenario(sc, "lf_vo", seed=4)
    assert a.digest() == b.digest()
    assert run_scenario(sc, "lf_vo", seed=5).digest() != a.digest()


def test_bad_params_raise_clear_errors():
    with pytest.raises(ScenarioError, match="controllers.lf_vo.v_samples"):
        make_controller("lf_vo", {"v_samples": 1})
    with pytest.raises(ScenarioError, match="controllers.lf_vo.follower_v_max"):
        make_controller("lf_vo", {"follower_v_max": 0.0})
    with pytest.raises(ScenarioError, match="did you mean 'horizon'"):
        make_controller("lf_vo", {"horizn": 2.0})
    with pytest.raises(ScenarioError, match="controllers.lf_vo.fallback"):
        make_controller("lf_vo", {"fallback": "panic"})
    with pytest.raises(ValueError, match="leader_index = 5"):
        ctrl(leader_index=5)


def random_world(rng, n, q=10, c=12, size=8.0):
    """Random poses, static discs and per-robot moving discs with padding, (N, Q) rows."""
    pose = np.column_stack((rng.uniform(0, size, (n, 2)), rng.uniform(-4.0, 4.0, n)))
    circles = rng.uniform(0, size, (c, 2))
    circle_reach = rng.uniform(0.2, 1.0, c) + 0.5
    pos = pose[:, None, :2] + rng.normal(0.0, 1.5, (n, q, 2))
    vel = rng.normal(0.0, 0.4, (n, q, 2))
    reach = rng.uniform(0.4, 0.9, (n, q))
    mask = rng.random((n, q)) < 0.6
    mask[:7] = False  # robots whose per-robot rows are all padding
    return pose, circles, circle_reach, pos, vel, reach, mask


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fast_clearance_equals_the_numpy_reference(seed):
    rng = np.random.default_rng(seed)
    n, nv, nw, h = 120, 11, 21, 30
    pose, circles, circle_reach, pos, vel, reach, mask = random_world(rng, n)
    v_max = rng.uniform(0.2, 0.7, n)
    v = np.repeat(v_max[:, None] * np.linspace(0.0, 1.0, nv), nw, axis=1)
    w = np.tile(np.linspace(-1.0, 1.0, nw), (n, nv))
    v = np.column_stack((v, rng.uniform(0.0, 0.5, n)))  # a preferred command per robot
    w = np.column_stack((w, rng.uniform(-1.0, 1.0, n)))
    pts = rollout(pose, v, w, 0.1, h, 1.0)
    ref = path_clearance(pts, 0.1, np.concatenate((np.broadcast_to(circles, (n, 12, 2)), pos), 1),
                         np.concatenate((np.zeros((n, 12, 2)), vel), 1),
                         np.concatenate((np.broadcast_to(circle_reach, (n, 12)), reach), 1),
                         np.concatenate((np.ones((n, 12), dtype=bool), mask), 1))
    for stride in (nw, 0, 5):  # the trig reuse is only a speed-up
        fast = vo_clearance(pose, v, w, 0.1, h, 1.0, pos, vel, reach, mask, circles,
                            circle_reach, w_stride=stride)
        assert np.isfinite(ref).all()
        np.testing.assert_allclose(fast, ref, rtol=0.0, atol=1e-12)
    assert (ref < 0.0).any() and (ref > 0.0).any()
    # moving discs only: robots with nothing but padding get inf, as in the reference
    ref = path_clearance(pts, 0.1, pos, vel, reach, mask)
    fast = vo_clearance(pose, v, w, 0.1, h, 1.0, pos, vel, reach, mask, w_stride=nw)
    assert np.isinf(ref[:7]).all() and np.isfinite(ref[7:]).all()
    np.testing.assert_array_equal(np.isinf(fast), np.isinf(ref))
    np.testing.assert_allclose(fast[7:], ref[7:], rtol=0.0, atol=1e-12)
    # no obstacle columns at all
    empty = np.zeros((n, 0, 2))
    assert np.isinf(vo_clearance(pose, v, w, 0.1, h, 1.0, empty, empty, np.zeros((n, 0)),
                                 np.zeros((n, 0), dtype=bool))).all()


def random_observation(rng, n, k=8, m=3, size=8.0):
    """A crowd of ``n`` robots with random per-robot neighbours and humans (padded)."""
    pose, *_ = random_world(rng, n, q=1, size=size)
    idx = rng.integers(0, n, (n, k))
    idx[rng.random((n, k)) < 0.3] = -1
    idx[:3] = -1
    pos = np.where((idx >= 0)[..., None], pose[:, None, :2] + rng.normal(0, 1.2, (n, k, 2)), 0.0)
    vel = np.where((idx >= 0)[..., None], rng.normal(0, 0.3, (n, k, 2)), 0.0)
    dist = np.where(idx >= 0, np.linalg.norm(pos - pose[:, None, :2], axis=-1), np.inf)
    hm = rng.random((n, m)) < 0.5
    hp = np.where(hm[..., None], pose[:, None, :2] + rng.normal(0, 2.0, (n, m, 2)), 0.0)
    hv = np.where(hm[..., None], rng.normal(0, 0.5, (n, m, 2)), 0.0)
    hr = np.where(hm, rng.uniform(0.2, 0.4, (n, m)), 0.0)
    slot = pose[:, :2] + rng.normal(0, 3.0, (n, 2))
    leader = np.array([size / 2, size / 2, 0.3, 0.4, 0.0])
    return Observation(0.0, 0.1, np.arange(n), pose, np.zeros((n, 2)), np.zeros((n, 2)), None,
                       Neighbours(idx, pos, vel, dist), MovingObstacles(hp, hv, hr, hm), leader,
                       np.zeros(2), rng.normal(0, 1.0, (n, 2)), slot)


@pytest.mark.parametrize("params", [{}, {"fallback": "stop", "follow": "virtual"},
                                    {"avoid_robots": False, "include_preferred": False},
                                    {"arrival_radius": 2.0, "robot_horizon": 5.0}])
def test_numba_and_numpy_kernels_give_the_same_commands(params):
    rng = np.random.default_rng(11)
    circles = [(tuple(rng.uniform(0, 8, 2)), float(rng.uniform(0.2, 0.6))) for _ in range(10)]
    sc = v_scenario(circles=circles)
    fast, ref = ctrl(sc, **params), ctrl(sc, kernel="numpy", **params)
    # 3 x 60 robots (each robot's choice is its own; the numpy reference takes about 25 ms a
    # robot, which made 3 x 150 the slowest test of the module)
    fell = 0
    for _ in range(3):
        obs = random_observation(rng, 60)
        np.testing.assert_array_equal(fast.act(obs), ref.act(obs))
        assert fast.last_fallbacks == ref.last_fallbacks
        fell += fast.last_fallbacks
    assert 0 < fell < 3 * 60  # both branches (safe argmin, fallback argmax) are exercised


def test_numba_and_numpy_kernels_give_the_same_run():
    sc = v_scenario(circles=[((6.0, 5.3), 0.3)], humans=[HEAD_ON], t_max=15.0)
    fast = run_scenario(sc, "lf_vo")
    ref = Simulator(sc, ctrl(sc, kernel="numpy")).run()
    assert fast.digest() == ref.digest()


def test_escape_turn_lets_a_robot_on_a_discs_margin_turn_away():
    # paper 002, -90 deg, seed 3 at 11 s: Robot 3 on disc A's margin (clearance ~0), its
    # target beyond the disc; every sample that moves dips inside the margin
    sc = v_scenario(circles=[((4.5, 5.0), 0.4)])
    obs = observation([[4.405, 5.694, -0.304]], [[10.66, 4.94]],
                      leader=(11.0, 5.0, 0.0, 0.0, 0.0))
    c = ctrl(sc)
    np.testing.assert_array_equal(c.act(obs), [[0.0, 0.0]])  # the penalties pick (0, 0)
    c = ctrl(sc, escape_turn=True)
    cmd = c.act(obs)
    assert c.last_fallbacks == 0
    assert cmd[0, 0] == 0.0 and cmd[0, 1] > 0.0  # turns in place, left, away from the disc


def test_escape_turn_frees_robot_3_of_the_papers_minus_90_degree_run():
    from pathlib import Path

    from dfcoa_opt.scenario.loader import load_scenario

    path = Path(__file__).resolve().parents[1] / "scenarios" / "paper002" / "lf_vo_m90deg.toml"
    lengths = {}
    for esc in (False, True):
        sc = load_scenario(path, 3, {"controllers.lf_vo.escape_turn": esc})
        log = run_scenario(sc, "lf_vo", seed=3)
        lengths[esc] = float(np.sum(np.linalg.norm(np.diff(log.pose[:, 2, :2], axis=0), axis=1)))
    assert lengths[False] < 6.0 < 13.0 < lengths[True]  # stuck at disc A; then through
