from pathlib import Path

import numpy as np
import pytest
import shapely

from dfcoa_opt.control.goto_slot import GotoSlot
from dfcoa_opt.scenario.loader import load_scenario, scenario_from_dict
from dfcoa_opt.sim.log import RunLog
from dfcoa_opt.sim.simulator import ControllerError, Simulator, run_scenario
from tests.helpers import Capture, assert_distributed

SCEN = Path(__file__).resolve().parents[1] / "scenarios"


def small(**over):
    d = {"dt": 0.1, "t_max": 30.0, "seed": 3,
         "world": {"size": [12.0, 8.0], "resolution": 10},
         "team": {"n": 4}, "formation": {"shape": "rectangle", "width": 1.2, "length": 1.6},
         "leader": {"start": [2.0, 4.0], "goal": [9.0, 4.0], "speed": 0.4},
         "sensors": {"lidar": {"beams": 36, "range_max": 5.0}}}
    for k, v in over.items():
        d[k] = {**d.get(k, {}), **v} if isinstance(v, dict) else v
    return scenario_from_dict(d, "<test>")


def test_goto_slot_reaches_goal_in_empty_world():
    sc = load_scenario(SCEN / "example_empty.toml")
    log = run_scenario(sc, "goto_slot")
    assert log.meta["reached_goal"] and log.meta["time_to_goal"] < sc.spec.t_max
    err = np.hypot(*(log.pose[-1, :, :2] - log.slots[-1]).T)
    assert np.all(err <= sc.spec.leader.settle_tolerance)
    assert np.hypot(*(log.leader[-1, :2] - sc.spec.leader.goal)) <= sc.spec.leader.goal_radius
    assert log.collision_events.sum() == 0


def test_obstacle_world_contacts_match_exact_geometry():
    sc = load_scenario(SCEN / "example_obstacles.toml")
    log = run_scenario(sc, "goto_slot")
    assert log.meta["reached_goal"]
    g = sc.world.grid
    cells = [shapely.box(g.origin[0] + j * g.cell_size, g.origin[1] + i * g.cell_size,
                         g.origin[0] + (j + 1) * g.cell_size, g.origin[1] + (i + 1) * g.cell_size)
             for i, j in np.argwhere(g.occupied)]
    union = shapely.unary_union(cells)
    pts = log.pose[:, :, :2].reshape(-1, 2)
    d = shapely.distance(union, shapely.points(pts)).reshape(log.pose.shape[:2])
    r = log.meta["robot_radius"]
    assert np.array_equal(log.obstacle_contacts, (d < r).sum(axis=1))
    assert log.obstacle_contacts.sum() > 0, "this scenario is built so that goto_slot hits a wall"
    onsets = np.diff(np.concatenate(([0], (d < r).any(1).astype(int)))).clip(0).sum()
    assert log.collision_events.sum() >= onsets >= 1


class NoisySteer:
    """Turns away from the nearest LiDAR return: makes trajectories depend on scan noise."""

    name = "noisy_steer"
    command = "unicycle"

    def reset(self, scenario, rng):
        self.rng = rng

    def act(self, obs):
        r = np.where(np.isfinite(obs.scan.ranges), obs.scan.ranges, 99.0)
        k = r.argmin(axis=1)
        turn = -np.sign(np.sin(obs.scan.angles[k])) * 0.5 / np.maximum(r.min(axis=1), 0.2)
        return np.column_stack((np.full(obs.n, 0.3), turn))


def test_same_seed_same_bits_other_seed_other_bits():
    sc = small(sensors={"lidar": {"beams": 36, "range_max": 5.0, "noise_std": 0.05}})
    a = Simulator(sc, NoisySteer(), seed=11).run()
    b = Simulator(sc, NoisySteer(), seed=11).run()
    c = Simulator(sc, NoisySteer(), seed=12).run()
    assert a.digest() == b.digest()
    for name, arr in a.arrays().items():
        np.testing.assert_array_equal(arr, b.arrays()[name], err_msg=name)
    assert a.digest() != c.digest()


def test_log_roundtrip(tmp_path):
    log = run_scenario(small(), "goto_slot")
    back = RunLog.load(log.save(tmp_path / "run.npz"))
    assert back.digest() == log.digest() and back.meta["controller"] == "goto_slot"
    with np.load(tmp_path / "run.npz") as z:  # truth localisation: pose_est is pose, once
        assert "pose_est" not in z.files and "pose" in z.files
    assert back.pose_est is not back.pose
    # an estimate that differs from the truth -- here only in the sign of a zero -- is kept
    log.pose_est[0, 0, 2] = -0.0 if log.pose[0, 0, 2] == 0.0 else log.pose[0, 0, 2] + 1e-3
    back = RunLog.load(log.save(tmp_path / "est.npz"))
    np.testing.assert_array_equal(back.pose_est.view(np.uint64), log.pose_est.view(np.uint64))
    assert back.digest() == log.digest()


def test_observation_rows_and_goto_slot_is_distributed():
    sc = small(world={"dynamic_obstacles": [{"radius": 0.3, "speed": 0.0,
                                              "waypoints": [[6.0, 7.5]]}]},
               sensors={"comm_radius": 1.7, "max_neighbors": 2, "obstacle_range": 3.0})
    cap = Capture(GotoSlot(GotoSlot.Params()))
    Simulator(sc, cap).run()
    obs = cap.obs[5]
    assert obs.scan.ranges.shape == (4, 36)
    d = np.hypot(*(obs.pose[:, None, :2] - obs.pose[None, :, :2]).transpose(2, 0, 1))
    for i in range(4):
        nb = obs.neighbours.index[i][obs.neighbours.mask[i]]
        expect = [j for j in np.argsort(d[i]) if j != i and d[i, j] <= 1.7][:2]
        assert list(nb) == expect
        sees = bool(obs.obstacles.mask[i, 0])
        assert sees == (np.hypot(*(obs.pose[i, :2] - [6.0, 7.5])) - 0.3 <= 3.0)
    assert np.allclose(obs.slot, obs.leader[:2] + (obs.slot - obs.leader[:2]))
    assert_distributed(GotoSlot(GotoSlot.Params()), obs)


@pytest.mark.parametrize("bad,msg", [(np.nan, "NaN/inf for robot"), ("shape", "returned shape")])
def test_bad_controller_output_fails_the_run(bad, msg):
    class Bad:
        name, command = "bad", "velocity"

        def reset(self, scenario, rng):
            pass

        def act(self, obs):
            if bad == "shape":
                return np.zeros((obs.n + 1, 2))
            u = np.zeros((obs.n, 2))
            u[2, 1] = bad
            return u

    with pytest.raises(ControllerError, match=msg):
        Simulator(small(), Bad()).run()


def test_velocity_disturbance_only_moves_its_robot_in_its_window():
    base = small()
    hit = small(disturbances=[{"robot": 1, "t_start": 1.0, "t_end": 2.0, "value": [0.0, 0.5]}])
    a, b = run_scenario(base, "goto_slot"), run_scenario(hit, "goto_slot")
    k1, k2 = 10, 21  # t = 1.0 s and the first step after the window
    np.testing.assert_array_equal(a.pose[: k1 + 1], b.pose[: k1 + 1])
    dy = b.pose[k2, 1, 1] - a.pose[k2, 1, 1]
    assert dy > 0.1  # pushed by up to 0.5 m, partly corrected already
    others = [0, 2, 3]
    assert np.allclose(a.pose[k2, others], b.pose[k2, others])


def test_stop_on_collision_and_double_integrator():
    sc = small(robots={"model": "double_integrator", "a_max": 2.0, "v_max": 0.8})
    log = run_scenario(sc, "goto_slot")  # velocity commands -> acceleration adapter
    assert log.meta["reached_goal"] and log.meta["robot_model"] == "double_integrator"
    crash = small(stop_on_collision=True, world={"obstacles": [
        {"type": "rectangle", "min": [5.0, 4.2], "max": [6.0, 4.9]}]})
    log2 = run_scenario(crash, "goto_slot")
    assert not log2.meta["reached_goal"] and log2.collision_events[-1] >= 1
    assert log2.collision_events[:-1].sum() == 0


def test_localization_shorthand_and_unknown_mode():
    from dfcoa_opt.core.errors import ScenarioError

    assert small(localization="truth").spec.localization.mode == "truth"
    with pytest.raises(ScenarioError, match="localization.mode: unknown estimator 'gps'"):
        small(localization="gps")


def test_world_clearance_is_exact_against_shapely():
    """Contacts are measured on the exact shapes (and map cells), not the rasterised shapes.

    Oracle: shapely's distance to the union of the polygons and circles.
    """
    sc = load_scenario(SCEN / "example_obstacles.toml")
    world = sc.world
    geoms = [shapely.Polygon(v) for v in world.polygons]
    geoms += [shapely.Point(c.center).buffer(c.radius, quad_segs=4096) for c in world.circles]
    union = shapely.union_all(geoms)
    rng = np.random.default_rng(3)
    pts = rng.uniform([0.0, 0.0], [24.0, 14.0], size=(2000, 2))
    ours = world.clearance(pts, cap=100.0)
    ref = np.array([union.distance(shapely.Point(p)) for p in pts])
    assert np.max(np.abs(ours - ref)) < 1e-6
    assert np.any(ours == 0.0) and np.any(ours > 1.0)
    # the rasterised grid differs by up to a cell diagonal: the old measure was not exact
    grid = world.grid.clearance(pts, cap=100.0)
    assert np.max(np.abs(grid - ref)) > 0.03


class _NoScan(Capture):
    uses_scan = False


def test_lidar_runs_only_when_the_controller_or_estimator_reads_it():
    sc = small(sensors={"lidar": {"beams": 36, "range_max": 5.0, "noise_std": 0.02}})
    with_scan, without = Capture(GotoSlot(GotoSlot.Params())), _NoScan(GotoSlot(GotoSlot.Params()))
    a, b = Simulator(sc, with_scan).run(), Simulator(sc, without).run()
    assert all(o.scan is not None for o in with_scan.obs)
    assert all(o.scan is None for o in without.obs)
    # the scan (and its noise draws) fed nothing else: the runs are the same, bit for bit
    assert a.digest() == b.digest()
    # Monte Carlo localisation reads the scan, so the LiDAR runs for it anyway
    mcl = small(localization={"mode": "mcl"})
    probe = _NoScan(GotoSlot(GotoSlot.Params()))
    Simulator(mcl, probe).run()
    assert probe.obs[0].scan is not None
