"""`reshape` through the messages: its planner hears the robots late, its plan arrives late."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import dfcoa_opt as d
from comparisons.reshape import planner as choice
from comparisons.reshape.central import CentralPlanner
from comparisons.reshape.controller import CARRIED, FIXED, NOMINAL, Reshape
from comparisons.reshape.relay import Plan, PlanRelay, depth_for
from comparisons.reshape.tracking import Guidance
from dfcoa_opt.control.base import as_batch
from dfcoa_opt.control.registry import make_controller

ROOT = Path(__file__).resolve().parents[1]
CORRIDOR = ROOT / "scenarios" / "bench" / "corridor.toml"
DT = 0.1  # the corridor's step, s
#: Long enough for the corridor's V to turn into a column (about t = 15 s).
T_MAX = 25.0


def _corridor(**keys: float):
    return d.load(CORRIDOR, overrides={"t_max": T_MAX, **keys})


@pytest.mark.parametrize("latency", [0.0, 0.3])
def test_the_planner_plans_from_the_robots_messages(monkeypatch, latency):
    """Every position the planner works from (waypoints, assignment) is a message's."""
    seen: dict[str, object] = {}
    used: list[tuple[CentralPlanner, float, np.ndarray, bool]] = []
    plan, waypoints, assign = CentralPlanner.plan, Guidance.waypoints, choice.assign

    def probe_plan(self, obs):
        seen["planner"], seen["obs"] = self, obs
        plan(self, obs)

    def record(pos):
        obs = seen["obs"]
        used.append((seen["planner"], obs.t, np.array(pos), obs.team is None))

    def probe_waypoints(self, pos, *args):
        record(pos)
        return waypoints(self, pos, *args)

    def probe_assign(pos, *args):
        record(pos)
        return assign(pos, *args)

    monkeypatch.setattr(CentralPlanner, "plan", probe_plan)
    monkeypatch.setattr(Guidance, "waypoints", probe_waypoints)
    monkeypatch.setattr(choice, "assign", probe_assign)
    ctrl = make_controller("reshape")
    runs = d.run_batch(_corridor(**{"comms.latency": latency}), ctrl, [0, 1])
    lag = round(latency / DT)
    stale = 0
    assert len(used) > 2 * T_MAX / ctrl.p.replan_period  # every plan, and the assignments
    for who, t, pos, no_team in used:
        log = runs[ctrl.runs.index(who)].log
        k = round(t / DT)
        assert no_team == (latency == 0.0)
        # without dropout the planner's copy of every robot is `lag` steps old
        np.testing.assert_array_equal(pos, log.pose[max(k - lag, 0), :, :2])
        stale += not np.array_equal(pos, log.pose[k, :, :2])
    assert (stale > 0) == (latency > 0.0)


class Recorder(Reshape):
    """``reshape`` that records, each step, the planner's latest plan and the one followed."""

    def __init__(self) -> None:
        super().__init__(Reshape.Params())
        self.made: list[tuple[int, np.ndarray, np.ndarray, dict[int, np.ndarray]]] = []
        self.followed: list[Plan] = []
        self.ages: list[float] = []

    def act(self, obs):
        u = super().act(obs)
        run = self.runs[0]
        mode = NOMINAL if run.nominal else FIXED if run.carried is None else CARRIED
        carried = np.zeros((self._n, 2)) if run.carried is None else run.carried.copy()
        self.made.append((mode, run.targets.copy(), carried,
                          {i: p.copy() for i, p in run.waypoints.items()}))
        assert self.last_plan is not None
        self.followed.append(self.last_plan)
        age = np.asarray(as_batch(obs).leader_age)  # (E,) by env in a batch (one run here)
        self.ages.append(float(age.reshape(-1)[0]))
        return u


def test_the_robots_follow_the_plan_of_the_leader_broadcast_they_hold():
    rec = Recorder()
    d.run(_corridor(**{"comms.leader_latency": 0.3, "comms.leader_dropout": 0.3}), rec, seed=2)
    lags = [round(a / DT) for a in rec.ages]
    assert max(lags) > 3  # lost broadcasts make some older than the latency
    late = 0
    for k, (got, lag) in enumerate(zip(rec.followed, lags, strict=True)):
        assert lag <= k
        mode, targets, carried, waypoints = rec.made[k - lag]
        np.testing.assert_array_equal(got.mode, mode)
        if mode == FIXED:
            np.testing.assert_array_equal(got.target, targets)
        if mode == CARRIED:
            np.testing.assert_array_equal(got.carried, carried)
        np.testing.assert_array_equal(np.flatnonzero(got.guided), sorted(waypoints))
        for i, point in waypoints.items():
            np.testing.assert_array_equal(got.waypoint[i], point)
        now = rec.made[k]
        late += now[0] != mode or (mode == FIXED and not np.array_equal(targets, now[1]))
    assert late > 0  # the plan changed while the robots still followed an older one


def test_without_a_late_broadcast_the_robots_follow_the_latest_plan():
    rec = Recorder()
    d.run(_corridor(**{"comms.latency": 0.3}), rec, seed=0)
    assert not any(rec.ages)
    for (mode, targets, _, waypoints), got in zip(rec.made, rec.followed, strict=True):
        np.testing.assert_array_equal(got.mode, mode)
        if mode == FIXED:
            np.testing.assert_array_equal(got.target, targets)
        np.testing.assert_array_equal(np.flatnonzero(got.guided), sorted(waypoints))


def test_a_broadcast_older_than_every_kept_plan_gets_the_oldest():
    relay = PlanRelay(1, 2, 3)
    for step in (0, 5, 10, 15):
        relay.keep(0, step, Plan(np.full(2, step, np.int8), np.full((2, 2), float(step)),
                                 np.zeros((2, 2)), np.zeros(2, bool), np.zeros((2, 2))))
    env, robot = np.zeros(2, np.intp), np.arange(2)
    for step, expect in ((3, 5), (9, 5), (10, 10), (14, 10), (40, 15)):
        got = relay.heard(env, robot, np.full(2, step))
        np.testing.assert_array_equal(got.target, np.full((2, 2), float(expect)))
    assert depth_for(0.5) == 21  # 10 s of plans at the default replan period


def test_late_and_lost_messages_change_the_run():
    base = d.run(_corridor(), "reshape", seed=0).log.digest()
    for keys in ({"comms.latency": 0.3}, {"comms.leader_latency": 0.3}):
        assert d.run(_corridor(**keys), "reshape", seed=0).log.digest() != base, keys


def test_a_batch_with_late_and_lost_messages_gives_each_run_its_own_bits():
    sc = _corridor(**{"comms.latency": 0.3, "comms.dropout": 0.2,
                      "comms.leader_latency": 0.2, "comms.leader_dropout": 0.1})
    batch = [r.log.digest() for r in d.run_batch(sc, "reshape", [0, 1, 2])]
    assert batch == [d.run(sc, "reshape", seed=s).log.digest() for s in (0, 1, 2)]
