"""Run outcomes (success, collision, deadlock, timeout) of runs fine, crashed, stuck, slow."""

import math
from pathlib import Path

import numpy as np
import pytest
from test_metrics import make_log

from dfcoa_opt import metrics
from dfcoa_opt.metrics.outcome import OUTCOMES, classify
from dfcoa_opt.scenario.loader import load_scenario
from dfcoa_opt.scenario.schema import MetricSpec
from dfcoa_opt.sim.simulator import run_scenario
from dfcoa_opt.sim.stall import stalled

ROOT = Path(__file__).resolve().parents[1]
CFG = MetricSpec()  # window 10 s, advance 0.2 m, displacement 0.2 m
DT = 0.1


def straight_run(speeds, steps=400, slot_gap=0.0, reached=False, **fields):
    """Two robots moving along +x at ``speeds[k]`` (m/s) at step k; the path is the x axis.

    Their slots are ``slot_gap`` ahead of them (m), so with a gap above the settle
    tolerance every robot counts as away from its slot.
    """
    x = np.concatenate(([0.0], np.cumsum(np.asarray(speeds, float)[:steps - 1] * DT)))
    pose = np.zeros((steps, 2, 2))
    pose[:, :, 0] = x[:, None]
    pose[:, 1, 1] = 1.0
    slots = pose.copy()
    slots[..., 0] += slot_gap
    return make_log(pose=pose, slots=slots, dt=DT,
                    meta={"leader_path": [[0.0, 0.5], [100.0, 0.5]], "reached_goal": reached,
                          "settle_tolerance": 0.5, "time_to_goal": 30.0 if reached else None},
                    **fields)


def test_fine_run_is_a_success():
    out = classify(straight_run(np.full(400, 0.3), reached=True), CFG)
    assert out["outcome"] == "success" and out["reached"]
    assert math.isnan(out["first_contact_time"]) and math.isnan(out["deadlock_time"])


@pytest.mark.parametrize("field", ["robot_contacts", "obstacle_contacts", "dynamic_contacts"])
def test_any_contact_makes_a_collision_even_when_the_goal_is_reached(field):
    hits = np.zeros(400, np.int32)
    hits[123] = 1
    out = classify(straight_run(np.full(400, 0.3), reached=True, **{field: hits}), CFG)
    assert out["outcome"] == "collision" and out["reached"]
    assert out["first_contact_time"] == pytest.approx(12.3)


def test_stuck_run_is_a_deadlock_from_when_it_stopped():
    speeds = np.where(np.arange(400) < 150, 0.3, 0.0)  # moves 15 s, then stops for good
    out = classify(straight_run(speeds, slot_gap=2.0), CFG)
    assert out["outcome"] == "deadlock" and not out["reached"]
    # x[k] = 0.03 k up to k = 150 (4.5 m), then 4.5 m. Instant k is stalled once
    # x[k] - x[k - 100] < 0.2 m, i.e. k - 100 >= 144: first stalled k = 244, and the
    # stretch without progress began one window (100 steps) earlier, at 14.4 s.
    assert out["deadlock_time"] == pytest.approx(14.4)


def test_slow_but_steady_run_is_a_timeout():
    # 0.03 m/s: 0.3 m per 10 s window, above both 0.2 m thresholds
    out = classify(straight_run(np.full(400, 0.03), slot_gap=2.0), CFG)
    assert out["outcome"] == "timeout" and math.isnan(out["deadlock_time"])
    # 0.015 m/s: 0.15 m per window -- no progress
    assert classify(straight_run(np.full(400, 0.015), slot_gap=2.0), CFG)["outcome"] == "deadlock"


def test_a_run_shorter_than_the_window_is_never_a_deadlock():
    assert classify(straight_run(np.zeros(50), steps=50, slot_gap=2.0), CFG)["outcome"] == \
        "timeout"


def test_robots_at_their_slots_do_not_hide_a_stuck_one():
    steps, lag = 300, 100
    pose = np.zeros((steps, 2, 2))
    pose[:, 1, 0] = 5.0 + 0.4 * np.sin(np.arange(steps))  # robot 1 chatters around its slot
    slots = np.zeros((steps, 2, 2))
    slots[:, 0, 0] = 3.0  # robot 0 stuck 3 m behind its slot
    slots[:, 1, 0] = 5.0
    progress = np.zeros(steps)
    st = stalled(pose, slots, progress, lag, 0.5, 0.2, 0.2)
    assert not st[:lag].any() and st[lag:].all()
    # the same chatter on a robot away from its slot counts as motion
    slots[:, 1, 0] = 9.0
    assert not stalled(pose, slots, progress, lag, 0.5, 0.2, 0.2)[lag:].all()


def test_centroid_advance_along_the_path_counts_as_progress():
    steps, lag = 200, 100
    pose = np.zeros((steps, 1, 2))
    slots = np.full((steps, 1, 2), 10.0)
    progress = 0.01 * np.arange(steps)  # 1 m per window along the path
    assert not stalled(pose, slots, progress, lag, 0.5, 0.2, 0.2).any()


def test_outcome_is_in_the_summary_and_every_class_exists():
    s = metrics.summary(straight_run(np.full(400, 0.3), reached=True), CFG)
    assert s["outcome"] == "success" and s["success"] and s["reached"]
    assert OUTCOMES == ("success", "collision", "deadlock", "timeout")


def test_goto_slot_through_a_wall_is_a_collision_not_a_success():
    sc = load_scenario(ROOT / "scenarios" / "bench" / "corridor.toml", 0)
    m = metrics.summary(run_scenario(sc, "goto_slot"), sc.spec.metrics)
    assert m["reached"] and not m["success"] and m["outcome"] == "collision"
    assert 0.0 < m["first_contact_time"] < m["time_to_goal"]


def test_stop_on_deadlock_ends_the_run_where_the_offline_test_says_deadlock():
    path = ROOT / "scenarios" / "bench" / "corridor.toml"
    full_sc = load_scenario(path, 0)
    full = run_scenario(full_sc, "dfcoa")
    ref = classify(full, full_sc.spec.metrics)
    assert ref["outcome"] == "deadlock"  # dfcoa's V stops at the 1.4 m doorway
    sc = load_scenario(path, 0, {"stop_on_deadlock": True})
    short = run_scenario(sc, "dfcoa")
    out = classify(short, sc.spec.metrics)
    assert out["outcome"] == "deadlock" and out["deadlock_time"] == ref["deadlock_time"]
    assert short.n_steps < full.n_steps
    # up to its end the stopped run is the full run, bit for bit
    np.testing.assert_array_equal(short.pose, full.pose[:short.n_steps])
    assert short.t[-1] == pytest.approx(ref["deadlock_time"] + CFG.deadlock_window)
