"""Robot profiles, actuated dynamics and the LiDAR rate in the simulator."""

from __future__ import annotations

import numpy as np
import pytest

import dfcoa_opt as d
from dfcoa_opt.cli import main
from dfcoa_opt.core.errors import ScenarioError
from dfcoa_opt.scenario.loader import load_scenario
from dfcoa_opt.sim.batch import BatchSimulator
from dfcoa_opt.world.robots.models import ActuatedUnicycle, Unicycle
from dfcoa_opt.world.robots.profiles import PROFILES

SCEN = "scenarios/example_obstacles.toml"


def load(**overrides):
    return load_scenario(SCEN, overrides={"t_max": 3.0, **overrides})


def test_a_profile_fills_the_keys_the_scenario_leaves_out():
    sc = load(**{"robots.profile": "turtlebot3_burger"})
    r, prof = sc.spec.robots, PROFILES["turtlebot3_burger"]
    assert r.wheel_radius == prof["robots"]["wheel_radius"]
    assert r.wheel_speed_max == prof["robots"]["wheel_speed_max"]
    assert sc.spec.sensors.lidar.rate == prof["lidar"]["rate"]
    # kinematic: the actuated-only keys stay at their defaults
    assert r.motor_time_constant == 0.0 and r.wheel_accel_max == float("inf")
    act = load(**{"robots.profile": "turtlebot3_burger", "robots.dynamics": "actuated"})
    assert act.spec.robots.motor_time_constant == prof["robots"]["motor_time_constant"]
    assert act.spec.robots.wheel_accel_max == prof["robots"]["wheel_accel_max"]


def test_explicit_keys_override_the_profile():
    sc = load(**{"robots.profile": "jackal", "robots.track_width": 0.5,
                 "sensors.lidar.beams": 90})
    assert sc.spec.robots.track_width == 0.5
    assert sc.spec.robots.wheel_radius == PROFILES["jackal"]["robots"]["wheel_radius"]
    assert sc.spec.sensors.lidar.beams == 90


def test_without_a_profile_nothing_changes():
    assert load().spec == load_scenario(SCEN, overrides={"t_max": 3.0}).spec
    assert load().spec.robots.dynamics == "kinematic"


@pytest.mark.parametrize(("overrides", "key", "words"), [
    ({"robots.profile": "turtlebot"}, "robots.profile", "known profiles: gritsbot, jackal"),
    ({"robots.motor_time_constant": 0.1}, "robots.motor_time_constant", "dynamics = 'actuated'"),
    ({"robots.dynamics": "actuated", "robots.model": "single_integrator"}, "robots.dynamics",
     "applies to model = 'unicycle'"),
])
def test_bad_robot_keys_are_one_line_errors(overrides, key, words):
    with pytest.raises(ScenarioError) as err:
        load(**overrides)
    text = str(err.value)
    assert "\n" not in text and key in text and words in text and SCEN in text


def test_actuated_batch_equals_single_runs_with_wheel_noise_and_a_lidar_rate():
    sc = load(**{"robots.profile": "turtlebot3_waffle_pi", "robots.dynamics": "actuated",
                 "robots.wheel_noise_std": 0.3})
    assert sc.spec.sensors.lidar.rate == 5.0
    seeds = [0, 1, 2]
    batch = d.run_batch(sc, "dfcoa", seeds)
    for seed, run in zip(seeds, batch, strict=True):
        alone = d.run(sc, "dfcoa", seed=seed)
        assert alone.log.digest() == run.log.digest()
    assert batch[0].log.digest() != batch[1].log.digest()


def test_actuated_runs_differ_from_kinematic_ones_and_noise_follows_the_seed():
    kin = d.run(load(), "goto_slot", seed=0).log
    act = d.run(load(**{"robots.dynamics": "actuated", "robots.motor_time_constant": 0.3}),
                "goto_slot", seed=0).log
    assert not np.array_equal(kin.pose, act.pose)
    # the lag: the first step's speed is below the kinematic robot's
    assert abs(act.twist[0, 0, 0]) < abs(kin.twist[0, 0, 0])
    noisy = load(**{"robots.dynamics": "actuated", "robots.wheel_noise_std": 0.5})
    assert d.run(noisy, "goto_slot", seed=4).log.digest() == \
        d.run(noisy, "goto_slot", seed=4).log.digest()


class Recorder:
    """Goes straight and records what it observes."""

    name, command = "recorder", "unicycle"

    def __init__(self):
        self.scans, self.limits = [], []

    def reset(self, scenario, rng):
        pass

    def act(self, obs):
        self.scans.append(obs.scan.ranges.copy())
        self.limits.append(obs.limits)
        return np.tile([0.4, 0.3], (obs.n, 1))


def test_the_lidar_rate_holds_each_scan_until_the_next():
    """5 Hz at dt = 0.1 s: a new scan every second step, the same one in between."""
    rec = Recorder()
    sc = load(**{"sensors.lidar.rate": 5.0, "t_max": 1.0})
    d.run(sc, rec, seed=0)
    s = rec.scans
    for k in range(0, len(s) - 1, 2):
        assert np.array_equal(s[k], s[k + 1])
        if k + 2 < len(s):
            assert not np.array_equal(s[k + 1], s[k + 2])


def test_observations_carry_the_limits():
    rec = Recorder()
    sc = load(**{"robots.profile": "gritsbot", "robots.dynamics": "actuated", "t_max": 0.3})
    d.run(sc, rec, seed=0)
    lim = rec.limits[0]
    prof = PROFILES["gritsbot"]["robots"]
    assert lim.wheel_speed_max == prof["wheel_speed_max"]
    assert lim.wheel_accel_max == prof["wheel_accel_max"]
    assert lim.motor_time_constant == prof["motor_time_constant"]
    assert lim.dynamics == "actuated"
    sim = BatchSimulator(sc, Recorder(), [0])
    assert type(sim.model) is ActuatedUnicycle
    assert type(BatchSimulator(load(), Recorder(), [0]).model) is Unicycle


def test_cli_run_with_a_profile_and_actuated_dynamics(tmp_path, capsys):
    code = main(["run", "scenarios/bench/crossing.toml", "--controller", "orca_nav",
                 "--set", "robots.profile=turtlebot3_burger", "--set", "robots.dynamics=actuated",
                 "--set", "t_max=2", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert code == 0 and "wheel_speed_peak" in out and "saturated_pct" in out
