"""Shared test helpers."""

from __future__ import annotations

import numpy as np

from dfcoa_opt.control.base import Observation


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
