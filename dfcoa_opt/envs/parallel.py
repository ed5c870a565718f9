"""PettingZoo ``ParallelEnv``: one run of a scenario, one agent per robot.

``parallel_env(scenario, seed)`` steps one run through the batched simulator's
:class:`~dfcoa_opt.sim.stepper.Stepper` (a batch of one): the agents
``robot_0 .. robot_{N-1}`` observe their own
:func:`~dfcoa_opt.control.features.flatten` vector and act with the robot
model's command; every agent gets the team's reward
(:mod:`dfcoa_opt.envs.rewards`), and the episode ends for all agents at once.
Layout, reward, ends and seeds: ``docs/envs.md``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from gymnasium.spaces import Box
from numpy.typing import NDArray
from pettingzoo import ParallelEnv

from dfcoa_opt.control.base import Observation
from dfcoa_opt.control.features import ObservationSpec
from dfcoa_opt.core.errors import DfcoaError
from dfcoa_opt.envs.core import OUTCOME_CODES, TeamBatch
from dfcoa_opt.envs.rewards import RewardSpec
from dfcoa_opt.scenario.scenario import Scenario
from dfcoa_opt.sim.log import RunLog

FloatArray = NDArray[np.float64]


class FormationParallelEnv(ParallelEnv[str, FloatArray, FloatArray]):
    """A formation run as a PettingZoo parallel environment (module docstring).

    Args:
        scenario: A loaded scenario or a scenario file.
        seed: The seed of the first episode when :meth:`reset` gets none.
        reward: The reward's weights (default :class:`RewardSpec`).
        observation: The observation's layout and scales (default :class:`ObservationSpec`).
        stop_on_deadlock: End a stalled run as a deadlock (terminated).
        **overrides: Scenario keys, ``__`` for the dot (``t_max=20.0``,
            ``leader__speed=0.4``).

    Attributes:
        scenario: The scenario the episodes run (with the episode-end settings).
        episode_seed: The current episode's seed (None before the first reset).
    """

    metadata: dict[str, Any] = {"name": "dfcoa_formation_v0", "render_modes": [],
                                "is_parallelizable": True}
    render_mode: str | None = None

    def __init__(self, scenario: Scenario | str | Path, seed: int = 0, *,
                 reward: RewardSpec | None = None, observation: ObservationSpec | None = None,
                 stop_on_deadlock: bool = True, **overrides: Any) -> None:
        self.core = TeamBatch(scenario, reward=reward, observation=observation,
                              stop_on_deadlock=stop_on_deadlock, overrides=overrides)
        core = self.core
        self.scenario = core.scenario
        self.possible_agents = [f"robot_{i}" for i in range(core.n)]
        self.agents: list[str] = []
        self.observation_spaces = {a: Box(core.obs_low, core.obs_high, dtype=np.float64)
                                   for a in self.possible_agents}
        self.action_spaces = {a: Box(core.action_low, core.action_high, dtype=np.float64)
                              for a in self.possible_agents}
        #: The global state (:meth:`state`): every robot's observation, robot after robot.
        self.state_space = Box(np.tile(core.obs_low, core.n), np.tile(core.obs_high, core.n),
                               dtype=np.float64)
        self._next_seed = int(seed)
        self.episode_seed: int | None = None
        self._obs = np.zeros((core.n, core.size))

    def observation_space(self, agent: str) -> Box:
        """The Box of one robot's observation vector (the same object every call)."""
        return self.observation_spaces[agent]

    def action_space(self, agent: str) -> Box:
        """The Box of one robot's command (the same object every call)."""
        return self.action_spaces[agent]

    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None,
              ) -> tuple[dict[str, FloatArray], dict[str, dict[str, Any]]]:
        """Start an episode: the run of ``seed``, else of the seed after the last episode's.

        Args:
            seed: The run's seed (>= 0), as in :func:`dfcoa_opt.run`. None: the
                constructor's seed at the first reset, then one more than the
                last episode's.
            options: Ignored.

        Returns:
            Every agent's observation ``(D,)`` and info: ``seed``, ``t`` (0.0 s)
            and ``outcome`` (0, :data:`~dfcoa_opt.envs.core.OUTCOME_CODES`):
            the keys of every step's infos.
        """
        if seed is not None:
            self._next_seed = int(seed)
        self.episode_seed = self._next_seed
        self._next_seed += 1
        self.core.start([self.episode_seed])
        self._obs = self.core.observe()[1][0]
        self.agents = list(self.possible_agents)
        info = self._info(0.0, 0)
        return ({a: self._obs[i] for i, a in enumerate(self.agents)},
                {a: dict(info) for a in self.agents})

    def step(self, actions: dict[str, Any]) -> tuple[
            dict[str, FloatArray], dict[str, float], dict[str, bool], dict[str, bool],
            dict[str, dict[str, Any]]]:
        """Apply every robot's action for one step ``dt``.

        Args:
            actions: One ``(2,)`` action per agent (all of them).

        Returns:
            Observations, rewards (the team's, for every agent), terminations,
            truncations and infos: ``seed``, ``t`` (s, the scored instant) and
            ``outcome``, the episode's outcome code
            (:data:`~dfcoa_opt.envs.core.OUTCOME_CODES`; 0 until the last step).
            After the last step ``agents`` is empty.

        Raises:
            DfcoaError: No episode is running (call :meth:`reset`).
            ValueError: An agent without an action, a wrong shape, NaN or inf.
        """
        if not self.agents:
            raise DfcoaError("no episode is running: call reset()")
        missing = [a for a in self.agents if a not in actions]
        if missing:
            raise ValueError(f"no action for agent(s) {missing}")
        act = np.array([np.asarray(actions[a], dtype=np.float64) for a in self.agents])
        if act.shape != (self.core.n, 2):
            raise ValueError(f"actions have shape {act.shape[1:]} per agent, expected (2,)")
        t = self.core.time(0)
        res = self.core.step(act[None])
        agents = self.agents
        info = self._info(t, OUTCOME_CODES[res.outcomes.get(0, "running")])
        if 0 in res.outcomes:
            obs = self._obs.copy()  # the last instant's: the episode ended there
            self.agents = []
        else:
            obs = self._obs = self.core.observe()[1][0]
        reward, term, trunc = float(res.reward[0]), bool(res.terminated[0]), bool(res.truncated[0])
        return ({a: obs[i] for i, a in enumerate(agents)}, dict.fromkeys(agents, reward),
                dict.fromkeys(agents, term), dict.fromkeys(agents, trunc),
                {a: dict(info) for a in agents})

    def _info(self, t: float, outcome: int) -> dict[str, Any]:
        """One agent's info: the same keys, all numbers, at the reset and at every step."""
        return {"seed": self.episode_seed, "t": t, "outcome": outcome}

    def state(self) -> FloatArray:
        """The global state: every robot's observation, robot after robot, ``(N * D,)``."""
        return self._obs.reshape(-1).copy()

    @property
    def toolkit_observation(self) -> Observation | None:
        """The :class:`Observation` behind the current observations (None after the end).

        What a controller's ``act`` takes: an expert (e.g. ``goto_slot``) can act
        through the environment with it.
        """
        return self.core.observation

    def episode_log(self) -> RunLog:
        """The finished episode's log (:meth:`TeamBatch.episode_log`), until the next reset."""
        return self.core.episode_log(0)

    def render(self) -> None:
        """No rendering: plot an episode's log (:meth:`episode_log`) with :mod:`dfcoa_opt.viz`."""
        return None

    def close(self) -> None:
        """Nothing to release."""


def parallel_env(scenario: Scenario | str | Path, seed: int = 0,
                 **options: Any) -> FormationParallelEnv:
    """A PettingZoo ``ParallelEnv`` of ``scenario``: one agent per robot (``robot_0`` ...).

    Args:
        scenario: A loaded scenario or a scenario file.
        seed: The first episode's seed when ``reset`` gets none.
        **options: ``reward`` (:class:`RewardSpec`), ``observation``
            (:class:`ObservationSpec`), ``stop_on_deadlock`` (bool, default
            True), and scenario keys (``t_max=20.0``, ``leader__speed=0.4``).

    Returns:
        The environment (``reset`` it first).

    Example:
        >>> from dfcoa_opt.envs import parallel_env
        >>> env = parallel_env("scenarios/example_empty.toml", t_max=5.0)
        >>> obs, infos = env.reset(seed=1)
        >>> sorted(obs)[:2], obs["robot_0"].shape
        (['robot_0', 'robot_1'], (56,))
    """
    return FormationParallelEnv(scenario, seed, **options)
