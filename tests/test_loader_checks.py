"""Scenario values that make part of a scenario meaningless: goal slots, moving discs."""

import numpy as np
import pytest

from dfcoa_opt.core.errors import ScenarioError
from dfcoa_opt.scenario.formation import slot_positions
from dfcoa_opt.scenario.loader import load_scenario, scenario_from_dict

BASE = {"world": {"size": [20.0, 10.0]}, "team": {"n": 4},
        "formation": {"shape": "line", "spacing": 1.0},
        "leader": {"start": [2.0, 5.0], "goal": [15.0, 5.0], "goal_radius": 0.5}}


def _with_circle(center, radius):
    return {**BASE, "world": {**BASE["world"], "obstacles": [
        {"type": "circle", "center": list(center), "radius": radius}]}}


def _goal_slots():
    sc = scenario_from_dict(BASE)
    return slot_positions(np.array([15.0, 5.0, 0.0]), sc.offsets)


def test_a_goal_slot_within_or_at_a_robot_radius_of_an_obstacle_is_an_error():
    slot = _goal_slots()[0]  # a line abreast: slots across the heading at the goal
    centre = slot + [0.0, 0.0]
    gap = 0.5
    # a circle whose surface lies just inside one robot radius (0.2 m) of the slot
    with pytest.raises(ScenarioError, match=r"leader\.goal: robot 0's formation slot at the goal"):
        scenario_from_dict(_with_circle(centre + [1.0, 0.0], 1.0 - 0.19))
    # exactly one radius away: rounding would decide the contact, so it is rejected too ...
    with pytest.raises(ScenarioError, match="within the robot radius 0.2 m"):
        scenario_from_dict(_with_circle(centre + [1.0 + 0.2, 0.0], 1.0))
    # ... and 1 mm more is fine
    scenario_from_dict(_with_circle(centre + [1.0 + 0.201, 0.0], 1.0))
    # ... but the leader may stop goal_radius early: the slot 0.5 m behind is checked too
    with pytest.raises(ScenarioError, match="robot 0's formation slot"):
        scenario_from_dict(_with_circle(centre - [gap + 0.5, 0.0], 0.5 + 0.1))


def test_the_common_large_100_reaches_clear_goal_slots_and_its_old_goal_is_rejected():
    sc = load_scenario("scenarios/bench/large_100.toml")
    assert tuple(sc.spec.leader.goal) == (42.0, 20.0)
    for back in (0.0, sc.spec.leader.goal_radius):
        xy = slot_positions(np.array([42.0 - back, 20.0, 0.0]), sc.offsets)
        assert sc.world.clearance(xy).min() >= 1.4 - 1e-9
    with pytest.raises(ScenarioError, match="formation slot at the goal"):
        load_scenario("scenarios/bench/large_100.toml", overrides={"leader.goal": [37.0, 20.0]})


@pytest.mark.parametrize("disc, key", [
    ({"speed": 0.5, "waypoints": [[5.0, 8.0]]}, "world.dynamic_obstacles[0].speed"),
    ({"speed": 0.0, "waypoints": [[5.0, 8.0], [6.0, 8.0]]}, "world.dynamic_obstacles[0].waypoints"),
    ({"speed": 0.0, "waypoints": [[5.0, 8.0]], "end": "loop"}, "world.dynamic_obstacles[0].end"),
])
def test_a_disc_told_to_move_that_cannot_is_an_error(disc, key):
    data = {**BASE, "t_max": 60.0,
            "world": {**BASE["world"], "dynamic_obstacles": [{"radius": 0.3, **disc}]}}
    with pytest.raises(ScenarioError) as err:
        scenario_from_dict(data, "x.toml")
    assert str(err.value).startswith(f"x.toml: {key}:") and "\n" not in str(err.value)


def test_a_parked_disc_and_a_moving_disc_are_fine():
    # a start after t_max is allowed: a shortened run (--set t_max=3) just ends first
    for disc in ({"speed": 0.0, "waypoints": [[5.0, 8.0]]},
                 {"speed": 0.5, "waypoints": [[5.0, 8.0], [6.0, 8.0]], "end": "bounce",
                  "start_time": 61.0}):
        scenario_from_dict({**BASE, "t_max": 60.0, "world": {
            **BASE["world"], "dynamic_obstacles": [{"radius": 0.3, **disc}]}})


def test_start_behind_moves_every_robot_back_along_the_leaders_heading():
    base = scenario_from_dict({**BASE, "leader": {**BASE["leader"], "start": [5.0, 5.0]}})
    back = scenario_from_dict({**BASE, "leader": {**BASE["leader"], "start": [5.0, 5.0]},
                               "team": {"n": 4, "start_behind": 0.98}})
    # the leader heads +x: x falls by 0.98 m, y and headings stay
    np.testing.assert_allclose(back.initial_pose[:, 0], base.initial_pose[:, 0] - 0.98)
    np.testing.assert_array_equal(back.initial_pose[:, 1:], base.initial_pose[:, 1:])


@pytest.mark.parametrize("team, key", [
    ({"n": 4, "start_behind": 5.0}, "team.start_behind"),  # behind the map's edge
    ({"n": 1, "placement": "explicit", "poses": [[2.0, 5.0, 0.0]], "start_behind": 0.5},
     "team.start_behind"),
])
def test_a_start_behind_that_cannot_apply_is_an_error_naming_the_key(team, key):
    with pytest.raises(ScenarioError, match=key.replace(".", r"\.")):
        scenario_from_dict({**BASE, "team": team})


def test_every_unknown_key_of_a_file_is_in_one_message(tmp_path):
    """Nested tables and arrays of tables too, in the file's order, each with its hint."""
    f = tmp_path / "two.toml"
    f.write_text('name = "x"\n[robots]\nv_mx = 0.5\n[leader]\nspeeed = 0.3\n'
                 '[[world.obstacles]]\ntype = "circle"\ncenter = [3.0, 3.0]\nradus = 0.5\n')
    with pytest.raises(ScenarioError) as err:
        load_scenario(f)
    assert str(err.value) == (
        f"{f}: robots.v_mx: unknown key (did you mean 'v_max'?); also unknown: leader.speeed "
        "(did you mean 'speed'?), world.obstacles[0].radus (did you mean 'radius'?)")


@pytest.mark.parametrize("depth", [600, 5000])
def test_a_file_nested_too_deeply_is_one_line_naming_it(tmp_path, depth):
    f = tmp_path / "deep.toml"
    f.write_text("name = 'x'\n[team]\nposes = " + "[" * depth + "]" * depth + "\n")
    with pytest.raises(ScenarioError, match=rf"^{f}: arrays or inline tables nested too deeply"):
        load_scenario(f)
