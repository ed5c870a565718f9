"""gymnasium ``VectorEnv``: E runs of a scenario as the E slots of one batched Stepper.

Each sub-environment is one team: its observation is ``(N, D)`` (row i =
robot i's :func:`~dfcoa_opt.control.features.flatten` vector), its action
``(N, 2)`` (row i = robot i's command), its reward the team's scalar
(:mod:`dfcoa_opt.envs.rewards`). A step is one ``sense`` and one ``apply`` of
the Stepper for every sub-environment, and Python loops only over the runs
that end. A finished sub-environment starts its next episode in its slot
(:meth:`~dfcoa_opt.sim.stepper.Stepper.restart`) while the others go on:
gymnasium's ``NEXT_STEP`` autoreset (default) or ``SAME_STEP``.

Seeds: after ``reset(seed=s)``, episode ``j`` (0, 1, ...) of sub-environment
``i`` is the run of seed ``s + i + j * E`` -- the run ``dfcoa_opt.run`` gives
for that seed with the same commands, bit for bit. ``reset()`` without a seed
first uses the constructor's seed, later starts every sub-environment's next
episode. Layout, reward, ends: ``docs/envs.md``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from gymnasium.spaces import Box
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space
from numpy.typing import NDArray

from dfcoa_opt.control.base import Observation
from dfcoa_opt.control.features import ObservationSpec
from dfcoa_opt.core.errors import DfcoaError
from dfcoa_opt.envs.core import OUTCOME_CODES, TeamBatch
from dfcoa_opt.envs.rewards import RewardSpec
from dfcoa_opt.scenario.scenario import Scenario
from dfcoa_opt.sim.log import RunLog

FloatArray = NDArray[np.float64]


class FormationVectorEnv(VectorEnv[FloatArray, FloatArray, NDArray[Any]]):
    """E formation runs of one scenario as a gymnasium vector environment (module docstring).

    Args:
        scenario: A loaded scenario or a scenario file.
        num_envs: E, the sub-environments (slots of the batch).
        seed: The base seed when :meth:`reset` gets none the first time.
        autoreset_mode: ``AutoresetMode.NEXT_STEP`` (or ``"NextStep"``) or
            ``SAME_STEP``. (``DISABLED`` is not offered: a partial reset would
            sense the running sub-environments twice, which changes their runs
            when sensing draws random numbers.)
        reward: The reward's weights.
        observation: The observation's layout and scales.
        stop_on_deadlock: End a stalled run as a deadlock (terminated).
        **overrides: Scenario keys, ``__`` for the dot (``t_max=20.0``).

    Attributes:
        scenario: The scenario the episodes run (with the episode-end settings).
    """

    metadata: dict[str, Any] = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}

    def __init__(self, scenario: Scenario | str | Path, num_envs: int, seed: int = 0, *,
                 autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
                 reward: RewardSpec | None = None, observation: ObservationSpec | None = None,
                 stop_on_deadlock: bool = True, **overrides: Any) -> None:
        if int(num_envs) < 1:
            raise ValueError(f"num_envs must be >= 1, got {num_envs}")
        mode = AutoresetMode(autoreset_mode)
        if mode not in (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP):
            raise ValueError(f"autoreset_mode {mode} is not offered: use NEXT_STEP or SAME_STEP")
        self.core = TeamBatch(scenario, reward=reward, observation=observation,
                              stop_on_deadlock=stop_on_deadlock, overrides=overrides)
        core = self.core
        self.scenario = core.scenario
        self.num_envs = int(num_envs)
        self.metadata = {**type(self).metadata, "autoreset_mode": mode}
        self.single_observation_space = Box(np.tile(core.obs_low, (core.n, 1)),
                                            np.tile(core.obs_high, (core.n, 1)),
                                            dtype=np.float64)
        self.single_action_space = Box(np.tile(core.action_low, (core.n, 1)),
                                       np.tile(core.action_high, (core.n, 1)),
                                       dtype=np.float64)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._base = int(seed)
        self._episode = np.zeros(self.num_envs, dtype=np.int64)
        self._started = False
        self._autoreset = np.zeros(self.num_envs, dtype=bool)
        self._obs = np.zeros((self.num_envs, core.n, core.size))

    @property
    def autoreset_mode(self) -> AutoresetMode:
        """``metadata["autoreset_mode"]``, an attribute as on gymnasium's own vector envs.

        torchrl's ``GymWrapper`` reads it (and takes ``SAME_STEP`` only).
        """
        return self.metadata["autoreset_mode"]

    # ------------------------------------------------------------------ seeds
    def episode_seeds(self) -> NDArray[np.int64]:
        """``(E,)`` the seed of each sub-environment's current episode: ``s + i + j E``."""
        return self._base + np.arange(self.num_envs) + self._episode * self.num_envs

    def _infos(self, t: FloatArray, ended: dict[int, str],
               started: NDArray[np.intp]) -> dict[str, Any]:
        """The infos of a reset or a step: the same keys, all numbers, every time.

        Every key has a value for every sub-environment; its ``_key`` mask
        says where the event happened: ``_seed`` an episode started,
        ``_outcome`` an episode ended (``outcome`` is 0 elsewhere), ``_t``
        everywhere.
        """
        outcome = np.zeros(self.num_envs, dtype=np.int64)
        ends = np.zeros(self.num_envs, dtype=bool)
        for e, name in ended.items():
            outcome[e], ends[e] = OUTCOME_CODES[name], True
        starts = np.zeros(self.num_envs, dtype=bool)
        starts[started] = True
        return {"seed": self.episode_seeds(), "_seed": starts, "t": t,
                "_t": np.ones(self.num_envs, dtype=bool), "outcome": outcome, "_outcome": ends}

    # ------------------------------------------------------------------ API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None,
              ) -> tuple[FloatArray, dict[str, Any]]:
        """Start a new episode in every sub-environment.

        Args:
            seed: The base seed ``s`` (>= 0): sub-environment ``i`` runs seed
                ``s + i``, its later episodes ``s + i + j E``. None: the
                constructor's seed the first time, later every
                sub-environment's next episode.
            options: Ignored, except ``reset_mask``, which is refused (see
                ``autoreset_mode``).

        Returns:
            Observations ``(E, N, D)`` and infos: ``seed`` (each episode's
            seed), ``t`` (0.0 s) and ``outcome`` (0), the keys of every step.
        """
        super().reset(seed=seed)
        if options and "reset_mask" in options:
            raise ValueError("reset_mask is not offered: sub-environments reset themselves "
                             f"({self.metadata['autoreset_mode']})")
        if seed is not None:
            self._base, self._episode[:] = int(seed), 0
        elif self._started:
            self._episode += 1
        self._started = True
        self.core.start(self.episode_seeds().tolist())
        if not self.core.restartable:
            raise DfcoaError(f"{self.scenario.source}: localization "
                             f"'{self.scenario.spec.localization.mode}' is batched and cannot "
                             "restart one run alone; use parallel_env or localization 'truth'")
        self._autoreset[:] = False
        self._observe()
        return self._obs.copy(), self._infos(np.zeros(self.num_envs), {},
                                             np.arange(self.num_envs))

    def step(self, actions: Any) -> tuple[FloatArray, FloatArray, NDArray[np.bool_],
                                          NDArray[np.bool_], dict[str, Any]]:
        """Apply one action per robot of every sub-environment for one step ``dt``.

        Args:
            actions: ``(E, N, 2)`` (the :attr:`action_space`'s shape).

        Returns:
            Observations ``(E, N, D)``, rewards ``(E,)``, terminations ``(E,)``,
            truncations ``(E,)`` and infos, numbers for every sub-environment:
            ``outcome`` (the code of :data:`~dfcoa_opt.envs.core.OUTCOME_CODES`,
            0 while running; ``_outcome`` marks the episodes that ended), ``seed``
            (each current episode's; ``_seed`` marks those that started) and
            ``t`` (s, the instant scored; 0 for a new episode); with
            ``SAME_STEP`` also ``final_obs`` and ``final_info`` (the ended
            episodes' infos).

        Raises:
            ValueError: A wrong shape, NaN or inf.
        """
        act = np.asarray(actions, dtype=np.float64)
        want = (self.num_envs, self.core.n, 2)
        if act.shape != want:
            raise ValueError(f"actions have shape {act.shape}, expected {want}")
        t = self.core.stepper.k * self.core.dt
        res = self.core.step(act)
        final: dict[str, Any] = {}
        if self.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP:
            start = np.flatnonzero(self._autoreset)  # ended at the last step: start now
            self._autoreset = res.terminated | res.truncated
        else:
            start = np.flatnonzero(res.terminated | res.truncated)
            if start.size:
                obs = np.full(self.num_envs, None, dtype=object)
                for e in start:
                    obs[e] = self._obs[e].copy()
                mask = np.zeros(self.num_envs, dtype=bool)
                mask[start] = True
                final = {"final_obs": obs, "_final_obs": mask,
                         "final_info": self._infos(t.copy(), res.outcomes, start[:0]),
                         "_final_info": mask.copy()}
        for e in start:
            self._episode[e] += 1
            self.core.restart(int(e), int(self.episode_seeds()[e]))
        t[start] = 0.0
        infos = self._infos(t, {} if final else res.outcomes, start)
        self._observe()
        return self._obs.copy(), res.reward, res.terminated, res.truncated, {**infos, **final}

    def _observe(self) -> None:
        """Sense the running sub-environments; the others keep their last observation."""
        active, flat = self.core.observe()
        if len(active) == self.num_envs:
            self._obs = flat
        elif len(active):
            obs = self._obs.copy()
            obs[active] = flat
            self._obs = obs

    def episode_log(self, env: int) -> RunLog:
        """The log of sub-environment ``env``'s episode that just ended.

        Available from the step that ends it until the sub-environment starts
        its next episode (with ``NEXT_STEP``, the next ``step``; with
        ``SAME_STEP`` never: it restarts in the same step). The
        :class:`RunLog` :func:`dfcoa_opt.run` gives, for the metrics.

        Raises:
            DfcoaError: The sub-environment's episode has not ended.
        """
        return self.core.episode_log(env)

    @property
    def toolkit_observation(self) -> Observation | None:
        """The batched :class:`Observation` behind the running sub-environments' observations.

        Rows are robot after robot of the running sub-environments in slot
        order (``env``: the sub-environment of each row); ``t`` is NaN when
        their clocks differ. What a batched controller's ``act`` takes.
        """
        return self.core.observation

    def close_extras(self, **kwargs: Any) -> None:
        """Drop the batch."""
        self.core._stepper = None


def vector_env(scenario: Scenario | str | Path, num_envs: int = 1, seed: int = 0,
               **options: Any) -> FormationVectorEnv:
    """A gymnasium ``VectorEnv`` of ``num_envs`` runs of ``scenario``, stepped as one batch.

    Args:
        scenario: A loaded scenario or a scenario file.
        num_envs: E, the sub-environments.
        seed: The base seed when the first ``reset`` gets none.
        **options: ``autoreset_mode``, ``reward`` (:class:`RewardSpec`),
            ``observation`` (:class:`ObservationSpec`), ``stop_on_deadlock``
            (default True) and scenario keys (``t_max=20.0``).

    Returns:
        The environment (``reset`` it first).

    Example:
        >>> from dfcoa_opt.envs import vector_env
        >>> env = vector_env("scenarios/example_empty.toml", num_envs=8, t_max=5.0)
        >>> obs, infos = env.reset(seed=0)
        >>> obs.shape, env.action_space.shape
        ((8, 4, 56), (8, 4, 2))
    """
    return FormationVectorEnv(scenario, num_envs, seed, **options)
