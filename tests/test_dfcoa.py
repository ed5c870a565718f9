"""The composed ``dfcoa`` controller: distributed rows, S1/S2 integration runs."""

from pathlib import Path

import numpy as np
import pytest

from dfcoa_opt import metrics
from dfcoa_opt.control.registry import make_controller
from dfcoa_opt.scenario.loader import load_scenario
from dfcoa_opt.sim.simulator import Simulator, run_scenario
from tests.helpers import Capture

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"


def test_rows_depend_only_on_their_own_observation():
    sc = load_scenario(SCENARIOS / "dfcoa_s1.toml", overrides={"t_max": 40.0})
    cap = Capture(make_controller("dfcoa"))
    Simulator(sc, cap).run()
    near = [o for o in cap.obs if np.min(o.scan.ranges) < 0.8]  # VFH* safety layer active
    assert near
    obs = near[len(near) // 2]
    full = make_controller("dfcoa")
    full.reset(sc, np.random.default_rng(0))
    want = full.act(obs)
    for i in range(sc.n):
        alone = make_controller("dfcoa")
        alone.reset(sc, np.random.default_rng(0))
        np.testing.assert_array_equal(alone.act(obs.take([i]))[0], want[i])


def test_without_avoidance_it_is_the_formation_law():
    from dfcoa_opt.control.dfcoa.formation_law import formation_tracking_law

    sc = load_scenario(SCENARIOS / "dfcoa_s2.toml", overrides={"t_max": 3.0})
    cap = Capture(make_controller("dfcoa", {"avoidance": False}))
    Simulator(sc, cap).run()
    obs = cap.obs[-1]
    np.testing.assert_array_equal(cap.inner.act(obs), formation_tracking_law(
        obs.slot_offset, obs.pose, obs.leader, 2.8, 0.7, 0.98))


@pytest.mark.parametrize("name, t_max", [("dfcoa_s1", 40.0), ("dfcoa_s2", 30.0)])
def test_numba_kernels_give_the_reference_run(name, t_max):
    """kernel=True (numba) and kernel=False (NumPy reference) give the same log, bit for bit."""
    sc = load_scenario(SCENARIOS / f"{name}.toml", overrides={"t_max": t_max})
    logs = []
    for kernel in (True, False):
        ctrl = make_controller("dfcoa")
        ctrl.kernel = kernel
        logs.append(Simulator(sc, ctrl).run())
    assert np.nanmin(logs[0].clearance) < 0.8  # the VFH* layer was active
    assert logs[0].digest() == logs[1].digest()


@pytest.mark.parametrize("name", ["dfcoa_s1", "dfcoa_s2"])
def test_paper_scenarios_reach_the_goal_without_collision(name):
    sc = load_scenario(SCENARIOS / f"{name}.toml")
    log = run_scenario(sc, "dfcoa")
    s = metrics.summary(log, sc.spec.metrics)
    assert s["success"] and s["collisions"] == 0
    assert s["min_inter_robot_distance"] > 2 * sc.spec.robots.radius


def _ground_speed(log):
    """(T-1, N) speed of each robot over the ground, push included (m/s)."""
    return np.linalg.norm(np.diff(log.pose[..., :2], axis=0), axis=2) / np.diff(log.t)[:, None]


def test_s2_disturbance_gives_the_papers_a1_transient_and_is_rejected():
    """Paper 000 §5.2.2: a1 peaks near 1.5 m/s, turns hard, all at 0.3 m/s by 30 s.

    The push adds a hard turn the other way. The paper's ±1.5 rad/s is not
    reproduced: a1's largest |ω| in t_0 is 1.26 rad/s, from the formation
    assembling at t = 0.5 s, and the push's turn peaks at -0.80 rad/s
    (docs/reproduction.md, Scenario 2).
    """
    sc = load_scenario(SCENARIOS / "dfcoa_s2.toml", overrides={"t_max": 30.0})
    dist = sc.spec.disturbances[0]
    undisturbed = load_scenario(SCENARIOS / "dfcoa_s2.toml",
                                overrides={"t_max": 30.0, "disturbances": []})
    log, ref = run_scenario(sc, "dfcoa"), run_scenario(undisturbed, "dfcoa")
    speed, ref_speed = _ground_speed(log), _ground_speed(ref)
    push = (log.t[1:] > dist.t_start) & (log.t[1:] <= dist.t_end)
    assert 1.4 <= speed[push, 0].max() <= 1.6  # paper: peak ≈ 1.5 m/s
    assert ref_speed[:, 0].max() <= sc.spec.robots.v_max + 1e-9
    assert speed[push, 1:].max() <= sc.spec.robots.v_max + 1e-9  # only a1 is pushed
    after = (log.t >= dist.t_start) & (log.t < dist.t_end + 5.0)
    assert log.twist[after, 0, 1].min() < ref.twist[after, 0, 1].min() - 0.5  # the push's turn
    err = np.linalg.norm(log.slots[:, 0] - log.pose[:, 0, :2], axis=1)
    ref_err = np.linalg.norm(ref.slots[:, 0] - ref.pose[:, 0, :2], axis=1)
    assert err[log.t <= dist.t_end].max() > ref_err.max() + 0.5  # the push displaces a1
    late = log.t >= 20.0
    np.testing.assert_allclose(err[late], ref_err[late], atol=0.05)  # and is rejected
    np.testing.assert_allclose(log.twist[-1, :, 0], 0.3, atol=0.02)  # paper: 0.3 m/s by 30 s
    assert metrics.summary(log, sc.spec.metrics)["collisions"] == 0
