"""Stable-Baselines3 ``VecEnv``: every robot of E teams as one SB3 environment, one batch.

``sb3_vec_env(scenario, num_envs=E, seed=s)`` wraps one
:class:`~dfcoa_opt.envs.vector.FormationVectorEnv` (E teams of N robots, one
batched Stepper, ``SAME_STEP`` autoreset) as an SB3 ``VecEnv`` of ``E * N``
environments: SB3 environment ``k`` is robot ``k % N`` of team ``k // N``. A
policy SB3 trains on it is shared by every robot (parameter sharing): each
robot's observation is its own ``(D,)`` vector, its action its own ``(2,)``
command, its reward the team's. The robots of one team end together, so
their ``dones`` are equal; SB3's usual contract holds: the observation after
a done is the next episode's first, the ended one's last is the info's
``terminal_observation``, and ``TimeLimit.truncated`` marks a timeout.

Seeds are the vector environment's: after :meth:`FormationSB3VecEnv.seed`
``(s)`` and a reset, team ``i``'s episode ``j`` is the run of seed
``s + i + j * E``; all distinct, so no two teams replay one episode.
``PPO(..., seed=s)`` calls ``seed(s)``. Docs: ``docs/envs.md``.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium.spaces import Box
from gymnasium.vector import AutoresetMode
from numpy.typing import NDArray
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices

from dfcoa_opt.envs.vector import FormationVectorEnv
from dfcoa_opt.scenario.scenario import Scenario

FloatArray = NDArray[np.float64]


class FormationSB3VecEnv(VecEnv):
    """E teams of N robots as ``E * N`` SB3 environments over one batch (module docstring).

    Args:
        scenario: A loaded scenario or a scenario file.
        num_envs: E, the teams (slots of the batch); SB3 sees ``E * N`` environments.
        seed: The base seed of the first reset when :meth:`seed` was not called.
        **options: What :func:`~dfcoa_opt.envs.vector_env` takes (``reward``,
            ``observation``, ``stop_on_deadlock``, scenario keys), except
            ``autoreset_mode`` (always ``SAME_STEP``, SB3's contract).

    Attributes:
        venv: The gymnasium vector environment of the E teams.
        robots: N, the robots of a team.
    """

    def __init__(self, scenario: Scenario | str | Path, num_envs: int = 1, seed: int = 0,
                 **options: Any) -> None:
        if "autoreset_mode" in options:
            raise ValueError("sb3_vec_env resets ended teams in the same step (SB3's contract); "
                             "autoreset_mode is not an option")
        self.venv = FormationVectorEnv(scenario, num_envs, seed,
                                       autoreset_mode=AutoresetMode.SAME_STEP, **options)
        core = self.venv.core
        self.robots, self.teams = core.n, self.venv.num_envs
        self._pending: int | None = None
        self._actions = np.zeros((self.teams, self.robots, 2))
        super().__init__(self.teams * self.robots,
                         Box(core.obs_low, core.obs_high, dtype=np.float64),
                         Box(core.action_low, core.action_high, dtype=np.float64))

    # ------------------------------------------------------------------ seeds
    def seed(self, seed: int | None = None) -> Sequence[int | None]:
        """Set the base seed ``s`` of the next :meth:`reset`.

        Team ``i``'s episode ``j`` is then the run of seed ``s + i + j * E``.

        Args:
            seed: The base seed (>= 0). None keeps the current schedule (the
                constructor's seed before the first reset, then each team's
                next episode), so a run without a seed is still reproducible.

        Returns:
            Each SB3 environment's episode seed (a team's robots share it): the
            next reset's with a seed, else the current episodes'.
        """
        if seed is None:
            return np.repeat(self.venv.episode_seeds(), self.robots).tolist()
        self._pending = int(seed)
        return [self._pending + k // self.robots for k in range(self.num_envs)]

    def episode_seeds(self) -> NDArray[np.int64]:
        """``(E,)`` the seed of each team's current episode (``s + i + j E``)."""
        return self.venv.episode_seeds()

    # ------------------------------------------------------------------ VecEnv API
    def reset(self) -> FloatArray:
        """Start a new episode in every team: observations ``(E * N, D)``.

        The seed set by :meth:`seed`, else every team's next episode (the
        constructor's seed the first time). ``reset_infos`` holds each robot's
        info (``seed``, ``t``, ``outcome``).
        """
        obs, infos = self.venv.reset(seed=self._pending)
        self._pending = None
        self.reset_infos = self._robot_infos(infos)
        return obs.reshape(self.num_envs, -1)

    def step_async(self, actions: np.ndarray) -> None:
        """Store the actions ``(E * N, 2)`` (one per robot) for :meth:`step_wait`."""
        act = np.asarray(actions, dtype=np.float64)
        if act.shape != (self.num_envs, 2):
            raise ValueError(f"actions have shape {act.shape}, expected ({self.num_envs}, 2)")
        self._actions = act.reshape(self.teams, self.robots, 2)

    def step_wait(self) -> tuple[FloatArray, FloatArray, NDArray[np.bool_],
                                 list[dict[str, Any]]]:
        """Step every team once: observations, rewards, dones and infos per robot.

        Returns:
            Observations ``(E * N, D)``, rewards ``(E * N,)`` (the team's, for
            each of its robots), dones ``(E * N,)`` and one info per robot:
            ``seed``, ``t`` s and ``outcome`` (the code of
            :data:`~dfcoa_opt.envs.core.OUTCOME_CODES`) of the current
            episode; where a team's episode ended, those of the ended episode,
            with ``terminal_observation`` and ``TimeLimit.truncated``.
        """
        obs, reward, term, trunc, infos = self.venv.step(self._actions)
        done = term | trunc
        robot_infos = self._robot_infos(infos)
        if done.any():
            final, last = infos["final_info"], infos["final_obs"]
            for e in np.flatnonzero(done):
                for i in range(self.robots):
                    k = e * self.robots + i
                    robot_infos[k] = {"seed": int(final["seed"][e]), "t": float(final["t"][e]),
                                      "outcome": int(final["outcome"][e]),
                                      "terminal_observation": last[e][i],
                                      "TimeLimit.truncated": bool(trunc[e] and not term[e])}
        n = self.robots
        return (obs.reshape(self.num_envs, -1), np.repeat(reward, n), np.repeat(done, n),
                robot_infos)

    def _robot_infos(self, infos: dict[str, Any]) -> list[dict[str, Any]]:
        """One info dict per robot from the vector environment's ``(E,)`` arrays."""
        seed, t, outcome = (infos[k].tolist() for k in ("seed", "t", "outcome"))
        return [{"seed": seed[e], "t": t[e], "outcome": outcome[e]}
                for e in range(self.teams) for _ in range(self.robots)]

    def close(self) -> None:
        """Drop the batch."""
        self.venv.close()

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """The vector environment's attribute, once per SB3 environment of ``indices``."""
        value = getattr(self.venv, attr_name)
        return [value for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Set an attribute of the vector environment (shared by every robot: all indices)."""
        if len(list(self._get_indices(indices))) != self.num_envs:
            raise ValueError("the robots share one vector environment: set_attr takes all of them")
        setattr(self.venv, attr_name, value)

    def env_method(self, method_name: str, *method_args: Any, indices: VecEnvIndices = None,
                   **method_kwargs: Any) -> list[Any]:
        """Call a method of the vector environment once; its result for every index."""
        value = getattr(self.venv, method_name)(*method_args, **method_kwargs)
        return [value for _ in self._get_indices(indices)]

    def env_is_wrapped(self, wrapper_class: type, indices: VecEnvIndices = None) -> list[bool]:
        """No gymnasium wrapper sits under this VecEnv: False for every index."""
        return [False for _ in self._get_indices(indices)]


def sb3_vec_env(scenario: Scenario | str | Path, num_envs: int = 1, seed: int = 0,
                **options: Any) -> FormationSB3VecEnv:
    """A Stable-Baselines3 ``VecEnv``: every robot of ``num_envs`` teams, one batched Stepper.

    Args:
        scenario: A loaded scenario or a scenario file.
        num_envs: E, the teams; SB3 sees ``E * N`` environments (one per robot).
        seed: The base seed of the first reset unless :meth:`~FormationSB3VecEnv.seed`
            sets one (``PPO(..., seed=s)`` does).
        **options: ``reward`` (:class:`~dfcoa_opt.envs.RewardSpec`), ``observation``,
            ``stop_on_deadlock`` and scenario keys (``t_max=20.0``).

    Returns:
        The environment; wrap it in SB3's ``VecMonitor`` for episode statistics.

    Example:
        >>> from dfcoa_opt.envs import sb3_vec_env
        >>> env = sb3_vec_env("scenarios/example_empty.toml", num_envs=8, t_max=5.0)
        >>> env.num_envs, env.reset().shape
        (32, (32, 56))
    """
    return FormationSB3VecEnv(scenario, num_envs, seed, **options)
