"""Internal consistency of the robot profiles (dfcoa_opt/world/robots/profiles.py, docs/robots.md).

Each check is one a mistyped value would break: a digit dropped from a wheel radius breaks
the speed relations, a range_min typed as range_max breaks the LiDAR order, and so on.
"""

from __future__ import annotations

import dataclasses
import math

import pytest

from dfcoa_opt.scenario.schema import LidarSpec, RobotSpec
from dfcoa_opt.world.robots.profiles import PROFILES, ROBOTARIUM

ROBOT_KEYS = {"radius", "wheel_radius", "track_width", "wheel_speed_max", "v_max", "w_max",
              "wheel_accel_max", "motor_time_constant"}
LIDAR_KEYS = {"beams", "fov", "range_min", "range_max", "noise_std", "rate"}
SLACK = 1.05  # published speeds are rounded; 5 % covers that, not a mistyped digit

# Published pairs that break the wheel-speed bound on w_max, each with the relation it does
# keep (docs/robots.md): the ROBOTIS e-manual gives the Burger 2.84 rad/s, which needs
# 2.84 * 0.080 / 0.033 = 6.88 rad/s (65.7 rpm) at the wheels while the XL430-W250 turns at
# most 61 rpm (6.39 rad/s, bound 2.64 rad/s); 2.84 rad/s is within 5 % of 2 v_max / d = 2.75.
W_MAX_EXCEPTIONS = {"turtlebot3_burger"}


@pytest.fixture(params=sorted(PROFILES))
def name(request: pytest.FixtureRequest) -> str:
    return request.param


def test_every_profile_has_the_same_robots_keys(name: str) -> None:
    assert set(PROFILES[name]) == {"robots", "lidar"}
    assert set(PROFILES[name]["robots"]) == ROBOT_KEYS


def test_profile_keys_are_scenario_keys() -> None:
    robot_fields = {f.name for f in dataclasses.fields(RobotSpec)}
    lidar_fields = {f.name for f in dataclasses.fields(LidarSpec)}
    assert ROBOT_KEYS <= robot_fields
    assert LIDAR_KEYS <= lidar_fields


def test_all_values_are_positive_and_finite(name: str) -> None:
    for section in ("robots", "lidar"):
        for key, value in PROFILES[name][section].items():
            assert isinstance(value, (int, float)) and not isinstance(value, bool), key
            assert math.isfinite(value) and value > 0, f"{name}.{section}.{key} = {value}"


def test_v_max_is_reachable_by_the_wheels(name: str) -> None:
    r = PROFILES[name]["robots"]
    assert r["v_max"] <= r["wheel_speed_max"] * r["wheel_radius"] * SLACK


def test_w_max_is_reachable_by_the_wheels(name: str) -> None:
    r = PROFILES[name]["robots"]
    bound = 2 * r["wheel_speed_max"] * r["wheel_radius"] / r["track_width"]
    if name in W_MAX_EXCEPTIONS:
        # the exception is still needed, and the published pair keeps the kinematic relation
        assert r["w_max"] > bound * SLACK
        assert r["w_max"] <= 2 * r["v_max"] / r["track_width"] * SLACK
    else:
        assert r["w_max"] <= bound * SLACK


def test_the_collision_disc_covers_the_wheels(name: str) -> None:
    r = PROFILES[name]["robots"]
    assert r["radius"] >= r["track_width"] / 2


# Plausibility: bounds every real robot of this class keeps, wide enough for all four
# profiles, narrow enough that a decimal point typed one place off falls outside them.


def test_the_published_top_speed_uses_the_wheels(name: str) -> None:
    r = PROFILES[name]["robots"]
    assert r["v_max"] >= 0.9 * r["wheel_speed_max"] * r["wheel_radius"]
    assert r["w_max"] >= 0.3 * 2 * r["v_max"] / r["track_width"]


def test_the_geometry_is_that_of_a_small_wheeled_robot(name: str) -> None:
    r = PROFILES[name]["robots"]
    assert r["wheel_radius"] < r["track_width"] / 2  # the wheels fit on the axle
    assert r["radius"] <= 1.25 * r["track_width"]  # the body is not much wider than the axle


def test_the_acceleration_is_physical(name: str) -> None:
    r = PROFILES[name]["robots"]
    assert 0.01 <= r["v_max"] / r["wheel_accel_max"] <= 1.0  # 0 to v_max in 10 ms to 1 s
    assert r["wheel_accel_max"] <= 15.0  # about 1.5 g: no tyre grips harder


def test_the_motor_lag_is_in_the_documented_range(name: str) -> None:
    assert 0.02 <= PROFILES[name]["robots"]["motor_time_constant"] <= 0.2


def test_the_lidar_is_a_lidar(name: str) -> None:
    lidar = PROFILES[name]["lidar"]
    if name == "gritsbot":
        assert lidar == {}  # no LiDAR on the GRITSbot
        return
    assert set(lidar) == LIDAR_KEYS
    assert isinstance(lidar["beams"], int) and lidar["beams"] >= 1
    assert 0 < lidar["fov"] <= 2 * math.pi
    assert lidar["range_min"] < lidar["range_max"]
    assert lidar["noise_std"] < lidar["range_min"]  # a 1-sigma error, not a range
    assert 0.2 <= math.degrees(lidar["fov"] / lidar["beams"]) <= 2.0  # angular step, deg
    assert 0.003 <= lidar["noise_std"] <= 0.05
    assert lidar["range_min"] <= 1.0 and lidar["range_max"] >= 2.0
    assert 1.0 <= lidar["rate"] <= 100.0


def test_the_robotarium_limits_are_the_gritsbot_profile() -> None:
    g = PROFILES["gritsbot"]["robots"]
    # as in the simulator source: max_wheel_velocity = max_linear_velocity / wheel_radius
    assert ROBOTARIUM["max_wheel_velocity"] == pytest.approx(
        ROBOTARIUM["max_linear_velocity"] / g["wheel_radius"], abs=1e-9)
    # max_angular_velocity = 2 (wheel_radius / robot_diameter) (max_linear / wheel_radius)
    assert ROBOTARIUM["max_angular_velocity"] == pytest.approx(
        2 * (g["wheel_radius"] / (2 * g["radius"]))
        * (ROBOTARIUM["max_linear_velocity"] / g["wheel_radius"]), abs=1e-9)
    assert g["v_max"] == ROBOTARIUM["max_linear_velocity"]
    assert g["w_max"] == ROBOTARIUM["max_angular_velocity"]
    assert g["wheel_speed_max"] == ROBOTARIUM["max_wheel_velocity"]


def test_the_robotarium_arena_and_collision_disc() -> None:
    x_min, y_min, width, height = ROBOTARIUM["boundaries"]
    assert (x_min, y_min) == (-width / 2, -height / 2)  # the arena is centred on the origin
    assert width > 0 and height > 0
    # the collision disc is larger than the robot, and its offset keeps the pose inside it
    diameter = ROBOTARIUM["collision_diameter"]
    assert diameter > 2 * PROFILES["gritsbot"]["robots"]["radius"]
    assert 0 < ROBOTARIUM["collision_offset"] < diameter / 2
    assert 0 < ROBOTARIUM["time_step"] < 0.1
