"""``nmpc`` with late and lost messages: a plan travels with its robot's state message."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import comparisons.nmpc.plans as nmpc_plans
import dfcoa_opt as d
from comparisons.nmpc.geometry import entry_predictions, neighbour_predictions
from comparisons.nmpc.plans import relayed_plans
from dfcoa_opt.control.base import Neighbours
from dfcoa_opt.control.registry import build_controller
from dfcoa_opt.sim.simulator import run_batch_logs
from tests.helpers import neighbours_from_lists
from tests.test_nmpc import _history, controller, scenario

ROOT = Path(__file__).resolve().parents[1]
CROSSING = ROOT / "scenarios" / "bench" / "crossing.toml"
DT = 0.1


def _with_age(nb: Neighbours, age) -> Neighbours:
    """``nb`` with message ages ``age`` (s) on its entries (0 on the padding)."""
    return replace(nb, age=np.where(nb.index >= 0, np.asarray(age, dtype=float), 0.0))


# ----------------------------------------------------------------- gathering, by hand
def test_each_entry_carries_its_senders_plan_of_the_step_its_message_was_sent():
    h, t = 2, 1.0
    snaps = []
    for back in range(4):  # readable plans of steps 1.0, 0.9, 0.8, 0.7 s: ids 0..2
        times = np.array([t - 0.1 * (back + 1), t - 0.1 * (back + 1), np.nan])
        poses = np.zeros((3, h + 1, 3))
        poses[:, :, 0] = 10.0 * back + np.arange(3)[:, None]  # x = 10 back + id
        snaps.append((t - 0.1 * back, times, poses))
    ids = np.array([[0, 1, -1], [0, 2, 5]])  # id 5: beyond the buffers
    age = np.array([[0.3, 0.0, 0.0], [0.1, 0.2, 0.0]])
    plan_t, plans = relayed_plans(snaps[::-1], t, DT, ids, age)  # any order
    # robot 0 as two receivers hold it: 3 and 1 steps old, plans of steps 0.7 and 0.9 s
    assert plans[0, 0, 0, 0] == 30.0 and plan_t[0, 0] == pytest.approx(0.6)
    assert plans[1, 0, 0, 0] == 10.0 and plan_t[1, 0] == pytest.approx(0.8)
    assert plans[0, 1, 0, 0] == 1.0 and plan_t[0, 1] == pytest.approx(0.9)  # fresh: now's
    assert plans.shape == (2, 3, h + 1, 2)
    # no plan: a sender without one, padding, an unknown id, a step no snapshot holds
    assert np.isnan(plan_t[1, 1]) and np.isnan(plan_t[0, 2]) and np.isnan(plan_t[1, 2])
    plan_t, _ = relayed_plans(snaps, t, DT, ids, np.full(ids.shape, 0.4))
    assert np.isnan(plan_t).all()


def test_a_late_entry_follows_its_plan_of_its_age_from_its_position():
    h, tau = 4, 0.1
    plan = np.array([[0.0, 0.0], [0.1, 0.0], [0.2, 0.0], [0.3, 0.0], [0.4, 0.0]])  # +x, 1 m/s
    nb = _with_age(neighbours_from_lists([[5.0, 5.0], [1.0, 1.0], [2.0, 2.0]],
                                         [[0.0, 0.0], [0.0, 0.0], [0.0, -1.0]], [[1, 2], [], []]),
                   [[0.2, 0.3], [0.0, 0.0], [0.0, 0.0]])
    plans = np.zeros((3, 2, h + 1, 2))
    plans[0, 0] = plan
    age = np.full((3, 2), np.inf)
    age[0, 0] = 3.0  # made one step before its message, which is 2 steps old
    pred, mask = entry_predictions(nb, 3, plans, age, tau, h)
    assert mask.tolist() == [[True, True, False], [False] * 3, [False] * 3]
    # robot 1: the plan from stage 3 (now) on, translated to the entry's position (1, 1)
    np.testing.assert_allclose(pred[0, 0], [[1.1, 1.0], [1.2, 1.0], [1.3, 1.0], [1.4, 1.0]],
                               atol=1e-12)
    # robot 2, no plan: the entry's velocity (0, -1) from the entry's position (2, 2)
    np.testing.assert_allclose(pred[0, 1], [[2.0, 1.9], [2.0, 1.8], [2.0, 1.7], [2.0, 1.6]],
                               atol=1e-12)
    age[0, 0] = 4.0  # H stages old: not used, the velocity (0, 0) from (1, 1)
    pred, _ = entry_predictions(nb, 3, plans, age, tau, h)
    np.testing.assert_array_equal(pred[0, 0], np.tile([1.0, 1.0], (h, 1)))


def test_given_the_plans_of_their_ids_entries_give_the_numbers_of_the_plans_by_id():
    rng = np.random.default_rng(4)
    h, tau, n = 5, 0.1, 6
    by_id = rng.normal(size=(n, h + 1, 2))
    age_by_id = np.array([0.0, 1.0, 2.5, np.inf, 4.0, 7.0])
    lists = [[1, 2, 3], [0, 4], [5, 1, 0, 3], [], [2], [0]]
    nb = neighbours_from_lists(rng.normal(size=(n, 2)), rng.normal(size=(n, 2)), lists)
    safe = np.maximum(nb.index, 0)
    want = neighbour_predictions(nb, 3, by_id, age_by_id, tau, h)
    got = entry_predictions(_with_age(nb, 0.3), 3, by_id[safe], age_by_id[safe], tau, h)
    for a, b in zip(want, got, strict=True):
        np.testing.assert_array_equal(a, b)


def test_a_row_alone_gives_the_same_command_with_late_messages():
    pose = np.array([[2.0, 5.0, 0.0], [2.6, 5.1, 0.0], [3.0, 5.6, math.pi], [2.5, 4.6, 1.0]])
    slots = np.array([[4.0, 5.0], [4.0, 6.0], [3.0, 5.0], [3.0, 4.0]])
    lists = [[1, 2], [0, 3], [0, 3], [2, 1]]
    ages = [[0.2, 0.1], [0.0, 0.3], [0.1, 0.2], [0.3, 0.0]]
    ctrl = controller(scenario(n=4, poses=[tuple(p) for p in pose], offsets=[(0.0, 0.0)] * 4))
    late = []

    def act(obs):  # every step: the same ages
        late.append(replace(obs, neighbours=_with_age(obs.neighbours, ages)))
        return plain(late[-1])

    plain, ctrl.act = ctrl.act, act
    obs = _history(ctrl, pose, slots, lists, steps=5)
    full = ctrl.act(obs)
    ctrl.act = plain
    for i in range(4):
        np.testing.assert_array_equal(ctrl.act(late[-1].take([i]))[0], full[i])
    fresh = ctrl.act(replace(late[-1], neighbours=replace(late[-1].neighbours, age=None)))
    assert not np.array_equal(fresh, full)  # the ages are read


# ----------------------------------------------------------------- in the simulator
def _recorded(monkeypatch, **keys):
    """Run crossing for 3 s; record each step's per-entry plans and each step's written plans."""
    sc = d.load(CROSSING, overrides={"t_max": 3.0, **keys})
    ctrl = build_controller("nmpc", sc.spec.controllers, sc.source)
    seen, written, act = [], [], ctrl.act

    def entries(nb, count, plans, plan_age, tau, horizon, index=None):
        seen.append((nb.age.copy(), index.copy(), plans.copy(), plan_age.copy()))
        return entry_predictions(nb, count, plans, plan_age, tau, horizon, index)

    def recorded_act(obs):
        u = act(obs)
        written.append((ctrl.plans._w["t"].copy(), ctrl.plans._w["x"][..., :2].copy()))
        return u

    monkeypatch.setattr(nmpc_plans, "entry_predictions", entries)
    ctrl.act = recorded_act
    log = d.run(sc, ctrl, seed=0).log
    assert len(seen) == len(written) == log.n_steps
    return seen, written


def _check_entries(seen, written, horizon=10):
    """Every entry's plan is the one its sender had written when it sent its message."""
    checked = 0
    for k, (age, ids, plans, plan_age) in enumerate(seen):
        for i, s in zip(*np.nonzero(ids >= 0), strict=True):
            lag = int(round(age[i, s] / DT))
            j, g = k - lag - 1, ids[i, s]  # the step whose plans were readable when sent
            if j < 0 or not np.isfinite(written[j][0][g]):
                assert plan_age[i, s] == np.inf
                continue
            want = (k * DT - written[j][0][g]) / DT
            if want >= horizon:  # too old to be used, whatever the buffers still hold
                assert plan_age[i, s] >= horizon
                continue
            np.testing.assert_array_equal(plans[i, s], written[j][1][g])
            assert plan_age[i, s] == pytest.approx(want)
            checked += 1
    return checked


def test_with_a_latency_of_3_steps_a_neighbours_plan_is_its_plan_of_4_steps_before(monkeypatch):
    seen, written = _recorded(monkeypatch, **{"comms.latency": 0.3})
    assert _check_entries(seen, written) > 0
    for k, (age, ids, _, plan_age) in enumerate(seen):
        on = ids >= 0
        assert on.any()
        np.testing.assert_allclose(age[on], min(k, 3) * DT)
        if k >= 4:  # every robot solved its problem at every step: plans made 4 steps before
            np.testing.assert_allclose(plan_age[on], 4.0)
        else:
            assert (plan_age[on] == np.inf).all()  # the messages of step 0 carry no plan


def test_with_lost_messages_each_entry_carries_the_plan_of_its_own_age(monkeypatch):
    seen, written = _recorded(monkeypatch, **{"comms.latency": 0.1, "comms.dropout": 0.4})
    assert _check_entries(seen, written) > 0
    lags = np.concatenate([np.round(age[ids >= 0] / DT) for age, ids, _, _ in seen])
    assert len(np.unique(lags)) >= 4  # several ages, some beyond one step


def test_a_batch_with_late_and_lost_messages_is_its_runs_alone():
    keys = {"t_max": 22.0, "comms.latency": 0.3, "comms.dropout": 0.2}
    seeds = (0, 1, 2)
    batch = run_batch_logs(d.load(CROSSING, overrides=keys), "nmpc", seeds)
    singles = [d.run(d.load(CROSSING, overrides=keys), "nmpc", seed=s).log for s in seeds]
    assert [log.digest() for log in batch] == [log.digest() for log in singles]


def test_a_latency_changes_the_run():
    # the robots come within reach of each other when D1 passes (t ~ 19 s)
    def digest(latency):
        keys = {"t_max": 22.0, "comms.latency": latency}
        return d.run(d.load(CROSSING, overrides=keys), "nmpc", seed=0).log.digest()

    assert digest(0.3) != digest(0.0)
