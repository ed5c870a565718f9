"""Random clutter field and start-pose noise."""

import numpy as np
import pytest

from dfcoa_opt.control.registry import make_controller
from dfcoa_opt.core.errors import ScenarioError
from dfcoa_opt.scenario.loader import scenario_from_dict
from dfcoa_opt.sim.simulator import Simulator
from dfcoa_opt.world.clutter import random_discs
from dfcoa_opt.world.shapes import Circle


def _data(**clutter):
    return {"world": {"size": [20.0, 10.0], "clutter": {"density": 0.15, **clutter}},
            "team": {"n": 3}, "formation": {"shape": "line"},
            "leader": {"start": [2.0, 5.0], "goal": [18.0, 5.0]}, "seed": 4, "t_max": 1.0}


def test_discs_meet_density_keep_clear_and_gap():
    rng = np.random.default_rng(1)
    keep = np.array([[2.0, 2.0], [8.0, 8.0]])
    discs = random_discs(rng, (0, 0, 10, 10), 0.2, 0.2, 0.5, keep, np.array([1.0, 2.0]), 0.1)
    c = np.array([d.center for d in discs])
    r = np.array([d.radius for d in discs])
    area = np.pi * np.sum(r**2)
    assert 0.2 * 100 <= area < 0.2 * 100 + np.pi * 0.5**2  # stops at the first disc past it
    assert np.all((r >= 0.2) & (r <= 0.5))
    assert np.all((c >= 0) & (c <= 10))
    for k, rad in zip(keep, (1.0, 2.0), strict=True):
        assert np.all(np.hypot(*(c - k).T) - r >= rad)
    d = np.hypot(*(c[:, None] - c[None]).transpose(2, 0, 1))
    gap = d - r[:, None] - r[None, :]
    np.fill_diagonal(gap, np.inf)
    assert gap.min() >= 0.1


def test_field_follows_the_seed():
    a = scenario_from_dict(_data())
    b = scenario_from_dict(_data())
    c = scenario_from_dict({**_data(), "seed": 5})
    d = scenario_from_dict({**_data(seed=4), "seed": 9})
    assert a.world.shapes == b.world.shapes and len(a.world.shapes) > 5
    assert a.world.shapes != c.world.shapes            # default: the scenario seed
    assert d.world.shapes == a.world.shapes            # an explicit clutter seed wins
    assert all(isinstance(s, Circle) for s in a.world.shapes)
    assert a.world.grid.occupied.mean() > 0.1          # rasterised into the grid


def test_start_and_formation_kept_clear():
    # discs only left of x = 14 m: the goal's formation slots stay clear (a loader check)
    sc = scenario_from_dict(_data(keep_clear=0.5, region=[0.0, 0.0, 14.0, 10.0]))
    assert sc.world.grid.clearance(sc.initial_pose[:, :2], 5.0).min() >= 0.5 + 0.2 - 0.11


def test_bad_clutter_keys():
    with pytest.raises(ScenarioError, match="world.clutter.radius_max"):
        scenario_from_dict(_data(radius_min=0.6, radius_max=0.5))
    with pytest.raises(ScenarioError, match="world.clutter.region"):
        scenario_from_dict(_data(region=[5.0, 0.0, 1.0, 10.0]))


def test_start_noise_is_seeded_and_kept_free():
    data = _data(seed=4)  # one field for every run seed: only the start noise follows it
    data["team"] = {"n": 3, "start_noise": 0.3, "heading_noise": 0.2}
    sc = scenario_from_dict(data)
    ctrl = make_controller("goto_slot")
    p0 = Simulator(sc, ctrl, seed=1).run().pose[0]
    p1 = Simulator(sc, ctrl, seed=1).run().pose[0]
    p2 = Simulator(sc, ctrl, seed=2).run().pose[0]
    assert np.array_equal(p0, p1) and not np.array_equal(p0, p2)
    moved = np.hypot(*(p0[:, :2] - sc.initial_pose[:, :2]).T)
    assert moved.max() > 0.0
    assert not sc.world.grid.is_occupied_at(p0[:, :2]).any()
    quiet = scenario_from_dict(_data(seed=4))
    assert np.array_equal(Simulator(quiet, ctrl, seed=1).run().pose[0], quiet.initial_pose)
