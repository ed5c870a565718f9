"""The virtual leader's precomputed track (dfcoa_opt.sim.leader.leader_track)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dfcoa_opt.scenario.formation import slot_positions
from dfcoa_opt.scenario.loader import load_scenario
from dfcoa_opt.sim import leader as leader_mod
from dfcoa_opt.sim.leader import VirtualLeader, leader_track
from dfcoa_opt.sim.simulator import run_scenario

SCEN = Path(__file__).resolve().parents[1] / "scenarios"


@pytest.fixture(autouse=True)
def _empty_cache(monkeypatch):
    monkeypatch.setattr(leader_mod, "_TRACKS", type(leader_mod._TRACKS)())


def test_track_is_the_leader_stepped_as_a_run_steps_it():
    sc = load_scenario(SCEN / "example_obstacles.toml")
    dt, steps = sc.spec.dt, int(round(sc.spec.t_max / sc.spec.dt)) + 1
    track = leader_track(sc, dt, steps)
    lead = VirtualLeader(sc)
    reached = 0
    for k in range(steps):
        assert track.at_goal[k] == lead.at_goal
        reached += int(lead.at_goal)
        state = lead.state(dt)
        np.testing.assert_array_equal(track.state[k], state)
        np.testing.assert_array_equal(track.slots[k], slot_positions(state[:3], sc.offsets))
        lead.advance(dt)
    assert 0 < reached < steps  # the leader arrives during the track


def test_track_is_shared_read_only_and_keyed_by_dt():
    sc = load_scenario(SCEN / "example_empty.toml")
    a = leader_track(sc, 0.1, 50)
    assert leader_track(sc, 0.1, 50) is a
    for arr in (a.state, a.at_goal, a.slots):
        with pytest.raises(ValueError):
            arr[0] = 0
    b = leader_track(sc, 0.2, 50)
    assert b is not a and not np.array_equal(a.state, b.state)


def test_least_recently_used_tracks_go_beyond_the_byte_budget(monkeypatch):
    sc = load_scenario(SCEN / "example_empty.toml")
    one = leader_track(sc, 0.1, 40).nbytes
    monkeypatch.setattr(leader_mod, "TRACKS_BYTES", 2 * one)
    first, second = leader_track(sc, 0.1, 40), leader_track(sc, 0.11, 40)
    assert leader_track(sc, 0.1, 40) is first  # first is now the most recent
    leader_track(sc, 0.12, 40)  # over budget: second goes
    assert leader_track(sc, 0.1, 40) is first
    assert leader_track(sc, 0.11, 40) is not second


def test_a_run_gives_the_same_bits_with_a_fresh_or_a_cached_track():
    sc = load_scenario(SCEN / "example_obstacles.toml")
    fresh = run_scenario(sc, "goto_slot")
    cached = run_scenario(sc, "goto_slot")
    assert len(leader_mod._TRACKS) == 1
    assert fresh.digest() == cached.digest()
    steps = len(fresh.t)
    track = next(iter(leader_mod._TRACKS.values()))
    np.testing.assert_array_equal(fresh.leader, track.state[:steps])
    np.testing.assert_array_equal(fresh.slots, track.slots[:steps])


@pytest.mark.parametrize("speed, dt", [(47.0, 0.05), (3.3, 1.0), (1e6, 0.05)])
def test_a_leader_faster_than_its_goal_region_per_step_lands_on_its_goal(speed, dt):
    """A step longer than goal_radius used to jump past the goal and circle back (or, fast
    enough, never stop): the leader slows for its last step and stops within the region."""
    sc = load_scenario(SCEN / "example_empty.toml",
                       overrides={"leader.speed": speed, "dt": dt, "t_max": 200.0})
    spec = sc.spec.leader
    assert speed * dt > spec.goal_radius
    steps = 200
    track = leader_track(sc, dt, steps)
    k = int(np.argmax(track.at_goal))
    assert track.at_goal[k] and track.at_goal[k:].all()
    goal = np.asarray(spec.goal)
    assert np.hypot(*(track.state[k, :2] - goal)) <= spec.goal_radius
    path = np.hypot(*np.diff(track.state[: k + 1, :2], axis=0).T).sum()
    planned = np.hypot(*np.diff(sc.leader_path, axis=0).T).sum()
    assert path <= planned + 1.0  # no detour past the goal and back
    v = track.state[:k, 3]
    assert np.all(v <= speed) and np.all(v > 0.0)  # it never stops short of its goal
