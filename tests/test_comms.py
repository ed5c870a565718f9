"""Late and lost messages, pose and command noise ([comms], sensors/robots noise keys)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import dfcoa_opt as d
from dfcoa_opt.control.base import BatchedController, as_batch

ROOT = Path(__file__).resolve().parents[1]
#: Digests of 3 controllers x the 7 common scenarios (seed 0, t_max 15 s), computed by the
#: code before the [comms] keys existed (commit da9d2a2): the keys at their defaults must
#: keep every bit.
GOLDEN = Path(__file__).parent / "data" / "digests" / "comms_defaults.json"
DEFAULTS = {"comms.latency": 0.0, "comms.dropout": 0.0, "comms.leader_latency": 0.0,
            "comms.leader_dropout": 0.0, "sensors.pose_noise_std": 0.0,
            "sensors.heading_noise_std": 0.0, "robots.command_noise_std": 0.0}
CROSSING = ROOT / "scenarios" / "bench" / "crossing.toml"


def test_every_key_at_its_default_keeps_the_digests_of_the_code_before_them():
    golden = json.loads(GOLDEN.read_text())
    assert len(golden) == 21
    for key, digest in golden.items():
        path, ctrl = key.split("|")
        sc = d.load(ROOT / path, overrides={"t_max": 15.0, "controllers.cbf.solver": "exact",
                                            "controllers.virtual_spring.offset_frame": "leader",
                                            **DEFAULTS})
        assert d.run(sc, ctrl, seed=0).log.digest() == digest, key


class Recorder(BatchedController):
    """goto_slot's command; records what each step's observation says about the others."""

    name = "comms_recorder"
    command = "velocity"
    uses_scan = False

    def __init__(self) -> None:
        self.seen: list[tuple[float, np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]] = []
        self.team: list[tuple[np.ndarray, np.ndarray] | None] = []
        self.now: list[tuple[np.ndarray, np.ndarray] | None] = []

    def reset_batch(self, scenarios, rngs) -> None:
        self.seen.clear()
        self.team.clear()
        self.now.clear()

    def act(self, obs):
        obs = as_batch(obs)
        nb = obs.neighbours
        age = None if nb.age is None else nb.age.copy()
        self.seen.append((obs.t, nb.index.copy(), nb.position.copy(), age,
                          np.array(obs.leader).reshape(-1, 5)[0], float(np.max(obs.leader_age))))
        self.team.append(None if obs.team is None else (obs.team.copy(), obs.team_age.copy()))
        self.now.append(None if obs.leader_now is None else
                        (np.array(obs.leader_now).reshape(-1, 5)[0], obs.slot_now.copy()))
        return 0.5 * (obs.slot - obs.pose[:, :2])


def _recorded(**keys):
    sc = d.load(CROSSING, overrides={"t_max": 8.0, **keys})
    rec = Recorder()
    run = d.run(sc, rec, seed=3)
    return run.log, rec.seen, rec.team, rec.now


def test_a_latency_delivers_each_senders_pose_of_that_many_steps_before():
    log, seen, team, _ = _recorded(**{"comms.latency": 0.3})
    lag = 3
    for k, (t, index, position, age, _, _) in enumerate(seen):
        assert t == pytest.approx(k * 0.1)
        i, slot = np.nonzero(index >= 0)
        sender = index[i, slot]
        src = max(k - lag, 0)
        np.testing.assert_array_equal(position[i, slot], log.pose[src, sender, :2])
        np.testing.assert_allclose(age[i, slot], (k - src) * 0.1)
        # the planner at the leader hears every robot as late
        np.testing.assert_array_equal(team[k][0][:, :2], log.pose[src, :, :2])
        np.testing.assert_allclose(team[k][1], (k - src) * 0.1)


def test_a_lost_message_leaves_the_last_one_received_with_its_age():
    log, seen, team, _ = _recorded(**{"comms.latency": 0.1, "comms.dropout": 0.4})
    ages = []
    for k, (_, index, position, age, _, _) in enumerate(seen):
        i, slot = np.nonzero(index >= 0)
        sender = index[i, slot]
        step = np.rint(k - age[i, slot] / 0.1).astype(int)  # the step the message was sent
        assert (step >= 0).all() and (step <= max(k - 1, 0)).all()
        np.testing.assert_array_equal(position[i, slot], log.pose[step, sender, :2])
        ages.append(age[i, slot])
        sent = np.rint(k - team[k][1] / 0.1).astype(int)
        np.testing.assert_array_equal(team[k][0][:, :2], log.pose[sent, np.arange(4), :2])
    ages = np.concatenate(ages)
    assert ages.max() >= 0.4 and (ages > 0.1 + 1e-9).mean() > 0.2  # lost ones age on


def test_the_leaders_broadcast_is_late_and_lost_for_the_whole_team():
    log, seen, team, known = _recorded(**{"comms.leader_latency": 0.2,
                                          "comms.leader_dropout": 0.3})
    assert all(x is None for x in team)  # messages between robots are not late: no team view
    held = 0
    for k, (_, _, _, _, leader, age) in enumerate(seen):
        step = int(round(k - age / 0.1))
        assert k - step >= min(k, 2)
        np.testing.assert_array_equal(leader, log.leader[step])
        held += k - step > 2
        # a planner at the leader knows the state of now, and its slots
        now, slots = known[k]
        np.testing.assert_array_equal(now, log.leader[k])
        np.testing.assert_array_equal(slots, log.slots[k])
    assert held > 5


def test_pose_and_command_noise_have_their_standard_deviations():
    sc = d.load(CROSSING, overrides={"t_max": 10.0, "sensors.pose_noise_std": 0.05,
                                     "sensors.heading_noise_std": 0.02})
    log = d.run(sc, "goto_slot", seed=0).log
    err = (log.pose_est - log.pose).reshape(-1, 3)
    err[:, 2] = np.mod(err[:, 2] + np.pi, 2 * np.pi) - np.pi
    np.testing.assert_allclose(err.std(axis=0), [0.05, 0.05, 0.02], rtol=0.1)
    plain = d.load(CROSSING, overrides={"t_max": 10.0})
    noisy = d.load(CROSSING, overrides={"t_max": 10.0, "robots.command_noise_std": 0.05})
    a, b = d.run(plain, "goto_slot", seed=0).log, d.run(noisy, "goto_slot", seed=0).log
    assert a.digest() != b.digest()
    np.testing.assert_array_equal(a.pose[0], b.pose[0])  # the same start; then it drifts
    assert np.abs(b.pose[1:, :, :2] - a.pose[1:, :, :2]).max() > 0.01


@pytest.mark.parametrize("ctrl", ["consensus_ivo", "nmpc", "dfcoa"])
def test_with_every_key_on_a_batch_is_its_runs_alone_and_a_seed_fixes_them(ctrl):
    sc = d.load(CROSSING, overrides={"t_max": 6.0, "comms.latency": 0.2, "comms.dropout": 0.3,
                                     "comms.leader_latency": 0.1, "comms.leader_dropout": 0.2,
                                     "sensors.pose_noise_std": 0.03,
                                     "robots.command_noise_std": 0.02})
    batch = [r.log.digest() for r in d.run_batch(sc, ctrl, [0, 1, 2])]
    assert batch == [d.run(sc, ctrl, seed=s).log.digest() for s in (0, 1, 2)]
    assert len(set(batch)) == 3
