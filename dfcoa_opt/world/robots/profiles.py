"""Robot profiles: published vendor specifications of four differential-drive robots.

A profile fills the ``[robots]`` keys and the ``[sensors.lidar]`` keys of a scenario with the
values of one real robot; keys the scenario gives explicitly override the profile. The data
here are plain numbers: every value, its source and, where a value is derived rather than
read, the reasoning behind it are in ``docs/robots.md``. The short comments below name the
source of each value.

Attributes:
    PROFILES: Profile name -> ``{"robots": {...}, "lidar": {...}}``. The ``robots`` keys are
        ``radius`` (m, collision disc), ``wheel_radius`` (m), ``track_width`` (m, distance
        between the wheel contact centres), ``wheel_speed_max`` (rad/s), ``v_max`` (m/s),
        ``w_max`` (rad/s), ``wheel_accel_max`` (m/s^2, rim acceleration of each wheel) and
        ``motor_time_constant`` (s, first-order lag of a wheel's speed). The ``lidar`` keys are
        ``beams`` (per scan), ``fov`` (rad), ``range_min`` and ``range_max`` (m),
        ``noise_std`` (m, one standard deviation of the range) and ``rate`` (Hz). The GRITSbot
        carries no LiDAR: its ``lidar`` entry is empty.
    ROBOTARIUM: Constants of the Robotarium testbed (Georgia Tech) that a run of GRITSbots must
        respect: ``boundaries`` (x_min, y_min, width, height) in m, ``collision_diameter`` in
        m, ``collision_offset`` in m (the Robotarium places each robot's collision disc this
        far ahead of its pose), ``max_linear_velocity`` in m/s, ``max_wheel_velocity`` and
        ``max_angular_velocity`` in rad/s, and the control period ``time_step`` in s.
"""

from __future__ import annotations

PROFILES: dict[str, dict[str, dict[str, float | int]]] = {
    "turtlebot3_burger": {
        "robots": {
            "radius": 0.105,  # ROBOT_RADIUS, ROBOTIS OpenCR firmware (published robot radius)
            "wheel_radius": 0.033,  # turtlebot3_bringup/param/burger.yaml wheels.radius
            "track_width": 0.160,  # turtlebot3_bringup/param/burger.yaml wheels.separation
            "wheel_speed_max": 6.387905062299246,  # 61 rpm: XL430-W250 at 12 V, firmware
            "v_max": 0.22,  # ROBOTIS e-manual, TurtleBot3 specifications
            "w_max": 2.84,  # ROBOTIS e-manual (above 2*v/d and the 61 rpm bound: see docs)
            "wheel_accel_max": 2.5,  # turtlebot3_navigation2 velocity_smoother max_accel
            "motor_time_constant": 0.05,  # estimate (docs/robots.md, Reasoning)
        },
        "lidar": {  # LDS-01 (e-manual specification table), vendor data sheet
            "beams": 360,  # 1 deg angular resolution
            "fov": 6.283185307179586,  # 360 deg
            "range_min": 0.12,
            "range_max": 3.5,
            "noise_std": 0.01,  # precision +/-10 mm taken as 1 sigma; ROBOTIS Gazebo model
            "rate": 5.0,  # 300 rpm
        },
    },
    "turtlebot3_waffle_pi": {
        "robots": {
            "radius": 0.220,  # ROBOT_RADIUS, ROBOTIS OpenCR firmware (published robot radius)
            "wheel_radius": 0.033,  # turtlebot3_bringup/param/waffle_pi.yaml wheels.radius
            "track_width": 0.287,  # turtlebot3_bringup/param/waffle_pi.yaml wheels.separation
            "wheel_speed_max": 8.063421144213802,  # 77 rpm: XM430-W210 at 12 V, firmware
            "v_max": 0.26,  # ROBOTIS e-manual, TurtleBot3 specifications
            "w_max": 1.82,  # ROBOTIS e-manual
            "wheel_accel_max": 2.5,  # turtlebot3_navigation2 velocity_smoother max_accel
            "motor_time_constant": 0.05,  # estimate (docs/robots.md, Reasoning)
        },
        "lidar": {  # LDS-01 (e-manual specification table), vendor data sheet
            "beams": 360,
            "fov": 6.283185307179586,
            "range_min": 0.12,
            "range_max": 3.5,
            "noise_std": 0.01,
            "rate": 5.0,
        },
    },
    "jackal": {
        "robots": {
            "radius": 0.3328,  # half the diagonal of 508 mm x 430 mm (Clearpath user manual)
            "wheel_radius": 0.098,  # jackal_description URDF, clearpath_control j100
            "track_width": 0.37559,  # jackal_description URDF "track" (geometric)
            "wheel_speed_max": 20.408163265306122,  # v_max / wheel_radius (no motor rpm)
            "v_max": 2.0,  # Clearpath Jackal user manual, System Specifications
            "w_max": 4.0,  # jackal_control / clearpath_control angular.z.max_velocity
            "wheel_accel_max": 10.0,  # Clearpath nav2 velocity_smoother max_accel (j100)
            "motor_time_constant": 0.1,  # estimate (docs/robots.md, Reasoning)
        },
        "lidar": {  # SICK LMS111 (LMS1xx), the jackal_description default 2-D LiDAR
            "beams": 541,  # 270 deg at 0.5 deg, both ends included
            "fov": 4.71238898038469,  # 270 deg
            "range_min": 0.5,
            "range_max": 20.0,
            "noise_std": 0.012,  # SICK: statistical error 12 mm (typical), taken as 1 sigma
            "rate": 50.0,  # the Clearpath LMS1xx driver runs the scanner at 50 Hz
        },
    },
    "gritsbot": {
        "robots": {
            "radius": 0.055,  # robot_diameter / 2, Robotarium simulator (robotarium_abc.py)
            "wheel_radius": 0.016,  # wheel_radius, Robotarium simulator
            "track_width": 0.105,  # base_length, Robotarium simulator
            "wheel_speed_max": 12.5,  # max_wheel_velocity = max_linear_velocity / wheel_radius
            "v_max": 0.2,  # max_linear_velocity, Robotarium simulator
            "w_max": 3.6363636363636362,  # max_angular_velocity, Robotarium simulator
            "wheel_accel_max": 6.0606060606060606,  # estimate: v_max / time_step (docs)
            "motor_time_constant": 0.05,  # estimate (docs/robots.md, Reasoning)
        },
        "lidar": {},  # the GRITSbot has no LiDAR
    },
}

ROBOTARIUM: dict[str, float | tuple[float, float, float, float]] = {
    "boundaries": (-1.6, -1.0, 3.2, 2.0),  # lower-left corner, width, height
    "collision_diameter": 0.135,
    "collision_offset": 0.025,
    "max_linear_velocity": 0.2,
    "max_wheel_velocity": 12.5,  # max_linear_velocity / wheel_radius
    "max_angular_velocity": 3.6363636363636362,  # 2 (r / robot_diameter) (v_max / r)
    "time_step": 0.033,
}
