"""torchrl ``EnvBase``: E runs of a scenario as one batched torchrl environment.

``torchrl_env(scenario, num_envs=E, seed=s)`` is a native torchrl environment
over :class:`~dfcoa_opt.envs.vector.FormationVectorEnv` (one batched
:class:`~dfcoa_opt.sim.stepper.Stepper`, E slots), laid out as torchrl's
multi-agent environments (VMAS's ``VmasEnv``): batch size ``[E]``, one group
``"robot"`` of shape ``[E, N]`` (the group :class:`torchrl.envs.PettingZooWrapper`
gives :func:`~dfcoa_opt.envs.parallel_env`'s agents ``robot_0`` ...):

================================  ==============  =======  ==========================
key                               shape           dtype    value
================================  ==============  =======  ==========================
``("robot", "observation")``      ``[E, N, D]``   float64  each robot's vector
``("robot", "action")``           ``[E, N, 2]``   float64  each robot's command
``("robot", "reward")``           ``[E, N, 1]``   float64  the team's reward
``"done"``, ``"terminated"``,     ``[E, 1]``      bool     the team's episode end
``"truncated"``
``("info", "seed")``              ``[E]``         int64    the episode's seed
``("info", "t")``                 ``[E]``         float64  the instant scored, s
``("info", "outcome")``           ``[E]``         int64    the outcome code
================================  ==============  =======  ==========================

The numbers are the vector environment's, float64 as it gives them (a
``DoubleToFloat`` transform casts them for a float32 policy). The action spec
is the robots' limits; actions are not clipped (the robot model saturates
them). The observation spec is unbounded (the ``Box`` bounds are
``vector_env``'s ``single_observation_space``). torchrl's
convention for ends: the step where a sub-environment ends returns its last
observation (the one its robots acted on) with ``done``; ``env.reset`` with a
``"_reset"`` mask (what ``rollout(..., break_when_any_done=False)`` and the
collectors send) then gives its next episode's first observation. That
episode has already started in its slot during the step (gymnasium's
``SAME_STEP``), so the running sub-environments are sensed once per step, as
in the vector environment, and the observations are its bits. Seeds are the
vector environment's: after :meth:`~torchrl.envs.EnvBase.set_seed` ``(s)``
(else the constructor's seed), episode ``j`` of sub-environment ``i`` is the
run of seed ``s + i + j * E``. Docs: ``docs/envs.md``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import torch
from gymnasium.vector import AutoresetMode
from numpy.typing import NDArray
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Bounded, Categorical, Composite, Unbounded
from torchrl.envs import EnvBase

from dfcoa_opt.core.errors import DfcoaError
from dfcoa_opt.envs.vector import FormationVectorEnv
from dfcoa_opt.scenario.scenario import Scenario

GROUP = "robot"
"""The group of the robots' entries (``("robot", "observation")`` ...)."""


class FormationTorchEnv(EnvBase):
    """E formation runs of one scenario as a batched torchrl environment (module docstring).

    Args:
        scenario: A loaded scenario or a scenario file.
        num_envs: E, the sub-environments (slots of the batch); the batch size.
        seed: The base seed of the first reset when :meth:`set_seed` was not called.
        device: Where the tensors go (the simulation runs on the CPU in numpy).
        **options: What :func:`~dfcoa_opt.envs.vector_env` takes (``reward``,
            ``observation``, ``stop_on_deadlock``, scenario keys such as
            ``t_max=20.0``), except ``autoreset_mode``.

    Attributes:
        venv: The gymnasium vector environment the steps go through (``SAME_STEP``).
        scenario: The scenario the episodes run (with the episode-end settings).
    """

    batch_locked = True

    def __init__(self, scenario: Scenario | str | Path, num_envs: int = 1, seed: int = 0,
                 device: str | torch.device = "cpu", **options: Any) -> None:
        if "autoreset_mode" in options:
            raise ValueError("torchrl_env resets through torchrl's '_reset' mask; "
                             "autoreset_mode is not an option")
        self.venv = FormationVectorEnv(scenario, num_envs, seed,
                                       autoreset_mode=AutoresetMode.SAME_STEP, **options)
        self.scenario = self.venv.scenario
        super().__init__(batch_size=torch.Size([self.venv.num_envs]), device=device)
        self._make_specs()
        self._obs: NDArray[np.float64] | None = None  # (E, N, D) every slot's current one
        self._pending = np.zeros(self.venv.num_envs, dtype=bool)  # ended at the last step
        self._seed: int | None = int(seed)  # the base seed of the next full reset, if new

    def _make_specs(self) -> None:
        """The specs: the module docstring's table."""
        core, e = self.venv.core, self.venv.num_envs
        n, size, f64, i64 = core.n, core.size, torch.float64, torch.int64
        dev = self.device
        shape = torch.Size([e, n])
        self.full_observation_spec = Composite(
            {GROUP: Composite(observation=Unbounded((e, n, size), dtype=f64, device=dev),
                              shape=shape),
             "info": Composite(seed=Unbounded((e,), dtype=i64, device=dev),
                               t=Unbounded((e,), dtype=f64, device=dev),
                               outcome=Unbounded((e,), dtype=i64, device=dev), shape=(e,))},
            shape=(e,), device=dev)
        low = torch.as_tensor(np.broadcast_to(core.action_low, (e, n, 2)).copy())
        high = torch.as_tensor(np.broadcast_to(core.action_high, (e, n, 2)).copy())
        self.full_action_spec = Composite(
            {GROUP: Composite(action=Bounded(low, high, (e, n, 2), dtype=f64, device=dev),
                              shape=shape)}, shape=(e,), device=dev)
        self.full_reward_spec = Composite(
            {GROUP: Composite(reward=Unbounded((e, n, 1), dtype=f64, device=dev), shape=shape)},
            shape=(e,), device=dev)
        self.full_done_spec = Composite(
            {k: Categorical(2, (e, 1), dtype=torch.bool, device=dev)
             for k in ("done", "terminated", "truncated")}, shape=(e,), device=dev)

    # ------------------------------------------------------------------ torchrl API
    def _set_seed(self, seed: int | None) -> None:
        """The base seed ``s`` of the next reset: sub-environment ``i`` then runs ``s + i``."""
        if seed is not None:
            if int(seed) < 0:
                raise ValueError(f"seeds must be >= 0, got {seed}")
            self._seed = int(seed)

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs: Any) -> TensorDictBase:
        """Start episodes: every sub-environment's, or those of the ``"_reset"`` mask.

        Without a mask, or with one over every sub-environment, every
        sub-environment starts its next episode in a new batch (the base seed
        of :meth:`set_seed` or the constructor the first time). A partial mask
        may only name sub-environments whose episode ended at the last step:
        their next episode started in their slot during that step.

        Raises:
            DfcoaError: A partial mask over a sub-environment whose episode is
                running (one slot cannot restart while the others go on: it
                would sense them twice in one step). End runs with ``t_max``,
                not with a ``StepCounter`` transform.
        """
        venv, e = self.venv, self.venv.num_envs
        mask = None if tensordict is None else tensordict.get("_reset", None)
        reset = (np.ones(e, dtype=bool) if mask is None
                 else mask.reshape(e).cpu().numpy().astype(bool))
        running = reset & ~self._pending
        if self._obs is None or running.any():
            if self._obs is not None and not reset.all():
                raise DfcoaError(f"sub-environment(s) {np.flatnonzero(running).tolist()} cannot "
                                 "restart while running: reset all of them or let them end")
            if self._seed is not None:
                self._obs = venv.reset(seed=self._seed)[0]
                self._seed = None
            else:  # the pending ones have started their next episode: start it again
                venv._episode[self._pending] -= 1
                self._obs = venv.reset()[0]
            reset[:] = True
        self._pending &= ~reset
        done = np.zeros((e, 1), dtype=bool)
        return self._out(self._obs, venv.episode_seeds(), np.zeros(e),
                         np.zeros(e, dtype=np.int64), done, done, done)

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        """One step ``dt`` of every sub-environment with ``("robot", "action")`` ``[E, N, 2]``.

        Returns:
            The next observations (an ended episode's last one), rewards, ends
            and infos: ``seed`` and ``t`` of the episode and instant the step
            scored, ``outcome`` its code where the episode ended (else 0).
        """
        act = tensordict.get((GROUP, "action")).detach().cpu().numpy()
        obs, reward, term, trunc, infos = self.venv.step(act)
        self._obs = nxt = obs
        self._pending = ended = term | trunc
        if ended.any():  # report the ended episodes; their slots run the next ones already
            nxt = obs.copy()
            nxt[ended] = np.stack(infos["final_obs"][ended])
            infos = infos["final_info"]  # the ended episodes' seeds, instants and outcomes
        return self._out(nxt, infos["seed"], infos["t"], infos["outcome"], ended[:, None],
                         term[:, None], trunc[:, None], reward)

    def _out(self, obs: NDArray[np.float64], seed: NDArray[np.int64], t: NDArray[np.float64],
             outcome: NDArray[np.int64], done: NDArray[np.bool_], terminated: NDArray[np.bool_],
             truncated: NDArray[np.bool_], reward: NDArray[np.float64] | None = None,
             ) -> TensorDictBase:
        """The tensordict of a reset or a step, of copies of the numpy arrays (no shared memory)."""
        e, n, dev = self.venv.num_envs, self.venv.core.n, self.device
        group = {"observation": torch.tensor(obs, device=dev)}
        if reward is not None:
            group["reward"] = torch.tensor(np.repeat(reward[:, None, None], n, axis=1), device=dev)
        info = {"seed": torch.tensor(seed, device=dev), "t": torch.tensor(t, device=dev),
                "outcome": torch.tensor(outcome, device=dev)}
        return TensorDict({GROUP: TensorDict(group, batch_size=(e, n), device=dev),
                           "info": TensorDict(info, batch_size=(e,), device=dev),
                           "done": torch.tensor(done, device=dev),
                           "terminated": torch.tensor(terminated, device=dev),
                           "truncated": torch.tensor(truncated, device=dev)},
                          batch_size=(e,), device=dev)

    def close(self, *, raise_if_closed: bool = True) -> None:
        """Drop the batch."""
        self.venv.close()
        super().close(raise_if_closed=raise_if_closed)


def torchrl_env(scenario: Scenario | str | Path, num_envs: int = 1, seed: int = 0,
                device: str | torch.device = "cpu", **options: Any) -> FormationTorchEnv:
    """A torchrl environment of ``num_envs`` runs of ``scenario``, stepped as one batch.

    Args:
        scenario: A loaded scenario or a scenario file.
        num_envs: E, the sub-environments (the batch size).
        seed: The base seed of the first reset (:meth:`set_seed` changes it).
        device: The tensors' device.
        **options: ``reward``, ``observation``, ``stop_on_deadlock`` and
            scenario keys (``t_max=20.0``), as :func:`~dfcoa_opt.envs.vector_env`.

    Returns:
        The environment; ``env.rollout(T, break_when_any_done=False)`` runs it.

    Example:
        >>> from dfcoa_opt.envs import torchrl_env
        >>> env = torchrl_env("scenarios/example_empty.toml", num_envs=8, t_max=5.0)
        >>> env.reset()["robot", "observation"].shape
        torch.Size([8, 4, 56])
    """
    return FormationTorchEnv(scenario, num_envs, seed, device, **options)
