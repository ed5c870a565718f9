"""Monte Carlo localization (dfcoa_opt.sim.localization.mcl)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchmarks.bench_mcl import numpy_sensor_update
from dfcoa_opt.core.errors import DfcoaError, ScenarioError
from dfcoa_opt.core.geometry import wrap_angle_fast
from dfcoa_opt.scenario.loader import scenario_from_dict
from dfcoa_opt.sim.localization import estimator_names, make_estimator
from dfcoa_opt.sim.localization.mcl import MonteCarloLocalization
from dfcoa_opt.sim.localization.mcl.motion import decompose_motion, sample_motion
from dfcoa_opt.sim.localization.mcl.resampling import (
    kld_sample_size,
    low_variance_resample,
    resample,
)
from dfcoa_opt.sim.localization.mcl.sensor import likelihood_table, sensor_update
from dfcoa_opt.sim.simulator import run_scenario
from dfcoa_opt.world.lidar import Lidar

WALLS = [  # a 12 m x 10 m room with a pillar in the middle and two more obstacles
    {"type": "rectangle", "min": [0.0, 0.0], "max": [12.0, 0.3]},
    {"type": "rectangle", "min": [0.0, 9.7], "max": [12.0, 10.0]},
    {"type": "rectangle", "min": [0.0, 0.0], "max": [0.3, 10.0]},
    {"type": "rectangle", "min": [11.7, 0.0], "max": [12.0, 10.0]},
    {"type": "rectangle", "min": [5.3, 4.3], "max": [6.7, 5.7]},
    {"type": "circle", "center": [2.0, 8.0], "radius": 0.6},
    {"type": "rectangle", "min": [9.5, 1.0], "max": [10.5, 2.5]},
]


def room(options=None, n=2, **over):
    d = {"dt": 0.1, "t_max": 10.0, "seed": 0,
         "world": {"size": [12.0, 10.0], "resolution": 10, "obstacles": WALLS},
         "team": {"n": n}, "formation": {"shape": "line", "spacing": 1.0},
         "leader": {"start": [3.0, 2.0], "goal": [9.0, 8.0], "speed": 0.3},
         "sensors": {"lidar": {"beams": 120, "range_max": 8.0}},
         "localization": {"mode": "mcl", "options": options or {}}}
    d.update(over)
    return scenario_from_dict(d, "<test>")


def circles(n, steps, dt=0.1, speed=0.3, radius=3.2):
    """True poses ``(steps, n, 3)``: robots on a circle around the pillar, half a turn apart."""
    t = np.arange(steps)[:, None] * dt
    a = speed / radius * t + np.pi * np.arange(n)[None, :]
    return np.stack([6.0 + radius * np.cos(a), 5.0 + radius * np.sin(a), a + np.pi / 2], axis=-1)


def drive(sc, poses, seed):
    """Estimates, odometry poses and particle counts at every step of ``poses``."""
    lidar = Lidar(sc.spec.sensors.lidar, sc.world.grid)
    n = poses.shape[1]
    est = MonteCarloLocalization(sc)
    est.reset(np.random.default_rng(seed))
    out, odom, counts = [], [], []
    for p in poses:
        scan = lidar.scan(p, p[:, :2], np.full(n, 0.2), np.arange(n))
        out.append(est.estimate(p, np.zeros((n, 2)), scan, 0.1))
        odom.append(est.odometry)
        counts.append(est.particle_counts)
    return np.array(out), np.array(odom), np.array(counts), est


def rmse(a, b):
    return float(np.sqrt(np.mean(np.sum((a[..., :2] - b[..., :2]) ** 2, axis=-1))))


@pytest.fixture(scope="module")
def circle_run():
    sc = room()
    poses = circles(2, 400)
    return poses, drive(sc, poses, seed=7)


def test_registered_with_paper_defaults():
    assert "mcl" in estimator_names()
    p = MonteCarloLocalization.Params()
    assert p.particle_limits == (50, 5000) and p.resampling_interval == 1
    assert p.initial_covariance == (0.05, 0.05, 0.05)
    assert p.update_thresholds == (0.01, 0.01, 0.1)
    assert p.odometry_noise == (0.25, 0.25, 0.2, 0.2)
    assert (p.sensor_limits, p.num_beams, p.measurement_noise) == ((0.0, 200.0), 120, 0.25)
    assert (p.expected_measurement_weight, p.random_measurement_weight) == (0.97, 0.03)
    assert p.max_likelihood_distance == 3.5
    assert isinstance(make_estimator("mcl", room()), MonteCarloLocalization)


def test_mcl_beats_dead_reckoning(circle_run):
    poses, (est, odom, _, _) = circle_run
    mcl_err, dr_err = rmse(est, poses), rmse(odom, poses)
    heading = np.abs(wrap_angle_fast(est[..., 2] - poses[..., 2]))
    assert mcl_err < 0.06, mcl_err
    assert dr_err > 0.3, dr_err  # the odometry noise is large (paper alphas)
    assert mcl_err < 0.1 * dr_err
    assert np.hypot(*(est[..., :2] - poses[..., :2]).T).max() < 0.25
    assert heading.max() < 0.15


def test_particle_counts_stay_in_limits_and_shrink(circle_run):
    _, (_, _, counts, est) = circle_run
    lo, hi = est.params.particle_limits
    assert counts.min() >= lo and counts.max() <= hi
    assert np.all(counts[-50:] < 200)  # converged: a handful of KLD bins


def test_counts_start_at_max_and_adapt():
    sc = room({"particle_limits": [30, 2000], "resampling_interval": 2,
               "initial_covariance": [0.3, 0.3, 0.2]})
    poses = circles(2, 12)
    _, _, counts, _ = drive(sc, poses, seed=1)
    assert np.all(counts[0] == 2000)  # no resampling yet at the first update
    assert np.all(counts[-1] < 300) and counts.min() >= 30


def test_kld_resampling_grows_with_spread():
    rng = np.random.default_rng(0)
    tight = np.column_stack((rng.normal(5.2, 0.01, 500), rng.normal(5.2, 0.01, 500),
                             rng.normal(0.3, 0.01, 500)))
    wide = np.column_stack((rng.uniform(0, 20, 500), rng.uniform(0, 20, 500),
                            rng.uniform(-np.pi, np.pi, 500)))
    parts = np.vstack((tight, wide))
    w = np.full(1000, 1.0 / 500)
    ptr = np.array([0, 500, 1000])
    bins = np.array([0.5, 0.5, math.pi / 18])
    _, new_w, new_ptr = resample(parts, w, ptr, np.array([True, True]), np.full((2, 2), 0.5),
                                 20, 3000, bins, 0.05, 0.99)
    n_tight, n_wide = np.diff(new_ptr)
    assert n_tight == 20  # one bin: the lower limit
    assert n_wide == 3000  # ~500 distinct bins: the bound (~5000) is over the upper limit
    np.testing.assert_allclose(new_w[:n_tight], 1.0 / n_tight)


def test_kld_bound_formula():
    assert kld_sample_size(1, 0.05, 0.99) == 0
    k, eps, z = 50, 0.05, 2.326
    b = 2.0 / (9.0 * (k - 1))
    bound = (k - 1) / (2 * eps) * (1 - b + math.sqrt(b) * z) ** 3
    assert kld_sample_size(k, eps, z) == math.ceil(bound)
    sizes = np.array([kld_sample_size(k, 0.05, 0.99) for k in range(2, 200)])
    assert np.all(np.diff(sizes) > 0)


def test_low_variance_resampling_counts_proportional_to_weights():
    rng = np.random.default_rng(3)
    w = rng.random(37) ** 3
    for n, u in ((1000, 0.0), (1000, 0.999), (250, 0.37)):
        idx = low_variance_resample(w, n, u)
        counts = np.bincount(idx, minlength=w.size)
        expect = n * w / w.sum()
        assert counts.sum() == n and np.all(np.diff(idx) >= 0)
        assert np.all(np.abs(counts - expect) < 1.0 + 1e-9)
    # a single heavy particle takes every draw
    assert np.all(low_variance_resample([0.0, 1.0, 0.0], 10, 0.5) == 1)


def test_odometry_model_noise_free_is_exact_and_noise_matches_alphas():
    rng = np.random.default_rng(0)
    prev = np.column_stack((rng.uniform(-5, 5, (50, 2)), rng.uniform(-3, 3, 50)))
    cur = prev + np.column_stack((rng.normal(0, 0.3, (50, 2)), rng.normal(0, 0.5, 50)))
    for mode in ("heading_change", "decomposition"):
        m = decompose_motion(prev, cur, mode)
        out = sample_motion(prev, m, (0, 0, 0, 0), rng.standard_normal((50, 3)))
        np.testing.assert_allclose(out[:, :2], cur[:, :2], atol=1e-12)
        np.testing.assert_allclose(wrap_angle_fast(out[:, 2] - cur[:, 2]), 0.0, atol=1e-12)
    # straight 1 m drive: translation variance alpha3 * 1, heading variance 2 * alpha2 * 1
    start = np.zeros((200_000, 3))
    end = np.tile([1.0, 0.0, 0.0], (200_000, 1))
    out = sample_motion(start, decompose_motion(start, end), (0.1, 0.04, 0.09, 0.3),
                        rng.standard_normal((200_000, 3)))
    assert abs(np.hypot(out[:, 0], out[:, 1]).std() - 0.3) < 0.01
    assert abs(out[:, 2].std() - math.sqrt(2 * 0.04)) < 0.01


def test_sideways_push_is_not_a_turn():
    prev = np.zeros((1, 3))
    cur = np.array([[0.0, 0.1, 0.0]])  # pushed 0.1 m to the left, no turn
    _, _, _, n1, n2 = decompose_motion(prev, cur, "heading_change")
    assert n1[0] == n2[0] == 0.0
    _, _, _, n1, n2 = decompose_motion(prev, cur, "decomposition")
    assert n1[0] == pytest.approx(math.pi / 2) and n2[0] == pytest.approx(math.pi / 2)


def test_same_seed_identical_different_seed_differs():
    sc = room()
    poses = circles(2, 40)
    a = drive(sc, poses, seed=11)
    b = drive(sc, poses, seed=11)
    c = drive(sc, poses, seed=12)
    for x, y in zip(a[:3], b[:3], strict=True):
        np.testing.assert_array_equal(x, y)
    assert not np.array_equal(a[0], c[0]) and not np.array_equal(a[1], c[1])


def test_reset_restarts_the_same_sequence():
    sc = room()
    poses = circles(2, 15)
    _, _, _, est = drive(sc, poses, seed=5)
    lidar = Lidar(sc.spec.sensors.lidar, sc.world.grid)
    first = drive(sc, poses, seed=5)[0]
    est.reset(np.random.default_rng(5))
    again = [est.estimate(p, None, lidar.scan(p, p[:, :2], np.full(2, 0.2), np.arange(2)), 0.1)
             for p in poses]
    np.testing.assert_array_equal(first, np.array(again))


def test_no_update_below_thresholds():
    sc = room()
    lidar = Lidar(sc.spec.sensors.lidar, sc.world.grid)
    est = MonteCarloLocalization(sc)
    est.reset(np.random.default_rng(0))
    pose = circles(2, 1)[0]

    def scan(p):
        return lidar.scan(p, p[:, :2], np.full(2, 0.2), np.arange(2))

    e0 = est.estimate(pose, None, scan(pose), 0.1)
    assert est.updated.all() and np.all(est.update_counts == 1)
    parts0 = est.particles(0)
    for _ in range(5):  # standing still: no odometry change, no update, same estimate
        e = est.estimate(pose, None, scan(pose), 0.1)
        assert not est.updated.any()
        np.testing.assert_array_equal(e, e0)
    np.testing.assert_array_equal(est.particles(0)[0], parts0[0])
    moved = pose.copy()
    moved[0, 0] += 0.005  # below the 0.01 m x threshold: follows the odometry only
    e = est.estimate(moved, None, scan(moved), 0.1)
    assert not est.updated.any() and np.all(est.update_counts == 1)
    np.testing.assert_array_equal(est.particles(0)[0], parts0[0])
    assert 0.0 < np.hypot(*(e[0, :2] - e0[0, :2])) < 0.02
    np.testing.assert_array_equal(e[1], e0[1])
    moved[0, 0] += 0.02  # now over it: robot 0 updates, robot 1 does not
    est.estimate(moved, None, scan(moved), 0.1)
    assert est.updated.tolist() == [True, False]
    assert est.update_counts.tolist() == [2, 1]
    turned = moved.copy()
    turned[1, 2] += 0.15  # a turn in place over the 0.1 rad threshold
    est.estimate(turned, None, scan(turned), 0.1)
    assert est.updated.tolist() == [False, True]


def test_numba_sensor_update_matches_numpy_reference():
    sc = room()
    est = MonteCarloLocalization(sc)
    lidar = Lidar(sc.spec.sensors.lidar, sc.world.grid)
    pose = circles(2, 1)[0]
    s = lidar.scan(pose, pose[:, :2], np.full(2, 0.2), np.arange(2))
    ex, ey, nv = est._beams(s)
    rng = np.random.default_rng(0)
    parts = np.repeat(pose, [300, 200], axis=0) + rng.normal(0, 0.3, (500, 3))
    parts[::7, :2] += 20.0  # some end points off the map
    ptr = np.array([0, 300, 500])
    for amcl in (False, True):
        table, outside = likelihood_table(sc.world.grid, 0.25, 0.97, 0.03, 200.0, 3.5,
                                          "amcl" if amcl else "product")
        for upd in ([True, True], [False, True]):
            w1 = rng.random(500)
            w1[:300] /= w1[:300].sum()
            w1[300:] /= w1[300:].sum()
            w2, e1, e2 = w1.copy(), np.zeros((2, 3)), np.zeros((2, 3))
            args = (ptr, np.array(upd), ex, ey, nv, table, outside, est._ox, est._oy,
                    est._inv_h, amcl)
            sensor_update(parts, w1, *args, e1)
            numpy_sensor_update(parts, w2, *args, e2)
            np.testing.assert_allclose(w1, w2, rtol=1e-9, atol=1e-300)
            np.testing.assert_allclose(e1, e2, rtol=1e-9, atol=1e-12)


def test_boundary_field_penalises_end_points_inside_thick_walls():
    sc = room()
    grid = sc.world.grid
    table, _ = likelihood_table(grid, 0.25, 0.97, 0.03, 200.0, 3.5, "product", "boundary")
    inside = grid.world_to_cell(np.array([6.0, 5.0]))  # centre of the 1.4 m pillar
    face = grid.world_to_cell(np.array([5.35, 5.0]))  # its west face
    assert table[inside] < table[face] - 2.0  # 0.7 m from the boundary
    occupied, _ = likelihood_table(grid, 0.25, 0.97, 0.03, 200.0, 3.5, "product",
                                   "occupied")
    assert occupied[inside] == occupied[face]


def test_bad_options_name_the_key():
    with pytest.raises(ScenarioError, match=r"localization\.options\.num_beam: unknown key "
                                            r"\(did you mean 'num_beams'\?\)"):
        room({"num_beam": 60})
    with pytest.raises(ScenarioError, match=r"localization\.options\.particle_limits"):
        room({"particle_limits": [500, 50]})
    with pytest.raises(ScenarioError, match=r"localization\.options\.measurement_noise"):
        room({"measurement_noise": 0.0})
    sc = room({"num_beams": 60, "particle_limits": [100, 1000]})
    assert MonteCarloLocalization(sc).params.num_beams == 60


def test_needs_a_lidar():
    sc = room(sensors={"lidar": {"enabled": False}})
    with pytest.raises(DfcoaError, match="needs the LiDAR"):
        MonteCarloLocalization(sc)
    est = MonteCarloLocalization(room())
    est.reset(np.random.default_rng(0))
    with pytest.raises(DfcoaError, match="scan"):
        est.estimate(circles(2, 1)[0], None, None, 0.1)


def test_end_to_end_goto_slot_with_mcl():
    sc = scenario_from_dict({
        "dt": 0.1, "t_max": 25.0, "seed": 4,
        "world": {"size": [12.0, 10.0], "resolution": 10, "obstacles": WALLS[:4] + WALLS[5:]},
        "team": {"n": 4, "start_noise": 0.1, "heading_noise": 0.1},
        "formation": {"shape": "rectangle", "width": 1.5, "length": 1.5},
        "leader": {"start": [2.5, 2.5], "goal": [8.5, 7.5], "speed": 0.3},
        "sensors": {"lidar": {"beams": 120, "range_max": 8.0}},
        "localization": "mcl"}, "<e2e>")
    log = run_scenario(sc, "goto_slot")
    err = np.hypot(*(log.pose_est[..., :2] - log.pose[..., :2]).transpose(2, 0, 1))
    heading = np.abs(wrap_angle_fast(log.pose_est[..., 2] - log.pose[..., 2]))
    assert log.meta["steps"] > 150
    assert not np.array_equal(log.pose_est, log.pose)
    assert np.sqrt(np.mean(err ** 2)) < 0.08, np.sqrt(np.mean(err ** 2))
    assert err.max() < 0.3 and heading.max() < 0.2
