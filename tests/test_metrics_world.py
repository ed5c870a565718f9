"""World difficulty metrics against values computed by hand on small worlds."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dfcoa_opt.bench.report.stats import cvar
from dfcoa_opt.bench.runner import execute
from dfcoa_opt.bench.sweep import RunSpec
from dfcoa_opt.metrics import world as mw
from dfcoa_opt.scenario.loader import scenario_from_dict
from dfcoa_opt.world.dynamic import DynamicObstacles, MovingDisc

#: A 20 x 10 m map with a 2 m wide corridor between two walls, x in [5, 15], y in [4, 6];
#: one robot, the leader straight along y = 5.
CORRIDOR = {
    "name": "corridor_world", "t_max": 5.0,
    "world": {"size": [20.0, 10.0], "resolution": 10,
              "obstacles": [{"type": "rectangle", "min": [5.0, 0.0], "max": [15.0, 4.0]},
                            {"type": "rectangle", "min": [5.0, 6.0], "max": [15.0, 10.0]}]},
    "team": {"n": 1}, "formation": {"shape": "line"},
    "leader": {"start": [1.0, 5.0], "goal": [19.0, 5.0]},
}


def _corridor():
    return scenario_from_dict(CORRIDOR)


def test_rays_in_the_corridor_by_hand() -> None:
    sc = _corridor()
    lengths = mw.ray_lengths(sc.world.grid, np.array([[10.0, 5.0]]))[0]
    # along the corridor the ray runs to the map's edge (10 m); at angle a off it, it meets
    # a wall 1 m away after 1 / |sin a| (the walls reach 5 m either way, far enough)
    a = 2 * np.pi * np.arange(16) / 16
    with np.errstate(divide="ignore"):
        expected = np.where(np.abs(np.sin(a)) < 1e-12, 10.0, 1.0 / np.abs(np.sin(a)))
    assert lengths == pytest.approx(expected, abs=1e-9)
    assert mw.visibility(lengths[None])[0] == pytest.approx(
        (20 + 4 * (1 / math.sin(math.pi / 8) + math.sqrt(2) + 1 / math.sin(3 * math.pi / 8)) + 2)
        / 16)
    # rays shorter than 3 m hit: all but the two along the corridor -> 4 switches
    assert mw.dispersion(lengths[None])[0] == 4
    # the narrowest axis is the vertical one: 1 + 1 m
    assert mw.characteristic_dimension(lengths[None])[0] == pytest.approx(2.0)


def test_rays_stop_at_the_map_edge() -> None:
    sc = scenario_from_dict({**CORRIDOR, "world": {"size": [20.0, 10.0], "resolution": 10}})
    lengths = mw.ray_lengths(sc.world.grid, np.array([[2.0, 5.0]]))[0]
    assert lengths[0] == pytest.approx(10.0)   # capped at the range
    assert lengths[8] == pytest.approx(2.0)    # the west edge
    assert lengths[4] == pytest.approx(5.0)    # the north edge
    assert lengths[2] == pytest.approx(5.0 * math.sqrt(2))


def test_tortuosity_passages_and_index_by_hand() -> None:
    assert mw.tortuosity(np.array([[0.0, 0.0], [3.0, 0.0], [3.0, 4.0]])) == pytest.approx(7 / 5)
    width = np.array([5.0, 5.0, 2.0, 2.0, 5.0, 1.0, 5.0, 2.9])
    assert mw.narrow_passages(width, 3.0) == 3
    assert mw.narrowest_passage_ratio(width, 2.0) == pytest.approx(0.5)
    values = {"world_clearance": 1.0, "world_visibility": 5.0, "world_dispersion": 2.0,
              "world_characteristic_dimension": 4.0, "world_tortuosity": 1.5,
              "world_narrowest_ratio": 0.25, "world_narrow_passages": 8.0,
              "world_crossings": 5.0}
    # normalised: 0.5, 0.5, 0.5, 0.5, 0.5, 0.75, 1 (capped), 0.5
    assert mw.difficulty_index(values) == pytest.approx((6 * 0.5 + 0.75 + 1.0) / 8)


def test_moving_crossings_by_hand() -> None:
    # up and down across y = 0 at 1 m/s: crossings at t = 4.95, 15.05 and 24.95 s
    disc = MovingDisc(0.3, 1.0, ((5.0, -4.95), (5.0, 5.05)), end="bounce")
    path = np.array([[0.0, 0.0], [10.0, 0.0]])
    assert mw.moving_crossings(DynamicObstacles((disc,)), path, 30.0, 0.1) == 3
    assert mw.moving_crossings(DynamicObstacles((disc,)), path, 10.0, 0.1) == 1
    beside = MovingDisc(0.3, 1.0, ((12.0, -5.0), (12.0, 5.0)), end="bounce")
    assert mw.moving_crossings(DynamicObstacles((beside,)), path, 30.0, 0.1) == 0
    assert mw.moving_crossings(DynamicObstacles(()), path, 30.0, 0.1) == 0


def test_world_difficulty_of_the_corridor() -> None:
    sc = _corridor()
    out = mw.world_difficulty(sc)
    assert out["world_tortuosity"] == pytest.approx(1.0)
    assert out["world_crossings"] == 0
    # the narrowest width is the corridor's 2 m; one robot is 0.4 m wide
    assert out["world_narrowest_ratio"] == pytest.approx(2.0 / 0.4)
    assert out["world_narrow_passages"] == 0
    assert 0.0 <= out["world_difficulty"] <= 1.0
    assert out["world_difficulty"] == pytest.approx(mw.difficulty_index(out))
    assert mw.world_difficulty(sc) == out  # kept per scenario object


def test_row_has_world_metrics(tmp_path) -> None:
    import json

    path = tmp_path / "corridor_world.toml"
    path.write_text("\n".join([
        'name = "corridor_world"', "t_max = 3.0",
        "[world]", "size = [20.0, 10.0]", "resolution = 10",
        "[[world.obstacles]]", 'type = "rectangle"', "min = [5.0, 0.0]", "max = [15.0, 4.0]",
        "[[world.obstacles]]", 'type = "rectangle"', "min = [5.0, 6.0]", "max = [15.0, 10.0]",
        "[team]", "n = 1", "[formation]", 'shape = "line"',
        "[leader]", "start = [1.0, 5.0]", "goal = [19.0, 5.0]"]) + "\n")
    row = execute(RunSpec(str(path), "corridor_world", "goto_slot", 0)).row
    assert row["status"] == "ok"
    expected = mw.world_difficulty(scenario_from_dict(CORRIDOR))
    assert {k: row["metrics"][k] for k in expected} == json.loads(json.dumps(expected))


def test_cvar_by_hand() -> None:
    x = [1.0, 5.0, 2.0, 4.0, 3.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    assert cvar(x, 0.9) == 5.0                      # the worst 10 % of 10 values: one
    assert cvar(x, 0.8) == pytest.approx(4.5)       # the mean of 5 and 4
    assert cvar(x, 0.75) == pytest.approx((5 + 4 + 0.5 * 3) / 2.5)
    assert cvar(x, 0.0) == pytest.approx(np.mean(x))
    assert cvar([1.0, float("nan")], 0.9) == math.inf
    with pytest.raises(ValueError):
        cvar([], 0.9)
