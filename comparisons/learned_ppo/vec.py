"""SB3 ``VecEnv`` glue for the training: body-frame actions, batches as one, shaping."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from gymnasium.spaces import Box
from numpy.typing import NDArray
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices, VecEnvWrapper


class Concat(VecEnv):
    """Several VecEnvs (e.g. one per scenario) with one observation and action space, in a row.

    Args:
        parts: The VecEnvs; their environments are numbered part after part.
        seed: The base seed every part gets from :meth:`seed`, whatever seed
            SB3 passes (the training's seed sets the network and the action
            noise, not the worlds: those stay on the training seeds).
    """

    def __init__(self, parts: Sequence[VecEnv], seed: int) -> None:
        self.parts = list(parts)
        self.base_seed = int(seed)
        first = self.parts[0]
        for p in self.parts[1:]:
            if p.observation_space != first.observation_space:
                raise ValueError("every part needs the same observation space")
            if p.action_space != first.action_space:
                raise ValueError("every part needs the same action Box")
        self._cuts = np.cumsum([0] + [p.num_envs for p in self.parts])
        super().__init__(int(self._cuts[-1]), first.observation_space, first.action_space)

    def seed(self, seed: int | None = None) -> list[int | None]:
        """Seed every part with :attr:`base_seed` (``seed`` is not used; class docstring)."""
        return [s for p in self.parts for s in p.seed(self.base_seed)]

    def reset(self) -> NDArray[np.float64]:
        """Reset every part; their observations in a row."""
        obs = [p.reset() for p in self.parts]
        self.reset_infos = [i for p in self.parts for i in p.reset_infos]
        return np.concatenate(obs)

    def step_async(self, actions: np.ndarray) -> None:
        """Hand each part its rows of ``actions``."""
        for k, p in enumerate(self.parts):
            p.step_async(actions[self._cuts[k]:self._cuts[k + 1]])

    def step_wait(self) -> tuple[Any, ...]:
        """Every part's step, in a row."""
        got = [p.step_wait() for p in self.parts]
        return (np.concatenate([g[0] for g in got]), np.concatenate([g[1] for g in got]),
                np.concatenate([g[2] for g in got]), [i for g in got for i in g[3]])

    def close(self) -> None:
        """Close every part."""
        for p in self.parts:
            p.close()

    def _split(self, indices: VecEnvIndices) -> list[tuple[VecEnv, list[int]]]:
        idx = list(self._get_indices(indices))
        out = []
        for k, p in enumerate(self.parts):
            lo, hi = self._cuts[k], self._cuts[k + 1]
            mine = [i - lo for i in idx if lo <= i < hi]
            if mine:
                out.append((p, mine))
        return out

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """Each part's attribute for its indices."""
        return [v for p, i in self._split(indices) for v in p.get_attr(attr_name, i)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Set the attribute in each part."""
        for p, i in self._split(indices):
            p.set_attr(attr_name, value, i)

    def env_method(self, method_name: str, *args: Any, indices: VecEnvIndices = None,
                   **kwargs: Any) -> list[Any]:
        """Call the method in each part."""
        return [v for p, i in self._split(indices)
                for v in p.env_method(method_name, *args, indices=i, **kwargs)]

    def env_is_wrapped(self, wrapper_class: type, indices: VecEnvIndices = None) -> list[bool]:
        """Ask each part."""
        return [v for p, i in self._split(indices) for v in p.env_is_wrapped(wrapper_class, i)]


class Shaping(VecEnvWrapper):
    """Training-only shaping of each robot's reward, from the observation the step produced.

    Each robot's reward gets two terms, per step (for an episode that ended,
    read from its ``terminal_observation``):

    - ``- slot * e * dt``: ``e`` (m) the robot's own distance to its slot (the
      ``slot`` block times ``range``), credit the team's formation errors
      do not give one robot;
    - ``- clearance * max(0, 1 - (d - radius) / margin)``: ``d`` (m) the
      nearest of its LiDAR beams (walls, obstacles, moving discs, other
      robots); 0 beyond ``radius + margin``, ``clearance`` at contact.

    Args:
        venv: The environment (its observations are ``SPEC``'s vectors).
        blocks: The observation's block slices (``ObservationSpec.layout()``).
        scale: The ``range`` of the slot block, m.
        range_max: ``(num_envs,)`` each environment's LiDAR range, m (the lidar block's scale).
        radius: The robots' radius, m.
        dt: The step, s.
        slot: Weight of the slot distance, 1/(m s).
        clearance: The penalty at contact, per step.
        margin: Distance beyond contact where the clearance penalty starts, m.
    """

    def __init__(self, venv: VecEnv, blocks: dict[str, slice], scale: float,
                 range_max: NDArray[np.float64], radius: float, dt: float, *, slot: float,
                 clearance: float, margin: float) -> None:
        super().__init__(venv)
        self.blocks, self.scale = blocks, float(scale)
        self.range_max = np.asarray(range_max, dtype=np.float64)
        self.radius, self.dt = float(radius), float(dt)
        self.slot, self.clearance, self.margin = float(slot), float(clearance), float(margin)

    def penalty(self, obs: NDArray[np.float64]) -> NDArray[np.float64]:
        """``(num_envs,)`` each robot's shaping penalty (>= 0) for its observation."""
        e = np.linalg.norm(obs[:, self.blocks["slot"]], axis=1) * self.scale
        d = obs[:, self.blocks["lidar"]].min(axis=1) * self.range_max
        near = np.clip(1.0 - (d - self.radius) / self.margin, 0.0, 1.0)
        return self.slot * e * self.dt + self.clearance * near

    def step_wait(self) -> tuple[Any, ...]:
        """The wrapped step, each reward less its robot's penalty."""
        obs, reward, done, infos = self.venv.step_wait()
        seen = obs
        if done.any():
            seen = obs.copy()
            for k in np.flatnonzero(done):
                seen[k] = infos[k]["terminal_observation"]
        return obs, reward - self.penalty(seen), done, infos

    def reset(self) -> NDArray[np.float64]:
        """The wrapped reset."""
        return self.venv.reset()


class BodyVelocity(VecEnvWrapper):
    """Actions in ``[-1, 1]^2``: a body-frame velocity (``scale`` m/s per unit) for unicycles.

    What a ``velocity`` controller with ``frame = "body"`` gets at run time:
    the row is rotated into the world by the robot's heading
    (:func:`dfcoa_opt.core.geometry.rotate`, as :class:`~dfcoa_opt.control.policy.PolicyController`
    does) and converted to the robots' ``(v, omega)`` by the simulator's
    near-identity map (:func:`dfcoa_opt.control.adapters.convert`), so the
    exported policy file runs the trained policy exactly.

    Args:
        venv: One :class:`~dfcoa_opt.envs.sb3.FormationSB3VecEnv` (its rows are
            its batch's robots in order).
        scale: m/s per unit of the action.
    """

    def __init__(self, venv: Any, scale: float) -> None:
        super().__init__(venv, action_space=Box(-1.0, 1.0, (2,), dtype=np.float32))
        self.scale = float(scale)
        spec = venv.venv.scenario.spec
        self.kind, self.nid = venv.venv.core.kind, spec.robots.nid_distance

    def step_async(self, actions: np.ndarray) -> None:
        """Rotate, convert and pass on the actions."""
        from dfcoa_opt.control.adapters import convert
        from dfcoa_opt.core.geometry import rotate

        obs = self.venv.venv.toolkit_observation
        y = self.scale * np.clip(np.asarray(actions, dtype=np.float64), -1.0, 1.0)
        cmd = convert(rotate(y, obs.pose[:, 2]), "velocity", self.kind, obs.pose,
                      obs.velocity, obs.dt, self.nid)
        self.venv.step_async(cmd)

    def step_wait(self) -> tuple[Any, ...]:
        """The wrapped step."""
        return self.venv.step_wait()

    def reset(self) -> NDArray[np.float64]:
        """The wrapped reset."""
        return self.venv.reset()
