"""DFCOA formation tracking law: the closed loop obeys eq 24 exactly."""

import numpy as np
import pytest

from dfcoa_opt.control.dfcoa.formation_law import (
    formation_errors,
    formation_tracking_law,
    formation_tracking_law_fast,
    pose_error,
    tracking_point_coordinates,
)
from dfcoa_opt.scenario.formation import polar_offsets, rectangle_offsets
from dfcoa_opt.world.robots.models import integrate_unicycle


def _simulate(k1, k2, d, v_l, w_l, t_end, dt=1e-3):
    offsets = rectangle_offsets(2.0, 2.0)
    leader = np.array([1.0, -2.0, 0.4])
    rng = np.random.default_rng(3)
    pose = np.column_stack((leader[:2] + offsets + rng.normal(0, 0.3, (4, 2)),
                            leader[2] + rng.normal(0, 0.3, 4)))
    lead5 = np.array([*leader, v_l, w_l])
    e0 = formation_errors(offsets, pose, lead5, d)
    for _ in range(int(round(t_end / dt))):
        cmd = formation_tracking_law(offsets, pose, lead5, k1, k2, d)
        pose = integrate_unicycle(pose, cmd[:, 0], cmd[:, 1], dt)
        lead5[:3] = integrate_unicycle(lead5[:3], v_l, w_l, dt)
    return e0, formation_errors(offsets, pose, lead5, d)


@pytest.mark.parametrize("v_l, w_l", [(0.3, 0.0), (0.3, 0.25), (0.5, -0.4)])
def test_errors_decay_at_the_designed_rates_with_a_moving_leader(v_l, w_l):
    k1, k2, d, t = 2.8, 0.7, 0.98, 1.5  # Table 3
    e0, e1 = _simulate(k1, k2, d, v_l, w_l, t)
    expect = e0 * np.exp(-np.array([k1, k2]) * t)
    assert np.all(np.abs(e0) > 0.02)
    np.testing.assert_allclose(e1, expect, atol=2e-3 * np.abs(e0).max())


def test_printed_eq_26_27_would_not_decay():
    """The law as printed (sin/cos swapped) does not give eq 24: the fix matters."""
    offsets = rectangle_offsets(2.0, 2.0)
    pose = np.array([[0.5, 0.8, 0.1], [-1.2, 0.7, 0.2], [-0.9, -1.1, -0.1], [1.1, -0.8, 0.0]])
    lead = np.array([0.0, 0.0, 0.0, 0.3, 0.1])
    k1, k2, d = 2.8, 0.7, 0.98
    lxy = tracking_point_coordinates(pose, lead, d)
    e = offsets - lxy
    delta = pose[:, 2] - lead[2]
    a_p = k1 * e[:, 0] + 0.3 + lxy[:, 1] * 0.1
    b_p = -k2 * e[:, 1] - lxy[:, 0] * 0.1
    v_p = a_p * np.sin(delta) - b_p * np.cos(delta)  # eq 26 as printed
    v_ours = formation_tracking_law(offsets, pose, lead, k1, k2, d)[:, 0]
    assert not np.allclose(v_p, v_ours, atol=0.05)


def test_tracking_point_coordinates_eq15():
    pose = np.array([[3.0, 4.0, np.pi / 2]])
    lead = np.array([1.0, 1.0, np.pi / 2])
    # point = (3, 4 + d); relative (2, 3 + d) rotated by -90 deg -> (3 + d, -2)
    np.testing.assert_allclose(tracking_point_coordinates(pose, lead, 0.5), [[3.5, -2.0]],
                               atol=1e-12)


def test_pose_error_algorithm2_matches_slot_geometry():
    d_a, phi_a = np.array([1.5, 2.0]), np.array([0.3, -2.0])
    lead = np.array([2.0, -1.0, 0.7])
    pose = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 0.0]])
    e, p_true = pose_error(lead, d_a, phi_a, pose)
    c, s = np.cos(0.7), np.sin(0.7)
    rot = polar_offsets(d_a, phi_a) @ np.array([[c, s], [-s, c]])
    np.testing.assert_allclose(p_true, lead[:2] + rot, atol=1e-12)
    np.testing.assert_allclose(e, p_true - pose[:, :2], atol=1e-12)


def test_numba_law_has_the_reference_bits():
    """formation_tracking_law_fast (numba) equals formation_tracking_law bit for bit."""
    rng = np.random.default_rng(11)
    n = 5000
    pose = np.column_stack((rng.uniform(-50, 50, (n, 2)), rng.uniform(-20, 20, n)))
    pose[::9, 2] = np.pi * rng.integers(-6, 7, len(pose[::9]))  # delta on the wrap's edges
    offsets = rng.normal(0.0, 2.0, (n, 2))
    offsets[::4, 1] = -0.0
    for lead in (np.array([1.0, -2.0, 0.4, 0.3, 0.25]), np.array([-3.0, 7.0, -9.0, 0.0, -0.6]),
                 np.array([0.0, 0.0, np.pi, 0.5, 0.0, 99.0])):
        for k1, k2, d in ((2.8, 0.7, 0.98), (1.0, 3.0, 0.2)):
            want = formation_tracking_law(offsets, pose, lead, k1, k2, d)
            got = formation_tracking_law_fast(offsets, pose, lead, k1, k2, d)
            np.testing.assert_array_equal(got.view(np.uint64), want.view(np.uint64))
    with pytest.raises(ValueError, match="leader"):
        formation_tracking_law_fast(offsets, pose, [0.0, 0.0, 0.0], 1.0, 1.0, 1.0)
