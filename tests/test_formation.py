import math

import numpy as np

from dfcoa_opt.scenario.formation import (
    formation_offsets,
    grid_offsets,
    line_offsets,
    rectangle_offsets,
    rectangle_polar,
    slot_positions,
    v_offsets,
)
from dfcoa_opt.scenario.schema import FormationSpec


def test_rectangle_eq3():
    w, ln = 1.5, 2.0
    th, d = rectangle_polar(w, ln)
    assert math.isclose(th, math.atan(w / ln)) and math.isclose(d, w / (2 * math.sin(th)))
    off = rectangle_offsets(w, ln)
    assert np.allclose(sorted(map(tuple, np.round(off, 12))),
                       sorted([(1.0, 0.75), (-1.0, 0.75), (-1.0, -0.75), (1.0, -0.75)]))
    assert np.allclose(off[0], [1.0, 0.75])  # front-left first


def test_v_eq5_6():
    off = v_offsets(5, 1.0, 0.5)
    # paper 002 eq 5-6: x_f = x_l - d cos(theta_l + phi) with theta_l = 0
    assert np.allclose(off[0], 0.0)
    assert np.allclose(off[1], [-math.cos(0.5), math.sin(0.5)])
    assert np.allclose(off[2], [-math.cos(0.5), -math.sin(0.5)])
    assert np.allclose(off[3], 2 * off[1])


def test_line_grid_centred():
    assert np.allclose(line_offsets(3, 2.0).mean(0), 0.0)
    g = grid_offsets(9, 1.0)
    assert np.allclose(g.mean(0), 0.0) and len({tuple(r) for r in g}) == 9


def test_polar_spec_and_slots_rotate_with_leader():
    spec = FormationSpec(shape="polar", offsets=((2.0, 0.0), (1.0, math.pi / 2)))
    off = formation_offsets(spec, 2)
    assert np.allclose(off, [[2.0, 0.0], [0.0, 1.0]])
    s = slot_positions(np.array([1.0, 1.0, math.pi / 2]), off)
    assert np.allclose(s, [[1.0, 3.0], [0.0, 1.0]])
    st = slot_positions(np.array([[0, 0, 0], [1.0, 1.0, math.pi / 2]]), off)
    assert st.shape == (2, 2, 2) and np.allclose(st[1], s)


def test_single_pose_slots_and_slot_velocity_match_the_batched_formulas_bit_for_bit():
    from dfcoa_opt.control.base import slot_velocity

    rng = np.random.default_rng(5)
    offsets = rng.normal(size=(7, 2))
    for _ in range(200):
        lead = np.concatenate((rng.normal(size=2) * 20.0, rng.uniform(-4.0, 4.0, 1),
                               rng.normal(size=2)))
        slots = slot_positions(lead[:3], offsets)
        assert np.array_equal(slots, slot_positions(lead[None, :3], offsets)[0])
        x, y, th, v, w = lead
        rel = slots - np.array([x, y])
        ref = v * np.array([np.cos(th), np.sin(th)]) + w * np.stack((-rel[:, 1], rel[:, 0]), -1)
        assert np.array_equal(slot_velocity(lead, slots), ref)
