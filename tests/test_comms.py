"""Late and lost messages, pose and command noise ([comms], sensors/robots noise keys)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import dfcoa_opt as d
from dfcoa_opt.control.base import BatchedController, as_batch
from dfcoa_opt.scenario.loader import scenario_from_dict

ROOT = Path(__file__).resolve().parents[1]
#: Digests of 3 controllers x the 7 common scenarios (seed 0, t_max 15 s), computed by the
#: code before the [comms] keys existed (commit da9d2a2): the keys at their defaults must
#: keep every bit.
GOLDEN = Path(__file__).parent / "data" / "digests" / "comms_defaults.json"
DEFAULTS = {"comms.latency": 0.0, "comms.dropout": 0.0, "comms.leader_latency": 0.0,
            "comms.leader_dropout": 0.0, "sensors.pose_noise_std": 0.0,
            "sensors.heading_noise_std": 0.0, "robots.command_noise_std": 0.0}
CROSSING = ROOT / "scenarios" / "bench" / "crossing.toml"
#: Digests of runs with latency 0 but messages on (dropout, the leader's latency and dropout,
#: noise), a short radio range and few neighbours, computed by the code that gated messages
#: by the distance at reception (commit b8503f6): at latency 0 the gate at sending is the same.
LATENCY0 = Path(__file__).parent / "data" / "digests" / "comms_latency0.json"
LATENCY0_KEYS = {"comms.dropout": 0.3, "comms.leader_latency": 0.2, "comms.leader_dropout": 0.2,
                 "sensors.pose_noise_std": 0.03, "robots.command_noise_std": 0.02}
LATENCY0_RUNS = {"crossing.toml": {"t_max": 10.0, "sensors.comm_radius": 2.5,
                                   "sensors.max_neighbors": 1},
                 "large_20.toml": {"t_max": 6.0}}


def test_every_key_at_its_default_keeps_the_digests_of_the_code_before_them():
    golden = json.loads(GOLDEN.read_text())
    assert len(golden) == 21
    for key, digest in golden.items():
        path, ctrl = key.split("|")
        sc = d.load(ROOT / path, overrides={"t_max": 15.0, "controllers.cbf.solver": "exact",
                                            "controllers.virtual_spring.offset_frame": "leader",
                                            **DEFAULTS})
        assert d.run(sc, ctrl, seed=0).log.digest() == digest, key


def test_at_latency_0_the_gate_at_sending_keeps_the_digests_of_the_gate_at_reception():
    golden = json.loads(LATENCY0.read_text())
    assert len(golden) == 6
    for key, digest in golden.items():
        path, ctrl = key.split("|")
        sc = d.load(ROOT / path, overrides={**LATENCY0_KEYS,
                                            **LATENCY0_RUNS[Path(path).name]})
        assert d.run(sc, ctrl, seed=1).log.digest() == digest, key


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


class Drive(BatchedController):
    """Fixed world velocities, one per robot; records each step's neighbour table."""

    name = "comms_drive"
    command = "velocity"
    uses_scan = False

    def __init__(self, velocity) -> None:
        self.velocity = np.asarray(velocity, dtype=float)
        self.seen: list[tuple[np.ndarray, np.ndarray, np.ndarray | None]] = []

    def reset_batch(self, scenarios, rngs) -> None:
        self.seen.clear()

    def act(self, obs):
        obs = as_batch(obs)
        nb = obs.neighbours
        self.seen.append((nb.index.copy(), nb.position.copy(),
                          None if nb.age is None else nb.age.copy()))
        return np.tile(self.velocity, (len(obs.pose) // len(self.velocity), 1))


RADIUS = 3.05  # m: the radio range of the driven runs (no distance there is within 1 mm of it)


def _driven(latency: float = 0.5):
    """Robot 0 still at (5, 5); robot 1 from 2 m away drives off, robot 2 from 5 m comes in.

    Returns:
        The log, what each step's table held, and each step's send-time step.
    """
    data = {
        "name": "driven", "dt": 0.1, "t_max": 3.5, "seed": 0,
        "world": {"size": [20.0, 20.0], "resolution": 10},
        "robots": {"model": "single_integrator", "radius": 0.2, "v_max": 1.0, "w_max": 2.0},
        "team": {"n": 3, "placement": "explicit", "start_noise": 0.0, "heading_noise": 0.0,
                 "poses": [[5.0, 5.0, 0.0], [7.0, 5.0, 0.0], [5.0, 10.0, 0.0]]},
        "formation": {"shape": "offsets", "offsets": [[0.0, 0.0], [2.0, 0.0], [0.0, 5.0]]},
        "leader": {"start": [5.0, 5.0], "goal": [5.5, 5.0], "speed": 0.02, "goal_radius": 0.1},
        "sensors": {"lidar": {"enabled": False}, "comm_radius": RADIUS},
        "comms": {"latency": latency},
    }
    ctrl = Drive([[0.0, 0.0], [1.0, 0.0], [0.0, -1.0]])
    log = d.run(scenario_from_dict(data, "<driven>"), ctrl, seed=0).log
    lag = int(round(latency / 0.1))
    return log, ctrl.seen, [max(k - lag, 0) for k in range(len(ctrl.seen))]


def _in_range(log, step: int, i: int, j: int) -> bool:
    return bool(np.hypot(*(log.pose[step, i, :2] - log.pose[step, j, :2])) <= RADIUS)


def test_the_table_holds_the_senders_in_range_when_they_sent():
    log, seen, src = _driven()
    assert len(seen) == 36
    for k, (index, position, age) in enumerate(seen):
        for i in range(3):
            senders = sorted(index[i][index[i] >= 0].tolist())
            assert senders == [j for j in range(3) if j != i and _in_range(log, src[k], i, j)], k
            row = index[i] >= 0
            np.testing.assert_array_equal(position[i, row], log.pose[src[k], index[i, row], :2])
            np.testing.assert_allclose(age[i, row], (k - src[k]) * 0.1)


def test_a_message_sent_in_range_is_received_after_the_sender_left_the_range():
    log, seen, src = _driven()
    left = [k for k in range(len(seen)) if not _in_range(log, k, 0, 1)]
    assert left[0] == 11  # robot 1 is 2 + 0.1 k m from robot 0
    late = [k for k in left if 1 in seen[k][0][0]]
    assert late == [11, 12, 13, 14, 15]  # sent at steps 6 .. 10, in range
    assert _in_range(log, src[15], 0, 1) and not _in_range(log, src[16], 0, 1)


def test_a_message_sent_out_of_range_is_not_received_after_the_sender_came_in():
    log, seen, src = _driven()
    came = [k for k in range(len(seen)) if _in_range(log, k, 0, 2)]
    assert came[0] == 20  # robot 2 is 5 - 0.1 k m from robot 0
    unheard = [k for k in came if 2 not in seen[k][0][0]]
    assert unheard == [20, 21, 22, 23, 24]  # sent at steps 15 .. 19, out of range
    assert 2 in seen[25][0][0] and 0 in seen[25][0][2]


def test_without_latency_the_table_is_the_one_in_range_now():
    log, seen, _ = _driven(latency=0.0)  # no late message: no Comms
    for k, (index, _, _) in enumerate(seen):
        assert (1 in index[0]) == _in_range(log, k, 0, 1)
        assert (2 in index[0]) == _in_range(log, k, 0, 2)


@pytest.mark.parametrize("ctrl", ["consensus_ivo", "lf_vo"])
def test_with_a_latency_and_a_short_range_a_batch_is_its_runs_alone(ctrl):
    """Moving robots 2 m apart, at the range's edge: the send step's table gates (it changes
    these runs), run by run."""
    sc = d.load(CROSSING, overrides={"t_max": 6.0, "comms.latency": 0.3, "comms.dropout": 0.2,
                                     "comms.leader_latency": 0.1,
                                     "sensors.pose_noise_std": 0.03,
                                     "sensors.comm_radius": 2.0, "sensors.max_neighbors": 2})
    batch = [r.log.digest() for r in d.run_batch(sc, ctrl, [0, 1, 2])]
    assert batch == [d.run(sc, ctrl, seed=s).log.digest() for s in (0, 1, 2)]
    assert len(set(batch)) == 3
