"""The virtual leader's precomputed track (dfcoa_opt.sim.leader.leader_track)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dfcoa_opt.formation import slot_positions
from dfcoa_opt.sim import leader as leader_mod
from dfcoa_opt.sim.leader import VirtualLeader, leader_track
from dfcoa_opt.sim.loader import load_scenario
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
        state = lead.state()
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
