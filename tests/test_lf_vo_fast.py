"""``lf_vo``'s one-pass clearance (per-column horizons) and its numba choice of the sample.

Oracles: two calls of the numpy reference
(``min(path_clearance(pts, far), path_clearance(pts[:, :, :h_r], near))``) and of
the kernel itself with one horizon each; ``argmin``/``argmax`` over
:func:`comparisons.lf_vo.equations.vo_cost` for :func:`vo_choose`.
"""

import numpy as np
import pytest

from comparisons.lf_vo.equations import path_clearance, rollout, vo_cost
from comparisons.lf_vo.kernel import vo_choose, vo_clearance
from tests.test_lf_vo import random_world

NV, NW, H = 11, 21, 30  # speed and turn-rate samples, prediction steps


def samples(rng, n):
    """A speed-major grid per robot plus one preferred command: ``(N, NV * NW + 1)``."""
    v_max = rng.uniform(0.2, 0.7, n)
    v = np.repeat(v_max[:, None] * np.linspace(0.0, 1.0, NV), NW, axis=1)
    w = np.tile(np.linspace(-1.0, 1.0, NW), (n, NV))
    v_ref, w_ref = rng.uniform(0.0, 0.5, n), rng.uniform(-1.0, 1.0, n)
    w_ref[:5] = w[0, 3]  # a preferred turn rate that is also on the grid
    return np.column_stack((v, v_ref)), np.column_stack((w, w_ref)), v_ref, w_ref


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_one_pass_with_per_column_horizons_equals_two_passes(seed):
    rng = np.random.default_rng(seed)
    n, h_r = 120, 12
    pose, circles, circle_reach, pos, vel, reach, mask = random_world(rng, n)
    v, w, _, _ = samples(rng, n)
    q = pos.shape[1]
    far_cols, near_cols = slice(0, q // 2), slice(q // 2, q)  # humans, robots
    limit = np.r_[np.full(q // 2, H), np.full(q - q // 2, h_r)]
    fast = vo_clearance(pose, v, w, 0.1, H, 1.0, pos, vel, reach, mask, circles, circle_reach,
                        w_stride=NW, limit=limit)
    # the kernel with one horizon per call: the same minima, bit for bit
    far = vo_clearance(pose, v, w, 0.1, H, 1.0, pos[:, far_cols], vel[:, far_cols],
                       reach[:, far_cols], mask[:, far_cols], circles, circle_reach,
                       w_stride=NW)
    near = vo_clearance(pose, v, w, 0.1, h_r, 1.0, pos[:, near_cols], vel[:, near_cols],
                        reach[:, near_cols], mask[:, near_cols], w_stride=NW)
    np.testing.assert_array_equal(fast, np.minimum(far, near))
    # the numpy reference: the near columns over the first h_r steps of the same rollout
    pts = rollout(pose, v, w, 0.1, H, 1.0)
    ref_far = path_clearance(
        pts, 0.1, np.concatenate((np.broadcast_to(circles, (n, len(circles), 2)),
                                  pos[:, far_cols]), 1),
        np.concatenate((np.zeros((n, len(circles), 2)), vel[:, far_cols]), 1),
        np.concatenate((np.broadcast_to(circle_reach, (n, len(circles))), reach[:, far_cols]), 1),
        np.concatenate((np.ones((n, len(circles)), dtype=bool), mask[:, far_cols]), 1))
    ref_near = path_clearance(pts[:, :, :h_r], 0.1, pos[:, near_cols], vel[:, near_cols],
                              reach[:, near_cols], mask[:, near_cols])
    ref = np.minimum(ref_far, ref_near)
    assert (ref_near < ref_far).any() and (ref_far < ref_near).any()  # both kinds matter
    np.testing.assert_allclose(fast, ref, rtol=0.0, atol=1e-12)
    # limits are clipped to 0..steps; a column with limit 0 is never checked
    np.testing.assert_array_equal(
        vo_clearance(pose, v, w, 0.1, H, 1.0, pos, vel, reach, mask, w_stride=NW,
                     limit=np.where(np.arange(q) < q // 2, 10 * H, 0)),
        vo_clearance(pose, v, w, 0.1, H, 1.0, pos[:, far_cols], vel[:, far_cols],
                     reach[:, far_cols], mask[:, far_cols], w_stride=NW))


def reference_choice(theta, v, w, v_ref, w_ref, theta_t, clear, weights):
    """``lf_vo``'s numpy reference: argmin of the safe costs, else argmax of the clearance."""
    cost = vo_cost(theta, v, w, v_ref, w_ref, theta_t, *weights)
    safe = clear >= 0.0
    fell = ~safe.any(axis=1)
    best = np.where(fell, np.argmax(clear, axis=1),
                    np.argmin(np.where(safe, cost, np.inf), axis=1))
    return best, fell


@pytest.mark.parametrize("weights", [(1.0, 1.0, 1.0, 0.01), (1.0, 2.0, 0.5, 0.0),
                                     (0.5, 0.0, 1.0, 0.0)])
def test_vo_choose_is_the_numpy_choice(weights):
    rng = np.random.default_rng(4)
    n = 200
    theta, theta_t = rng.uniform(-4.0, 4.0, n), rng.uniform(-np.pi, np.pi, n)
    v, w, v_ref, w_ref = samples(rng, n)
    clear = rng.normal(0.2, 0.5, v.shape)
    clear[:20] = -np.abs(clear[:20]) - 0.01  # no safe sample: fall back
    clear[20:25, :-1], clear[20:25, -1] = -1.0, 0.0  # only the preferred command is safe
    clear[25:30] = np.inf  # no obstacle at all
    clear[30:35] = np.round(clear[30:35], 1)  # ties of the largest clearance
    best, fell = reference_choice(theta, v, w, v_ref, w_ref, theta_t, clear, weights)
    assert fell[:20].all() and not fell[20:].any()
    for stride in (NW, 0, 5):  # the trigonometry reuse is only a speed-up
        got = vo_choose(theta, v, w, v_ref, w_ref, theta_t, clear, *weights, w_stride=stride)
        np.testing.assert_array_equal(got[0], best)
        np.testing.assert_array_equal(got[1], fell)
    with pytest.raises(ValueError, match="S >= 1"):
        vo_choose(theta, np.zeros((n, 0)), np.zeros((n, 0)), v_ref, w_ref, theta_t,
                  np.zeros((n, 0)), *weights)
