"""The goal-slot check: where the leader ends, the boundary, and the shipped scenarios."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from dfcoa_opt.core.errors import ScenarioError
from dfcoa_opt.scenario import loader, placement
from dfcoa_opt.scenario.formation import slot_positions
from dfcoa_opt.scenario.loader import load_scenario, read_toml, scenario_from_dict
from dfcoa_opt.scenario.placement import final_leader_poses
from dfcoa_opt.scenario.scenario import Scenario
from dfcoa_opt.sim.leader import VirtualLeader

ROOT = Path(__file__).resolve().parents[1]
CORPUS = ROOT / "tests" / "data" / "bad_scenarios"
SHIPPED = sorted(p for p in (ROOT / "scenarios").rglob("*.toml") if "sweeps" not in p.parts)


def _drive(sc: Scenario) -> tuple[np.ndarray, float]:
    """Drive the simulator's virtual leader until it is at its goal: its pose and the time."""
    leader, steps = VirtualLeader(sc), 0
    while not leader.at_goal and steps * sc.spec.dt < sc.spec.t_max:
        leader.state(sc.spec.dt)
        leader.advance(sc.spec.dt)
        steps += 1
    assert leader.at_goal
    return leader.pose, steps * sc.spec.dt


def _stop_pose(sc: Scenario) -> np.ndarray:
    return _drive(sc)[0]


def _goal_clearance(sc: Scenario) -> float:
    """Smallest clearance of a formation slot over the final leader poses, m."""
    poses = final_leader_poses(sc.leader_path, sc.spec, sc.leader_heading)
    return min(float(sc.world.clearance(slot_positions(p, sc.offsets)).min()) for p in poses)


@pytest.mark.parametrize("name", ["dfcoa_s1.toml", "dfcoa_s2.toml", "example_obstacles.toml",
                                  "bench/large_100.toml"])
def test_the_final_poses_run_from_the_goal_to_where_the_simulated_leader_stops(name):
    # dfcoa_s1/s2 use improved A*, whose path ends with a 5-7 cm hop from the last cell centre
    # to the exact goal: its direction (-135 and -90 degrees) is not the arrival heading
    sc = load_scenario(ROOT / "scenarios" / name)
    poses = final_leader_poses(sc.leader_path, sc.spec, sc.leader_heading)
    assert poses.shape == (placement.GOAL_SAMPLES, 3)
    np.testing.assert_allclose(poses[0, :2], sc.spec.leader.goal, atol=1e-12)
    stop = _stop_pose(sc)
    assert np.hypot(*(stop[:2] - poses[-1, :2])) < 0.11
    assert abs(math.remainder(stop[2] - poses[-1, 2], 2 * math.pi)) < math.radians(1.2)
    assert np.all(poses[:, 2] == poses[-1, 2])


def _approach_case(**circle) -> dict:
    data = read_toml(CORPUS / "goal_slot_on_the_approach_heading.toml")
    data["world"]["obstacles"] = [{"type": "circle", "radius": 0.4, **circle}]
    return data


def test_a_short_last_hop_does_not_set_the_arrival_heading():
    # the path (2, 5) -> (15, 5.05) -> (15, 5): the last 5 cm point south
    data = _approach_case(center=[17.0, 5.0])  # 0.1 m from slot (16.5, 5) if the hop counted
    sc = scenario_from_dict(data)  # accepted: at the real heading the slots lie across x = 15
    poses = final_leader_poses(sc.leader_path, sc.spec, sc.leader_heading)
    assert poses[-1, 2] == pytest.approx(math.atan2(0.05, 13.0), abs=1e-6)
    assert _stop_pose(sc)[2] == pytest.approx(poses[-1, 2], abs=math.radians(0.1))
    assert _goal_clearance(sc) > 1.5
    with pytest.raises(ScenarioError, match=r"leader\.goal: robot 0's formation slot at the goal"):
        scenario_from_dict(_approach_case(center=[15.0, 7.0]))  # 0.1 m from slot (15, 6.5)


def _still(heading: float, obstacle: dict, start=(5.0, 5.0), goal=(5.0, 5.0)) -> dict:
    """A line of 4 robots (1 m apart) whose leader starts at (or near) its goal."""
    return {"world": {"size": [10.0, 10.0], "obstacles": [obstacle]}, "team": {"n": 4},
            "formation": {"shape": "line", "spacing": 1.0},
            "leader": {"start": list(start), "goal": list(goal), "heading": heading}}


FAR = {"type": "circle", "center": [1.0, 9.0], "radius": 0.3}


@pytest.mark.parametrize("goal", [(5.0, 5.0), (5.3, 5.1)])
def test_a_leader_that_starts_within_goal_radius_never_moves_and_keeps_its_heading(goal):
    sc = scenario_from_dict(_still(math.pi / 2, FAR, goal=goal))
    poses = final_leader_poses(sc.leader_path, sc.spec, sc.leader_heading)
    np.testing.assert_array_equal(poses, [[5.0, 5.0, math.pi / 2]])
    np.testing.assert_array_equal(_stop_pose(sc), poses[0])
    # the slots of that pose lie along x: (3.5 .. 6.5, 5); one 0.1 m from a circle is an error
    near = {"type": "circle", "center": [7.0, 5.0], "radius": 0.4}
    with pytest.raises(ScenarioError, match=r"robot 3's formation slot at the goal \(6\.5, 5\)"):
        scenario_from_dict(_still(math.pi / 2, near, goal=goal))
    scenario_from_dict(_still(0.0, near, goal=goal))  # heading 0: the slots lie along y


@pytest.mark.parametrize("x0, ok", [(6.7, False), (6.6999, False), (6.701, True)])
def test_the_boundary_a_slot_exactly_one_radius_from_a_wall_is_rejected(x0, ok):
    # slot 3 sits at (6.5, 5); the rectangle's left edge is x0 - 6.5 from it, measured exactly
    # on the shape (World.clearance), not on the 0.1 m grid. At exactly one radius (0.2 m) the
    # simulator's `clearance < radius` is decided by rounding, so the loader rejects it too.
    wall = {"type": "rectangle", "min": [x0, 4.0], "max": [7.5, 6.0]}
    data = _still(math.pi / 2, wall)
    if ok:
        assert _goal_clearance(scenario_from_dict(data)) == pytest.approx(0.201)
    else:
        with pytest.raises(ScenarioError, match="within the robot radius 0.2 m"):
            scenario_from_dict(data)


def test_the_original_large_100_breaks_the_goal_slot_rule_and_no_other(monkeypatch):
    original = CORPUS / "goal_slot_in_obstacle.toml"
    with pytest.raises(ScenarioError, match=r"leader\.goal: robot 64's formation slot"):
        load_scenario(original)
    monkeypatch.setattr(loader, "check_goal_clear", lambda *args: None)
    sc = load_scenario(original)
    assert sc.spec.leader.goal == (37.0, 20.0)
    at_goal = sc.world.clearance(slot_positions(np.array([37.0, 20.0, 0.0]), sc.offsets))
    assert np.count_nonzero(at_goal == 0.0) == 4  # inside a circle
    assert np.count_nonzero(np.abs(at_goal - 0.2) < 1e-9) == 6  # exactly one radius away
    centres = slot_positions(np.array([37.0, 20.0, 0.0]), sc.offsets).tolist()
    assert [32.5, 16.5] in centres and [32.5, 23.5] in centres
    # the fixed file: 5 m further, and t_max longer so the time left to settle did not shrink
    fixed = load_scenario(ROOT / "scenarios" / "bench" / "large_100.toml")
    assert fixed.spec.leader.goal == (42.0, 20.0)
    assert _goal_clearance(fixed) == pytest.approx(1.4, abs=1e-9)
    assert fixed.spec.t_max - _drive(fixed)[1] >= sc.spec.t_max - _drive(sc)[1]


@pytest.mark.parametrize("path", SHIPPED, ids=[str(p.relative_to(ROOT)) for p in SHIPPED])
def test_every_shipped_scenario_has_clear_goal_slots(path):
    sc = load_scenario(path)
    assert _goal_clearance(sc) > sc.spec.robots.radius + placement.GOAL_TOLERANCE
