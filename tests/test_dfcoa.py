"""The composed ``dfcoa`` controller: distributed rows, S1/S2 integration runs."""

from pathlib import Path

import numpy as np
import pytest

from dfcoa_opt import metrics
from dfcoa_opt.control.registry import make_controller
from dfcoa_opt.sim.loader import load_scenario
from dfcoa_opt.sim.simulator import Simulator, run_scenario

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"


class Capture:
    """Records the observations a controller receives."""

    def __init__(self, inner):
        self.inner, self.obs = inner, []
        self.command, self.name = inner.command, inner.name

    def reset(self, scenario, rng):
        self.inner.reset(scenario, rng)

    def act(self, obs):
        self.obs.append(obs)
        return self.inner.act(obs)


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
    from dfcoa_opt.control.formation_law import formation_tracking_law

    sc = load_scenario(SCENARIOS / "dfcoa_s2.toml", overrides={"t_max": 3.0})
    cap = Capture(make_controller("dfcoa", {"avoidance": False}))
    Simulator(sc, cap).run()
    obs = cap.obs[-1]
    np.testing.assert_array_equal(cap.inner.act(obs), formation_tracking_law(
        obs.slot_offset, obs.pose, obs.leader, 2.8, 0.7, 0.98))


@pytest.mark.parametrize("name", ["dfcoa_s1", "dfcoa_s2"])
def test_paper_scenarios_reach_the_goal_without_collision(name):
    sc = load_scenario(SCENARIOS / f"{name}.toml")
    log = run_scenario(sc, "dfcoa")
    s = metrics.summary(log, sc.spec.metrics)
    assert s["success"] and s["collisions"] == 0
    assert s["min_inter_robot_distance"] > 2 * sc.spec.robots.radius
