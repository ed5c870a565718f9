"""Metrics of dfcoa_opt.metrics against hand-computed values on synthetic logs."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from dfcoa_opt import metrics as m
from dfcoa_opt.bench.runner import jsonable
from dfcoa_opt.metrics import risk as metrics_risk
from dfcoa_opt.metrics import robots as mr
from dfcoa_opt.metrics import units
from dfcoa_opt.metrics import world as metrics_world
from dfcoa_opt.metrics.outcome import OUTCOMES
from dfcoa_opt.scenario.schema import MetricSpec
from dfcoa_opt.sim.log import RunLog

SQUARE = np.array([[1.0, 1.0], [-1.0, 1.0], [-1.0, -1.0], [1.0, -1.0]])


def make_log(pose=None, slots=None, leader=None, twist=None, dt=0.1, radius=0.2,
             meta=None, **fields) -> RunLog:
    """A RunLog with the given arrays and zeros elsewhere (clearance = 5 m = cap)."""
    if pose is None:
        pose = np.repeat(SQUARE[None], 3, axis=0)
    pose = np.asarray(pose, dtype=float)
    if pose.shape[-1] == 2:
        pose = np.concatenate([pose, np.zeros(pose.shape[:-1] + (1,))], axis=-1)
    n_t, n = pose.shape[:2]
    z = np.zeros((n_t, n))
    zi = np.zeros(n_t, dtype=np.int32)
    args = dict(
        t=np.arange(n_t) * dt, pose=pose, pose_est=pose.copy(),
        velocity=np.zeros((n_t, n, 2)),
        twist=np.zeros((n_t, n, 2)) if twist is None else np.asarray(twist, dtype=float),
        command=np.zeros((n_t, n, 2)),
        leader=np.zeros((n_t, 5)) if leader is None else np.asarray(leader, dtype=float),
        slots=pose[..., :2].copy() if slots is None else np.asarray(slots, dtype=float),
        offsets=np.zeros((n, 2)), clearance=np.full((n_t, n), 5.0),
        min_inter_robot=np.full(n_t, np.inf if n == 1 else 2.0),
        robot_contacts=zi.copy(), obstacle_contacts=zi.copy(), dynamic_contacts=zi.copy(),
        collision_events=zi.copy(), dyn_pos=np.zeros((n_t, 0, 2)), dyn_radius=np.zeros(0),
        filter_status=z.astype(np.int8), filter_slack=z.copy(), filter_time=z.copy(),
        steering=np.full_like(z, np.nan),
        meta={"dt": dt, "robot_radius": radius, "reached_goal": False, "time_to_goal": None,
              **(meta or {})},
    )
    args.update(fields)
    return RunLog(**args)


def rot(theta: float) -> np.ndarray:
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s], [s, c]])


# ------------------------------------------------------------------ eq 6-8
def test_translated_formation_has_centroid_error_5_and_no_shape_error():
    slots = np.repeat(SQUARE[None], 4, axis=0)
    log = make_log(pose=slots + [3.0, 4.0], slots=slots)
    np.testing.assert_allclose(m.formation_centroid_error(log), 5.0)
    np.testing.assert_allclose(m.formation_shape_error(log), 0.0, atol=1e-12)
    s = m.summary(log, MetricSpec())
    assert s["fce_rms"] == pytest.approx(5.0) and s["fce_max"] == pytest.approx(5.0)
    assert s["fce_x_rms"] == pytest.approx(3.0) and s["fce_y_rms"] == pytest.approx(4.0)
    assert s["fse_rms"] == pytest.approx(0.0, abs=1e-12)
    assert s["stability_pct"] == 100.0


def test_rotated_formation_has_no_centroid_error_and_known_shape_error():
    # Square of circumradius sqrt(2) rotated by 90 deg about its centroid: every
    # corner moves by the chord sqrt(2) * sqrt(2) = 2 m.
    slots = SQUARE[None] + [10.0, -2.0]
    pose = SQUARE[None] @ rot(math.pi / 2).T + [10.0, -2.0]
    log = make_log(pose=pose, slots=slots)
    np.testing.assert_allclose(m.formation_centroid_error(log), 0.0, atol=1e-12)
    np.testing.assert_allclose(m.formation_shape_error(log), [2.0])
    # mixed: one robot off its slot by (4, 0): centroid moves (1, 0), shape error
    # = (|(3,0)| + 3 * |(-1,0)|) / 4 = 1.5
    pose = SQUARE.copy()[None]
    pose[0, 0] += [4.0, 0.0]
    log = make_log(pose=pose, slots=SQUARE[None])
    assert m.formation_centroid_error(log)[0] == pytest.approx(1.0)
    assert m.formation_shape_error(log)[0] == pytest.approx(1.5)
    assert m.summary(log)["stability_pct"] == 0.0


def test_stability_pct_counts_steps_below_threshold():
    pose = np.repeat(SQUARE[None], 4, axis=0).copy()
    pose[1, 0] += [0.8, 0.0]   # E_s = (0.6 + 3 * 0.2) / 4 = 0.3 < 0.5
    pose[2, 0] += [4.0, 0.0]   # E_s = 1.5
    pose[3, 0] += [8.0, 0.0]   # E_s = 3.0
    log = make_log(pose=pose, slots=np.repeat(SQUARE[None], 4, axis=0))
    np.testing.assert_allclose(m.formation_shape_error(log), [0.0, 0.3, 1.5, 3.0])
    assert m.formation_stability_pct(log, MetricSpec()) == pytest.approx(50.0)
    assert m.formation_stability_pct(log, MetricSpec(stability_threshold=2.0)) == 75.0
    s = m.summary(log)
    assert s["fse_mean"] == pytest.approx(1.2)
    assert s["fse_rms"] == pytest.approx(math.sqrt((0.09 + 2.25 + 9.0) / 4))


def test_stability_error_is_trailing_moving_average():
    ec = np.array([0.0, 1.0, 2.0, 3.0, 4.0, 5.0])
    slots = np.zeros((6, 1, 2))
    pose = np.stack([ec, np.zeros(6)], axis=-1)[:, None, :]
    log = make_log(pose=pose, slots=slots, dt=0.5)
    np.testing.assert_allclose(m.formation_centroid_error(log), ec)
    # window 1.5 s / dt 0.5 s = 3 samples; early steps average what exists
    want = [0.0, 0.5, 1.0, 2.0, 3.0, 4.0]
    np.testing.assert_allclose(m.formation_stability_error(log, 1.5), want)
    np.testing.assert_allclose(m.formation_stability_error(log, 0.1), ec)  # 1 sample
    s = m.summary(log, MetricSpec(fste_window=1.5))
    assert s["fste_max"] == pytest.approx(4.0) and s["fste_final"] == pytest.approx(4.0)
    assert s["fce_mean"] == pytest.approx(2.5)


# --------------------------------------------------------------- eq 9-10
def test_velocity_centroid_error_and_rms_velocities():
    twist = np.array([[[0.2, 0.1], [0.4, -0.3]],      # V_c 0.3, w_c -0.1
                      [[0.0, 0.0], [0.0, 0.0]]])
    leader = np.array([[0, 0, 0, 0.6, 0.3], [0, 0, 0, 0.3, 0.4]])
    log = make_log(pose=np.zeros((2, 2, 2)) + [[0, 0], [1, 0]], twist=twist, leader=leader)
    np.testing.assert_allclose(m.velocity_centroid_error(log), [0.5, 0.5])
    v_rms, w_rms = m.rms_velocities(log)
    np.testing.assert_allclose(v_rms, [math.sqrt(0.1), 0.0])
    np.testing.assert_allclose(w_rms, [math.sqrt(0.05), 0.0])
    s = m.summary(log)
    assert s["vce_rms"] == pytest.approx(0.5)
    assert s["v_rms"] == pytest.approx(math.sqrt(0.1) / 2)
    assert s["w_rms"] == pytest.approx(math.sqrt(0.05) / 2)
    avg_v, avg_w = mr.average_velocities_per_robot(log)
    np.testing.assert_allclose(avg_v, [0.1, 0.2])
    np.testing.assert_allclose(avg_w, [0.05, -0.15])
    np.testing.assert_allclose(mr.mean_abs_angular_velocity_per_robot(log), [0.05, 0.15])


# -------------------------------------------------------------------- eq 11
@pytest.mark.parametrize("d", [0.25, 0.5, 1.0, 2.0, 3.0])
def test_two_robot_risk_is_inverse_square_of_distance(d):
    log = make_log(pose=[[[0.0, 0.0], [d, 0.0]]])
    spec = MetricSpec(risk_lambda1=1.5, risk_lambda2=0.0, risk_reference_distance=0.5)
    assert m.collision_risk(log, spec)[0] == pytest.approx(2 * 1.5 / d**2)
    assert m.collision_risk_normalised(log, spec)[0] == pytest.approx(min(1.0, (0.5 / d) ** 2))


def test_robot_risk_counts_ordered_pairs_within_detection_range():
    # collinear robots at x = 0, 1, 3: pairs 1 m, 2 m, 3 m apart
    log = make_log(pose=[[[0.0, 0.0], [1.0, 0.0], [3.0, 0.0]]])
    full = m.collision_risk(log, MetricSpec(risk_lambda2=0.0, risk_detection_range=3.5))
    assert full[0] == pytest.approx(2 * (1 + 1 / 4 + 1 / 9))
    cut = m.collision_risk(log, MetricSpec(risk_lambda2=0.0, risk_detection_range=2.5))
    assert cut[0] == pytest.approx(2 * (1 + 1 / 4))
    assert m.collision_risk(make_log(pose=[[[0.0, 0.0]]]), MetricSpec())[0] == 0.0


@pytest.mark.parametrize(("steps", "n", "side"), [(7, 5, 4.0), (30, 120, 25.0)])
def test_robot_risk_is_per_step_and_matches_all_pairs(steps, n, side):
    """The sweep-line pair term against a dense all-pairs sum, step by step."""
    rng = np.random.default_rng(n)
    pos = rng.uniform(0, side, size=(steps, n, 2))
    pos[0, 1] = pos[0, 0]  # coincident robots: the distance floor applies
    log = make_log(pose=pos)
    spec = MetricSpec(risk_lambda2=0.0, risk_detection_range=2.0)
    d = np.linalg.norm(pos[:, :, None] - pos[:, None], axis=-1)
    off = ~np.eye(n, dtype=bool)
    floor = m.RISK_DISTANCE_FLOOR
    inv = np.where(off & (d <= 2.0), 1.0 / np.maximum(np.where(off, d, 1.0), floor) ** 2, 0.0)
    np.testing.assert_allclose(m.collision_risk(log, spec), inv.sum(axis=(1, 2)), rtol=1e-12)


def test_obstacle_risk_static_and_moving(monkeypatch):
    spec = MetricSpec(risk_lambda1=0.0, risk_lambda2=2.0, risk_reference_distance=0.5,
                      risk_detection_range=3.5, clearance_cap=5.0)
    clearance = np.array([[1.0, 4.0], [0.5, 5.0]])  # 4 m beyond range, 5 m = cap
    dyn_pos = np.array([[[0.0, 2.0]], [[10.0, 10.0]]])  # disc r = 0.5 above robot 0
    log = make_log(pose=[[[0.0, 0.0], [20.0, 0.0]]] * 2, clearance=clearance,
                   dyn_pos=dyn_pos, dyn_radius=np.array([0.5]))
    # step 0: static 1/1^2, moving disc surface 1.5 m from robot 0; robot 1 20 m away
    want = 2.0 * np.array([1.0 + 1 / 1.5**2, 1 / 0.5**2])
    np.testing.assert_allclose(m.collision_risk(log, spec), want)
    # lambda1 = 0: R_ref = lambda2 / d_ref^2 = 8
    np.testing.assert_allclose(m.collision_risk_normalised(log, spec), np.minimum(want / 8, 1))
    monkeypatch.setattr(metrics_risk, "CHUNK_ELEMS", 1)
    np.testing.assert_allclose(m.collision_risk(log, spec), want)
    s = m.summary(log, spec)
    assert s["risk_max"] == pytest.approx(1.0)
    assert s["risk_mean"] == pytest.approx((want[0] / 8 + 1.0) / 2)
    # the cap counts as "no obstacle" even when it is inside the detection range
    capped = MetricSpec(risk_lambda1=0.0, risk_detection_range=10.0, clearance_cap=5.0)
    no_dyn = make_log(pose=[[[0.0, 0.0]]], clearance=np.array([[5.0]]))
    assert m.collision_risk(no_dyn, capped)[0] == 0.0


def test_overlapping_robots_give_finite_risk():
    log = make_log(pose=[[[1.0, 1.0], [1.0, 1.0]]])
    r = m.collision_risk(log, MetricSpec())
    assert np.isfinite(r).all() and r[0] > 1e6
    assert m.collision_risk_normalised(log, MetricSpec())[0] == 1.0


@pytest.mark.parametrize("kind", ["robot_contacts", "obstacle_contacts", "dynamic_contacts"])
def test_raw_risk_of_a_run_with_a_contact_is_inf(kind):
    """A contact of any kind: the raw risk summaries are inf (null in JSON), not 1e12."""
    pose = np.zeros((3, 2, 2)) + [[0.0, 0.0], [1.0, 0.0]]
    pose[1, 1] = [0.0, 0.0]  # robots on top of each other at t1: 1/d^2 at the floor
    contact = np.array([0, 1, 0], dtype=np.int32)
    log = make_log(pose=pose, **{kind: contact})
    s = m.summary(log)
    assert s["outcome"] == "collision"
    assert s["risk_raw_mean"] == math.inf and s["risk_raw_max"] == math.inf
    assert m.collision_risk(log)[1] == pytest.approx(2 / m.RISK_DISTANCE_FLOOR**2)  # the series
    assert s["risk_max"] == 1.0  # the normalised risk stays at its clip
    row = jsonable(s)
    assert row["risk_raw_mean"] is None and row["risk_raw_max"] is None
    clean = m.summary(make_log(pose=pose))  # the same geometry, no contact logged
    assert clean["outcome"] != "collision"
    assert clean["risk_raw_max"] == pytest.approx(2 / m.RISK_DISTANCE_FLOOR**2)
    assert clean["risk_raw_mean"] == pytest.approx(np.mean(m.collision_risk(log)))


# ------------------------------------------------------------------ general
def test_safety_counts_and_distances():
    n_t = 5
    log = make_log(
        pose=np.zeros((n_t, 2, 2)) + [[0, 0], [3, 0]],
        clearance=np.array([[1.0, 2.0], [0.3, 2.0], [0.15, 2.0], [1.0, 2.0], [5.0, 5.0]]),
        min_inter_robot=np.array([3.0, 2.5, 0.35, 1.0, 3.0]),
        robot_contacts=np.array([0, 0, 1, 0, 0], dtype=np.int32),
        obstacle_contacts=np.array([0, 0, 1, 1, 0], dtype=np.int32),
        dynamic_contacts=np.array([0, 0, 0, 0, 2], dtype=np.int32),
        collision_events=np.array([0, 0, 2, 0, 1], dtype=np.int32),
        radius=0.2,
    )
    s = m.summary(log)
    assert s["min_inter_robot_distance"] == pytest.approx(0.35)
    assert s["min_obstacle_clearance"] == pytest.approx(-0.05)
    assert s["collisions"] == 3
    assert s["robot_contact_steps"] == 1
    assert s["obstacle_contact_steps"] == 3 and s["dynamic_contact_steps"] == 1
    one = make_log(pose=np.zeros((3, 1, 2)))
    assert math.isnan(m.min_inter_robot_distance(one))


def test_path_length_of_known_polyline():
    # robot 0: (0,0) -> (3,4) -> (3,0) -> (3,0) = 5 + 4 + 0; robot 1 stands still
    p0 = np.array([[0.0, 0.0], [3.0, 4.0], [3.0, 0.0], [3.0, 0.0]])
    pose = np.stack([p0, np.full((4, 2), 7.0)], axis=1)
    log = make_log(pose=pose)
    np.testing.assert_allclose(mr.path_length_per_robot(log), [9.0, 0.0])
    np.testing.assert_allclose(mr.distance_travelled(log), [9.0, 0.0])
    assert m.summary(log)["path_length_mean"] == pytest.approx(4.5)


def test_goal_and_filter_statistics():
    status = np.array([[0, 1], [1, 2], [3, 0]], dtype=np.int8)
    ftime = np.array([[0.001, 0.002], [0.003, 0.004], [0.005, 0.006]])
    log = make_log(pose=np.zeros((3, 2, 2)) + [[0, 0], [2, 0]], filter_status=status,
                   filter_time=ftime, meta={"reached_goal": True, "time_to_goal": 12.5})
    s = m.summary(log)
    assert s["filter_interventions"] == 2
    assert s["filter_fallbacks"] == 2
    assert s["filter_solver_failures"] == 1
    assert s["filter_time_median"] == pytest.approx(0.0035)
    assert s["success"] is True and s["time_to_goal"] == 12.5
    none = m.summary(make_log(meta={"reached_goal": False, "time_to_goal": 9.0}))
    assert none["filter_time_median"] == 0.0 and none["filter_interventions"] == 0
    assert none["success"] is False and math.isnan(none["time_to_goal"])


# ----------------------------------------------------------- papers 002 / 004
def test_position_error_and_mse_eq14():
    slots = np.zeros((2, 2, 2))
    pose = np.array([[[3.0, 4.0], [0.0, 1.0]], [[0.0, 0.0], [0.0, -2.0]]])
    log = make_log(pose=pose, slots=slots)
    np.testing.assert_allclose(mr.leader_follower_position_error(log), [[5, 1], [0, 2]])
    np.testing.assert_allclose(mr.mse_per_robot(log), [[25, 1], [0, 4]])
    np.testing.assert_allclose(mr.formation_position_error_per_robot(log), [2.5, 1.5])
    s = m.summary(log)
    assert s["mse_mean"] == pytest.approx(7.5) and s["lf_error_mean"] == pytest.approx(2.0)



def test_leader_robot_target_error_follows_the_leader_robots_pose():
    """Paper 002: the target is eq 5-6 around robot 0's real pose, not the virtual slot."""
    offsets = np.array([[0.0, 0.0], [-1.0, 0.5], [-1.0, -0.5]])
    lead = np.array([[2.0, 3.0, math.pi / 2], [2.0, 4.0, 0.0]])  # two steps, robot 0
    rel = offsets - offsets[0]
    pose = np.zeros((2, 3, 3))
    pose[:, 0] = lead
    # robot 1 exactly on its target at t0 (heading +y: (-1, 0.5) -> (-0.5, -1)), 0.3 m off at t1
    pose[0, 1, :2] = lead[0, :2] + [-0.5, -1.0]
    pose[1, 1, :2] = lead[1, :2] + rel[1] + [0.0, 0.3]
    pose[:, 2, :2] = lead[:, :2] + 10.0  # far away
    log = make_log(pose=pose, slots=np.zeros((2, 3, 2)), offsets=offsets)
    err = mr.leader_robot_target_error(log)
    assert err[:, 0] == pytest.approx([0.0, 0.0])
    assert err[:, 1] == pytest.approx([0.0, 0.3])
    assert err[1, 2] == pytest.approx(np.hypot(10.0 - rel[2, 0], 10.0 - rel[2, 1]))
    # paper 004: a fixed frame (heading 0) instead of the leader robot's heading
    fixed = mr.leader_robot_target_error(log, frame_heading=0.0)
    assert fixed[0, 1] == pytest.approx(np.hypot(-0.5 - rel[1, 0], -1.0 - rel[1, 1]))
    assert fixed[1, 1] == pytest.approx(0.3)


def test_collisions_per_robot_counts_contact_onsets_with_each_kind():
    r = 0.2
    n_t = 6
    pose = np.zeros((n_t, 3, 2))
    pose[:, 0] = [0.0, 0.0]
    pose[:, 1] = [[5.0, 0.0], [0.3, 0.0], [0.3, 0.0], [5.0, 0.0], [0.35, 0.0], [5.0, 0.0]]
    pose[:, 2] = [10.0, 10.0]
    clearance = np.full((n_t, 3), 5.0)
    clearance[[1, 2, 4], 2] = 0.1  # robot 2 touches a static obstacle twice (onsets 1, 4)
    dyn = np.zeros((n_t, 1, 2))
    dyn[:, 0] = [[0.0, 9.0], [0.0, 0.45], [0.0, 9.0], [0.0, 9.0], [0.0, 9.0], [0.0, 0.3]]
    log = make_log(pose=pose, radius=r, clearance=clearance, dyn_pos=dyn,
                   dyn_radius=np.array([0.3]))
    # robot 0: pair onsets with robot 1 at t1 and t4, human onsets at t1 and t5 (0.45 < 0.5)
    # robot 1: the two pair onsets; robot 2: two static onsets
    assert mr.collisions_per_robot(log).tolist() == [4, 2, 2]


# ------------------------------------------------------------------- summary
REQUIRED = """fce_rms fce_mean fce_max fce_x_rms fce_y_rms fse_rms fse_mean fste_max fste_final
stability_pct vce_rms v_rms w_rms risk_mean risk_max min_inter_robot_distance
min_obstacle_clearance collisions robot_contact_steps obstacle_contact_steps path_length_mean
time_to_goal success filter_interventions filter_fallbacks filter_solver_failures mse_mean
lf_error_mean steps outcome reached first_contact_time deadlock_time risk_raw_mean risk_raw_max
risk_clip_pct""".split()


def test_summary_keys_types_and_json():
    log = make_log(pose=np.zeros((4, 1, 2)))  # one robot: NaN min distance
    s = m.summary(log, MetricSpec())
    assert set(REQUIRED) <= set(s)
    assert set(m.PAPER_000_TABLE5) <= set(s)
    for k, v in s.items():
        if k.startswith("robotarium_"):  # the Robotarium's checks: only for a gritsbot
            assert v is None, k
            continue
        assert type(v) in ((str,) if k == "outcome" else (float, int, bool)), (k, type(v))
    assert s["outcome"] in OUTCOMES
    assert s["steps"] == 4 and isinstance(s["steps"], int)
    text = json.dumps(s, allow_nan=True)
    back = json.loads(text)
    assert math.isnan(back["min_inter_robot_distance"]) and math.isnan(back["time_to_goal"])


def test_every_summary_key_has_a_unit():
    """A new metric without a unit in units.UNITS fails here."""
    log = make_log(pose=np.zeros((4, 2, 2)) + [[0.0, 0.0], [2.0, 0.0]],
                   meta={"controller_counters": {"replans": 2}})
    keys = list(m.summary(log, MetricSpec()))
    assert "ctl_replans" in keys
    missing = [k for k in keys if k not in units.UNITS
               and not k.startswith(units.COUNTER_PREFIX)]
    assert missing == []
    assert units.units(keys)["ctl_replans"] == "1"
    assert {k: units.unit(k) for k in ("fce_rms", "time_to_goal", "risk_raw_max",
                                                "collisions", "stability_pct", "w_rms")} == {
        "fce_rms": "m", "time_to_goal": "s", "risk_raw_max": "1/m^2", "collisions": "1",
        "stability_pct": "%", "w_rms": "rad/s"}
    with pytest.raises(KeyError, match="no unit"):
        units.unit("no_such_metric")
    # no unit of a key that no summary or world-difficulty table has
    world = [k for k, _, _ in metrics_world.INDEX_SCALES]
    world += ["world_difficulty", "world_path_length", "world_reference_time"]
    assert set(units.UNITS) == set(keys) - {"ctl_replans"} | set(world)


def test_with_unit_formats_values_for_people():
    assert units.with_unit(0.0027474, "fce_rms") == "0.002747 m"
    assert units.with_unit(65.4, "time_to_goal") == "65.4 s"
    assert units.with_unit(3, "collisions") == "3"
    assert units.with_unit(math.nan, "time_to_goal") == "n/a"
    assert units.with_unit(math.inf, "risk_raw_max") == "inf 1/m^2"
    assert units.with_unit("collision", "outcome") == "collision"


def test_summary_accepts_scenario_like_settings():
    class Holder:  # stands for a ScenarioSpec (.metrics) or a Scenario (.spec.metrics)
        metrics = MetricSpec(stability_threshold=2.0)

    class ScenarioLike:
        spec = Holder()

    pose = SQUARE[None].copy()
    pose[0, 0] += [4.0, 0.0]  # E_s = 1.5
    log = make_log(pose=pose, slots=SQUARE[None])
    assert m.summary(log, Holder())["stability_pct"] == 100.0
    assert m.summary(log, ScenarioLike())["stability_pct"] == 100.0
    assert m.summary(log)["stability_pct"] == 0.0


def test_scales_to_many_robots_without_step_loops():
    rng = np.random.default_rng(0)
    n_t, n = 200, 1000
    pose = rng.uniform(0, 60, size=(n_t, n, 2))
    log = make_log(pose=pose, slots=pose + 0.1)
    r = m.collision_risk(log, MetricSpec(risk_lambda2=0.0))
    assert r.shape == (n_t,) and np.all(r > 0)
    assert m.summary(log)["fse_rms"] == pytest.approx(0.0, abs=1e-9)


# ------------------------------------------------------------------ property
coords = st.floats(-50, 50, allow_nan=False)


@settings(max_examples=60, deadline=None)
@given(pose=arrays(np.float64, (3, 4, 2), elements=coords),
       slots=arrays(np.float64, (3, 4, 2), elements=coords),
       shift=st.tuples(coords, coords), theta=st.floats(-math.pi, math.pi))
def test_shape_error_invariant_under_common_rigid_motion(pose, slots, shift, theta):
    base = m.formation_shape_error(make_log(pose=pose, slots=slots))
    r = rot(theta)
    moved = make_log(pose=pose @ r.T + shift, slots=slots @ r.T + shift)
    np.testing.assert_allclose(m.formation_shape_error(moved), base, atol=1e-9)
    ec = m.formation_centroid_error(make_log(pose=pose, slots=slots))
    np.testing.assert_allclose(m.formation_centroid_error(moved), ec, atol=1e-9)


def test_loc_rmse_is_the_rms_position_estimate_error():
    log = make_log()
    assert m.summary(log)["loc_rmse"] == 0.0
    est = log.pose.copy()
    est[:, 0, :2] += [0.3, 0.4]          # one of four robots off by 0.5 m at every step
    est[:, 1, 2] += 1.0                  # heading errors do not count
    log = make_log(pose_est=est)
    assert m.summary(log)["loc_rmse"] == pytest.approx(math.sqrt(0.25 / 4))


# ------------------------------------------------------------------ open stretches
def test_open_steps_need_every_robot_clear_of_walls_and_moving_discs():
    n_t = 4
    pose = np.repeat(SQUARE[None], n_t, axis=0)
    clearance = np.full((n_t, 4), 5.0)
    clearance[1, 2] = 1.19  # surface gap 0.99 m < 1.0 m: closed
    clearance[2, 0] = 1.2   # exactly 1.0 m: open
    dyn_pos = np.full((n_t, 1, 2), 50.0)
    dyn_pos[3, 0] = [1.0 + 0.2 + 0.3 + 0.9, 1.0]  # 0.9 m from robot 0's edge: closed
    log = make_log(pose=pose, slots=pose[..., :2] + [0.0, 0.5], clearance=clearance,
                   dyn_pos=dyn_pos, dyn_radius=np.array([0.3]))
    assert m.open_steps(log).tolist() == [True, False, True, False]
    s = m.summary(log)
    assert s["open_pct"] == pytest.approx(50.0)
    assert s["fce_open_rms"] == pytest.approx(0.5) and s["fse_open_rms"] == pytest.approx(0.0)
    wide = m.open_steps(log, MetricSpec(open_clearance=0.5))
    assert wide.tolist() == [True, True, True, True]
    nothing_open = make_log(pose=pose, clearance=np.full((n_t, 4), 0.5))
    assert math.isnan(m.summary(nothing_open)["fce_open_rms"])
