"""Shared test helpers."""

from __future__ import annotations

import numpy as np

from dfcoa_opt.control.base import Neighbours, Observation


def assert_distributed(controller, obs: Observation) -> None:
    """Row i of ``act(obs)`` must equal ``act(obs.take([i]))``: it uses robot i's row only.

    Works for stateless controllers; stateful ones must be reset between calls.
    """
    full = np.asarray(controller.act(obs))
    for i in range(obs.n):
        alone = np.asarray(controller.act(obs.take([i])))
        assert alone.shape == (1, full.shape[1])
        np.testing.assert_array_equal(alone[0], full[i], err_msg=f"row {i} depends on other rows")


class Capture:
    """A controller wrapper that records every observation it is given."""

    def __init__(self, inner):
        self.inner, self.obs = inner, []
        self.command, self.name = inner.command, getattr(inner, "name", "capture")

    def reset(self, scenario, rng):
        self.inner.reset(scenario, rng)

    def act(self, obs):
        self.obs.append(obs)
        return self.inner.act(obs)


def neighbours_from_lists(pos, vel, lists, k: int | None = None) -> Neighbours:
    """A hand-made neighbour table: ``lists[i]`` = robot i's neighbour indices (rows of pos).

    Args:
        pos: ``(N, 2)`` robot positions, m.
        vel: ``(N, 2)`` robot velocities, m/s.
        lists: Per robot, the indices of its neighbours.
        k: Table width; default the longest list (at least 1).
    """
    pos, vel = np.asarray(pos, dtype=float), np.asarray(vel, dtype=float)
    n = len(pos)
    k = k or max(1, max((len(js) for js in lists), default=0))
    idx = -np.ones((n, k), np.intp)
    for i, js in enumerate(lists):
        idx[i, :len(js)] = js
    pad = idx < 0
    safe = np.where(pad, 0, idx)
    return Neighbours(idx, np.where(pad[..., None], 0.0, pos[safe]),
                      np.where(pad[..., None], 0.0, vel[safe]),
                      np.where(pad, np.inf, np.linalg.norm(pos[safe] - pos[:, None], axis=-1)))
