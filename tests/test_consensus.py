"""Paper 001's consensus controllers (eq 14) and (eq 15-17): comparisons/consensus.py.

Oracles: a hand evaluation of eq 14; the exact discrete-time linear system that
the simulator's explicit Euler makes of eq 14 (and of eq 15 in free space with
the 'arrival' law); the eigenvalues of that system for eq 21's topology.
"""

import numpy as np
import pytest

from comparisons.consensus import Consensus, ConsensusIvo
from dfcoa_opt.control.base import STATUS_OK, MovingObstacles, Observation, slot_velocity
from dfcoa_opt.control.registry import build_controller, make_controller
from dfcoa_opt.core.errors import ScenarioError
from dfcoa_opt.scenario.loader import scenario_from_dict
from dfcoa_opt.sim.simulator import Simulator, run_scenario
from dfcoa_opt.world.robots.models import integrate_unicycle
from tests.helpers import Capture, assert_distributed, neighbours_from_lists

K1, K2, K3 = 0.25, 0.45, 37.5  # paper 001, section V.B
DT = 0.01  # s; explicit Euler needs K3 * DT < 2
DELTA = np.array([[1.0, 1.0], [-1.0, 1.0], [1.0, -1.0]])  # paper's Delta_i, world frame, m
START = [[3.0, 0.0], [0.0, 3.0], [-3.0, 0.0]]  # Table II, m
V_MAX_PAPER = 3.0 * np.sqrt(2.0)  # |[3, 3]|, m/s


def rot(th):
    return np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])


def table2(controllers=None, t_max=40.0, speed=V_MAX_PAPER, v_max=100.0, **extra):
    """Table II: three robots at rest, leader from (0, 0) at ``speed`` along 45 deg.

    The paper's Delta_i are world vectors and its leader moves along [3, 3]
    (heading 45 deg): the leader-frame offsets are R(-45 deg) Delta_i. The goal
    lies beyond where the leader gets in ``t_max``, so v_L stays constant.
    """
    heading = np.pi / 4
    far = speed * t_max + 10.0
    data = {"name": "table2", "dt": DT, "t_max": t_max, "seed": 0,
            "world": {"size": [far + 20.0, far + 20.0], "origin": [-10.0, -10.0],
                      "resolution": 1},
            "robots": {"model": "double_integrator", "radius": 0.5, "v_max": v_max,
                       "a_max": 1000.0},
            "team": {"n": 3, "placement": "explicit", "poses": [[*p, 0.0] for p in START]},
            "formation": {"shape": "offsets", "offsets": (DELTA @ rot(heading)).tolist()},
            "leader": {"start": [0.0, 0.0], "goal": [far * np.cos(heading), far * np.sin(heading)],
                       "speed": speed, "heading": heading},
            "sensors": {"lidar": {"enabled": False}},
            "controllers": controllers or {}, **extra}
    return scenario_from_dict(data, "<table2>")


def corridor(controllers=None, obstacle=True, comm_radius=10.0, t_max=25.0, dt=DT):
    """Leader along +x at 1 m/s, robots start on their slots, a pentagon on robots 0-1's line."""
    shapes = [{"type": "polygon", "vertices": [[6.0, 0.5], [7.5, 0.3], [7.8, 1.5], [6.8, 2.2],
                                               [5.8, 1.6]]}] if obstacle else []
    data = {"name": "corridor", "dt": dt, "t_max": t_max, "seed": 0,
            "world": {"size": [30.0, 12.0], "origin": [-3.0, -6.0], "resolution": 5,
                      "obstacles": shapes},
            "robots": {"model": "double_integrator", "radius": 0.5, "v_max": 3.0,
                       "a_max": 1000.0},
            "team": {"n": 3, "placement": "explicit",
                     "poses": [[x, y, 0.0] for x, y in DELTA.tolist()]},
            "formation": {"shape": "offsets", "offsets": DELTA.tolist()},
            "leader": {"start": [0.0, 0.0], "goal": [20.0, 0.0], "speed": 1.0, "heading": 0.0,
                       "settle_tolerance": 0.05},
            "sensors": {"lidar": {"enabled": False}, "comm_radius": comm_radius},
            "controllers": controllers or {}}
    return scenario_from_dict(data, "<corridor>")


def errors(log):
    """Leader-relative errors x^ (T, N, 2) and v^ (T, N, 2) of a straight-leader run."""
    th = log.leader[:, 2]
    v_l = log.leader[:, 3, None] * np.column_stack((np.cos(th), np.sin(th)))
    return log.pose[:, :, :2] - log.slots, log.velocity - v_l[:, None, :]


def hat_laplacian(b=1.0):
    """L + diag(b) of eq 21's complete graph on three robots."""
    return 3.0 * np.eye(3) - np.ones((3, 3)) + b * np.eye(3)


def euler_replay(x0, v0, steps, a_x, a_v):
    """Iterate x+ = x + dt v, v+ = v + dt (a_x x + a_v v) (3x3 blocks, each column a coordinate)."""
    m = np.eye(6) + DT * np.block([[np.zeros((3, 3)), np.eye(3)], [a_x, a_v]])
    z = np.concatenate((x0, v0))
    out = [z]
    for _ in range(steps - 1):
        z = m @ z
        out.append(z)
    out = np.array(out)
    return out[:, :3], out[:, 3:]


def oscillator_rate(e, de, t, lam, window):
    """Decay rate of ``Q = |de + s e|^2 + w^2 |e|^2`` (``lam = -s + i w``), fitted in ``window``.

    For a mode with the eigenvalues ``-s +- i w``, ``Q`` is exactly ``Q0 exp(-2 s t)``.
    """
    s, w = -lam.real, abs(lam.imag)
    q = ((de + s * e) ** 2).sum(axis=-1) + w**2 * (e**2).sum(axis=-1)
    sel = (t > window[0]) & (t < window[1])
    return -0.5 * np.polyfit(t[sel], np.log(q[sel]), 1)[0], q


def hand_observation(pos, vel, leader, slot_offsets, neighbours):
    """A 3-robot observation; ``neighbours[i]`` = robot i's neighbour indices."""
    n = len(pos)
    nb = neighbours_from_lists(pos, vel, neighbours, k=2)
    slots = leader[:2] + slot_offsets @ rot(leader[2]).T
    pose = np.column_stack((pos, np.zeros(n)))
    return Observation(0.0, DT, np.arange(n), pose, vel, np.zeros((n, 2)), None, nb,
                       MovingObstacles(np.zeros((n, 0, 2)), np.zeros((n, 0, 2)), np.zeros((n, 0)),
                                       np.zeros((n, 0), bool)),
                       np.asarray(leader, float), np.zeros(2), slot_offsets, slots)


POS = np.array([[3.1, -0.4], [0.2, 2.7], [-2.9, 0.3]])
VEL = np.array([[0.5, -1.0], [1.5, 0.25], [-0.75, 2.0]])
OFFSETS = DELTA  # corridor()'s leader-frame offsets


@pytest.mark.parametrize("b", [1.0, 0.4])
def test_eq14_by_hand(b):
    """Eq 14 term by term, with world Delta_i = R(theta) offsets_i; robot 0 does not see 2."""
    leader = np.array([0.5, -0.2, 0.3, 2.0, 0.0])  # omega = 0: the paper's constant Delta
    neighbours = [[1], [0, 2], [1]]
    obs = hand_observation(POS, VEL, leader, OFFSETS, neighbours)
    ctrl = Consensus(Consensus.Params(b=b))
    ctrl.reset(corridor(obstacle=False), None)  # its offsets are OFFSETS
    delta = OFFSETS @ rot(0.3).T
    x_l, v_l = leader[:2], 2.0 * np.array([np.cos(0.3), np.sin(0.3)])
    expect = np.zeros((3, 2))
    for i in range(3):
        pos_term = b * (POS[i] - x_l - delta[i])
        vel_term = b * (VEL[i] - v_l)
        for j in neighbours[i]:  # a_ij = 1
            pos_term = pos_term + (POS[i] - POS[j] - delta[i] + delta[j])
            vel_term = vel_term + (VEL[i] - VEL[j])
        expect[i] = -K1 * pos_term - K2 * vel_term
    np.testing.assert_allclose(ctrl.act(obs), expect, rtol=0, atol=1e-12)


def test_a_formation_that_turns_with_the_leader_needs_no_correction():
    """omega != 0: robots on their slots, moving with the slot velocities, get u_c = 0."""
    leader = np.array([0.5, -0.2, 0.3, 2.0, 0.7])
    slots = leader[:2] + OFFSETS @ rot(0.3).T
    vel = slot_velocity(leader, slots)
    obs = hand_observation(slots, vel, leader, OFFSETS, [[1, 2], [0, 2], [0, 1]])
    ctrl = Consensus(Consensus.Params())
    ctrl.reset(corridor(obstacle=False), None)
    np.testing.assert_allclose(ctrl.act(obs), 0.0, atol=1e-12)


def test_slot_velocity_is_the_derivative_of_the_slot():
    leader = np.array([1.0, 2.0, 0.4, 0.8, 0.6])
    h = 1e-6
    moved = integrate_unicycle(leader[:3], leader[3], leader[4], h)
    fd = ((moved[:2] + OFFSETS @ rot(moved[2]).T) - (leader[:2] + OFFSETS @ rot(0.4).T)) / h
    np.testing.assert_allclose(slot_velocity(leader, leader[:2] + OFFSETS @ rot(0.4).T), fd,
                               atol=1e-5)


@pytest.mark.parametrize("law", ["unit", "arrival"])
def test_eq15_k3_term_uses_world_velocities(law):
    """Free space, no robot constraint active: u = u_c - k3 (v - w), w = disc(vslot + v_pref).

    Decision 1: the k3 term compares the robot's world velocity with the safe
    world velocity (slot velocity plus eq 17's leader-relative v_pref).
    """
    sc = corridor(obstacle=False)
    leader = np.array([0.5, -0.2, 0.0, 1.0, 0.0])
    pos = leader[:2] + DELTA + np.array([[-0.2, 0.0], [0.05, 0.0], [0.0, 0.0]])
    vel = np.array([[1.2, 0.1], [0.9, -0.2], [1.0, 0.0]])
    obs = hand_observation(pos, vel, leader, DELTA, [[1, 2], [0, 2], [0, 1]])
    ctrl = make_controller("consensus_ivo", {"pref_law": law})
    ctrl.reset(sc, np.random.default_rng(0))
    base = Consensus(Consensus.Params())
    base.reset(sc, None)
    u = ctrl.act(obs)
    v_max = sc.spec.robots.v_max  # 3 m/s
    if law == "unit":  # v_max towards the slot (0.2 m and 0.05 m away), 0 on it
        pref = np.array([[v_max, 0.0], [-v_max, 0.0], [0.0, 0.0]])
        w = np.array([[v_max, 0.0], [1.0 - v_max, 0.0], [1.0, 0.0]])  # robot 0: (4, 0) -> disc
        assert list(ctrl.last_result.status) == [1, 0, 0]  # STATUS_MODIFIED by the disc
    else:  # within arrival_radius = 1 m: v_max (slot - x) / 1 m
        pref = v_max * (obs.slot - pos)
        w = np.array([1.0, 0.0]) + pref
        assert np.all(ctrl.last_result.status == STATUS_OK)
    np.testing.assert_allclose(ctrl.last_result.command, w, atol=1e-12)
    np.testing.assert_allclose(u, base.act(obs) - K3 * (vel - w), atol=1e-9)


def test_consensus_converges_at_the_rate_of_its_eigenvalues():
    """Table II start, no obstacle, pure eq 14: the run is the linear system, to 1e-9 m.

    x^ and v^ obey x^'' = -k1 L^ x^ - k2 L^ v^ (L^ = L + diag(b)); the simulator's
    explicit Euler makes that x^+ = x^ + dt v^, v^+ = v^ + dt x^''. Eq 21: the
    eigenvalues of L^ are 1 (centroid) and 4, 4 (shape), so the modes decay as
    s^2 + k2 l s + k1 l = 0: -0.225 +- 0.447i (centroid) and -0.9 +- 0.436i (shape).
    """
    sc = table2()
    log = run_scenario(sc, "consensus")
    assert np.abs(log.leader[:, 4]).max() < 1e-9  # straight leader: Delta_i constant
    assert np.linalg.norm(log.velocity, axis=-1).max() < 0.5 * sc.spec.robots.v_max  # linear
    assert np.linalg.norm(log.command, axis=-1).max() < 0.5 * sc.spec.robots.a_max
    x_hat, v_hat = errors(log)
    lhat = hat_laplacian()
    xr, vr = euler_replay(x_hat[0], v_hat[0], len(log.t), -K1 * lhat, -K2 * lhat)
    np.testing.assert_allclose(x_hat, xr, rtol=0, atol=1e-9)
    np.testing.assert_allclose(v_hat, vr, rtol=0, atol=1e-9)

    a = np.block([[np.zeros((3, 3)), np.eye(3)], [-K1 * lhat, -K2 * lhat]])
    lams = np.linalg.eigvals(a)
    slow, fast = lams[np.argmax(lams.real)], lams[np.argmin(lams.real)]
    np.testing.assert_allclose([slow.real, abs(slow.imag)], [-0.225, np.sqrt(0.25 - 0.225**2)])
    np.testing.assert_allclose([fast.real, abs(fast.imag)], [-0.9, np.sqrt(1.0 - 0.81)])
    t = log.t
    c, dc = x_hat.mean(axis=1), v_hat.mean(axis=1)  # eq 4: centroid error
    rate_c, q_c = oscillator_rate(c, dc, t, slow, (5.0, 35.0))
    e, de = x_hat[:, 0] - x_hat[:, 1], v_hat[:, 0] - v_hat[:, 1]  # a shape error
    rate_s, _ = oscillator_rate(e, de, t, fast, (1.0, 15.0))
    assert rate_c == pytest.approx(0.225, rel=0.01)  # measured 0.2243 (Euler, dt 0.01)
    assert rate_s == pytest.approx(0.9, rel=0.01)  # measured 0.903

    # formation reached (eq 3-4) at t = 40 s; the centroid bound is the envelope
    # sqrt(Q0)/w exp(-s t) with s lowered to 0.22 for Euler: about 1.4e-3 m.
    rel_x = x_hat[-1, :, None] - x_hat[-1, None, :]  # x_i - x_j - (Delta_i - Delta_j)
    rel_v = log.velocity[-1, :, None] - log.velocity[-1, None, :]
    assert np.linalg.norm(rel_x, axis=-1).max() < 1e-9  # shape modes: e^(-0.9 * 40)
    assert np.linalg.norm(rel_v, axis=-1).max() < 1e-9
    bound = np.sqrt(q_c[0]) / abs(slow.imag) * np.exp(-0.22 * t[-1])
    assert bound < 2e-3
    assert np.linalg.norm(c[-1]) < bound  # measured 1.0e-3 m
    assert np.linalg.norm(v_hat[-1], axis=-1).max() < bound


def test_b_zero_leaves_the_centroid_where_it_started():
    """b = 0: 1^T L = 0, so the mean acceleration is 0 and the team ignores the leader."""
    sc = table2({"consensus": {"b": 0.0}}, t_max=20.0)
    log = run_scenario(sc, "consensus")
    centroid = log.pose[:, :, :2].mean(axis=1)
    np.testing.assert_allclose(centroid, np.broadcast_to([0.0, 1.0], centroid.shape), atol=1e-9)
    assert np.linalg.norm(log.leader[-1, :2] - centroid[-1]) > 50.0  # the leader went away
    x_hat, v_hat = errors(log)
    shape = x_hat[-1] - x_hat[-1].mean(axis=0)  # still forms the shape: rate 0.675 1/s
    assert np.abs(shape).max() < 1e-4
    lhat = hat_laplacian(0.0)
    xr, _ = euler_replay(x_hat[0], v_hat[0], len(log.t), -K1 * lhat, -K2 * lhat)
    np.testing.assert_allclose(x_hat, xr, rtol=0, atol=1e-9)


def test_consensus_ivo_arrival_law_converges_like_its_linearisation():
    """Free space, 'arrival': once the filter passes every velocity and every robot is
    within arrival_radius of its slot, eq 15 is linear,
    x^'' = -k1 L^ x^ - k2 L^ v^ - k3 (v^ + g x^), g = v_max / arrival_radius,
    and the run follows its Euler replay; slowest eigenvalue -4.62 (shape modes).
    """
    sc = table2({"consensus_ivo": {"pref_law": "arrival"}}, t_max=10.0, speed=np.sqrt(2.0),
                v_max=V_MAX_PAPER)
    log = run_scenario(sc, "consensus_ivo")
    x_hat, v_hat = errors(log)
    dist = np.linalg.norm(x_hat, axis=-1)
    free = (log.filter_status == STATUS_OK).all(axis=1) & (dist < 1.0).all(axis=1)
    k0 = int(np.nonzero(~free)[0].max()) + 1  # from here on: linear
    assert log.t[k0] < 2.0  # measured 1.09 s
    g = V_MAX_PAPER / 1.0
    lhat = hat_laplacian()
    a_x, a_v = -K1 * lhat - K3 * g * np.eye(3), -K2 * lhat - K3 * np.eye(3)
    xr, vr = euler_replay(x_hat[k0], v_hat[k0], len(log.t) - k0, a_x, a_v)
    np.testing.assert_allclose(x_hat[k0:], xr, rtol=0, atol=1e-9)
    np.testing.assert_allclose(v_hat[k0:], vr, rtol=0, atol=1e-9)
    lams = np.linalg.eigvals(np.block([[np.zeros((3, 3)), np.eye(3)], [a_x, a_v]]))
    assert lams.real.max() == pytest.approx(-4.616, abs=1e-3) and np.all(lams.imag == 0)
    assert dist[-1].max() < 1e-9 and np.linalg.norm(v_hat[-1], axis=-1).max() < 1e-9
    assert log.collision_events.sum() == 0


def test_consensus_ivo_unit_law_reaches_the_slots_but_chatters():
    """'unit' (eq 17): |v_pref| = v_max until the slot is hit, so the robots circle it.

    Measured (t > 5 s): |x^| <= 0.197 m, RMS |v^| = 2.17 m/s = 0.51 v_max, about 17
    reversals of the radial velocity per second. The neighbourhood asserted is
    2 (v_max + |v_L|) / k3 = 0.30 m: the distance covered at the largest relative
    speed in twice the velocity loop's time constant 1/k3.
    """
    v_l = np.sqrt(2.0)
    sc = table2({"consensus_ivo": {"pref_law": "unit"}}, t_max=15.0, speed=v_l,
                v_max=V_MAX_PAPER)
    log = run_scenario(sc, "consensus_ivo")
    x_hat, v_hat = errors(log)
    late = log.t > 5.0
    dist = np.linalg.norm(x_hat[late], axis=-1)
    speed = np.linalg.norm(v_hat[late], axis=-1)
    assert dist.max() < 2.0 * (V_MAX_PAPER + v_l) / K3
    assert np.sqrt((speed**2).mean()) > 0.25 * V_MAX_PAPER  # does not settle
    radial = np.sign((x_hat[late] * v_hat[late]).sum(axis=-1))
    flips = (np.diff(radial, axis=0) != 0).sum(axis=0) / (log.t[late][-1] - log.t[late][0])
    assert flips.min() > 5.0  # reversals per second
    assert log.collision_events.sum() == 0


@pytest.mark.parametrize("law", ["unit", "arrival"])
def test_consensus_ivo_avoids_the_polygon_that_consensus_hits(law):
    """The pentagon lies on the line of robots 0 and 1."""
    plain = run_scenario(corridor(), "consensus")
    assert plain.collision_events.sum() > 0  # measured 2 (robots 0 and 1)
    sc = corridor({"consensus_ivo": {"pref_law": law}})
    log = run_scenario(sc, "consensus_ivo")
    assert log.collision_events.sum() == 0
    assert log.clearance.min() >= sc.spec.robots.radius
    assert log.min_inter_robot.min() >= 2 * sc.spec.robots.radius
    assert (log.filter_status != STATUS_OK).any()  # the filter acted and was logged
    assert log.meta["reached_goal"]  # and the formation settled again after it
    pushed = np.linalg.norm(log.pose[:, :2, :2] - log.slots[:, :2], axis=-1).max()
    assert pushed > 1.0  # robots 0-1 left their slots to go round (measured 2.7-3.0 m)


def test_both_controllers_are_distributed():
    """Communication range 2.5 m: robot 0 sees 1 and 2, robots 1 and 2 only robot 0."""
    sc = corridor(comm_radius=2.5, t_max=7.0)
    cap = Capture(build_controller("consensus_ivo"))
    Simulator(sc, cap).run()
    obs = cap.obs[600]  # t = 6 s: robots 0-1 going round the pentagon
    assert (obs.neighbours.mask.sum(axis=1) < 2).any()
    assert obs.pose[:2, 0].min() > 4.0
    for cid in ("consensus", "consensus_ivo"):
        ctrl = build_controller(cid)
        ctrl.reset(sc, np.random.default_rng(0))
        assert_distributed(ctrl, obs)


@pytest.mark.parametrize("cid", ["consensus", "consensus_ivo"])
def test_same_seed_same_bits(cid):
    """Bit-identical runs for one seed (start noise drawn from it), different for another.

    ``filter_time`` is the filter's wall-clock solve time: it differs between
    identical runs, and ``RunLog.digest`` leaves it out.
    """
    sc = table2({"consensus_ivo": {"pref_law": "arrival"}}, t_max=3.0, speed=np.sqrt(2.0),
                v_max=V_MAX_PAPER, team={"n": 3, "placement": "explicit", "start_noise": 0.1,
                                         "poses": [[*p, 0.0] for p in START]})
    a, b = (run_scenario(sc, cid, seed=5) for _ in range(2))
    c = run_scenario(sc, cid, seed=6)
    for name, arr in a.arrays().items():
        if name != "filter_time":
            np.testing.assert_array_equal(arr, b.arrays()[name], err_msg=name)
    assert not np.array_equal(a.pose, c.pose)
    assert a.digest() == b.digest() != c.digest()


def test_params_are_validated_and_reach_the_filter():
    ctrl = build_controller("consensus_ivo", {"consensus_ivo": {"time_horizon": 3.0,
                                                                "k3": 20.0}})
    assert isinstance(ctrl, ConsensusIvo)
    assert ctrl._filter.p.time_horizon == 3.0 and ctrl._filter.p.obstacles == "ivo"
    assert ctrl.p.k1 == K1 and ctrl.p.k2 == K2 and ctrl.p.k3 == 20.0
    with pytest.raises(ScenarioError, match=r"f.toml: controllers.consensus_ivo.pref_law"):
        make_controller("consensus_ivo", {"pref_law": "fast"}, "f.toml")
    with pytest.raises(ScenarioError, match=r"controllers.consensus.k1: must be > 0.0"):
        make_controller("consensus", {"k1": -0.25}, "f.toml")
    with pytest.raises(ScenarioError, match=r"controllers.consensus.b: must be >= 0.0"):
        make_controller("consensus", {"b": -1.0}, "f.toml")
    with pytest.raises(ScenarioError, match="k3 dt = 2.5 must be < 2"):
        run_scenario(corridor({"consensus_ivo": {"k3": 250.0, "k3_step_limit": False}}),
                     "consensus_ivo")


def test_k3_step_limit_makes_coarse_steps_deadbeat_and_stable():
    """At dt = 0.1 s (k3 dt = 3.75) the gain used is 1/dt; the run is stable and converges.

    Without the limit the same setting is refused (explicit Euler would diverge).
    """
    sc = corridor({"consensus_ivo": {"pref_law": "arrival"}}, dt=0.1)
    ctrl = build_controller("consensus_ivo", sc.spec.controllers)
    ctrl.reset(sc, np.random.default_rng(0))
    assert ctrl._k3 == pytest.approx(10.0)
    log = run_scenario(sc, "consensus_ivo")
    assert log.collision_events.sum() == 0
    assert np.all(np.isfinite(log.velocity)) and np.abs(log.velocity).max() <= 3.0 + 1e-9
    x_hat, _ = errors(log)
    assert np.linalg.norm(x_hat[-1], axis=1).max() < 0.05
    with pytest.raises(ScenarioError, match="k3 dt = 3.75 must be < 2"):
        run_scenario(corridor({"consensus_ivo": {"k3_step_limit": False}}, dt=0.1),
                     "consensus_ivo")
