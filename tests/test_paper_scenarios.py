"""Smoke runs of every paper-002 and paper-004 scenario with its controller, collisions counted."""

from pathlib import Path

import numpy as np
import pytest

from dfcoa_opt.bench.recipes.paper002 import TARGET_TOL, time_to_target
from dfcoa_opt.metrics.robots import collisions_per_robot, path_length_per_robot
from dfcoa_opt.scenario.loader import load_scenario
from dfcoa_opt.sim.simulator import run_scenario

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"


@pytest.mark.parametrize("name", ["lf_vo_0deg", "lf_vo_m45deg", "lf_vo_m90deg"])
def test_paper002_scenario_runs_to_the_target_without_collision(name):
    sc = load_scenario(str(SCENARIOS / f"paper002/{name}.toml"))
    log = run_scenario(sc, "lf_vo")
    goal = np.asarray(sc.spec.leader.goal)
    assert np.isfinite(time_to_target(log, goal))  # Robot 1 within TARGET_TOL of the goal
    assert np.linalg.norm(log.pose[-1, 0, :2] - goal) <= TARGET_TOL
    hits = collisions_per_robot(log)
    assert hits.sum() == 0, hits
    # the humans really crossed the formation's route: they came within 2 m of a robot
    gap = np.linalg.norm(log.pose[:, :, None, :2] - log.dyn_pos[:, None], axis=-1)
    assert gap.min() < 2.0


@pytest.mark.parametrize("k", [0, 1, 2, 3])
@pytest.mark.parametrize("n", [5, 10, 15, 20])
def test_paper004_scenario_runs_to_the_goal(n, k):
    sc = load_scenario(str(SCENARIOS / f"paper004/vs_n{n}_dyn{k}.toml"))
    log = run_scenario(sc, "virtual_spring")
    assert log.n_robots == n and log.dyn_pos.shape[1] == k
    # the leader robot reaches the goal; every robot moved the whole route
    assert np.linalg.norm(log.pose[-1, 0, :2] - sc.spec.leader.goal) < 0.5
    assert path_length_per_robot(log).min() > 30.0
    # seed 0: at most one contact onset (n = 15 with 1-2 obstacle robots, n = 20 with 3);
    # goto_slot, which does not avoid, has 3 (n = 5) and 32 (n = 20) with 3 obstacle robots
    assert collisions_per_robot(log).sum() <= 1
