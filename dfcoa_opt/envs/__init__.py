"""Learning environments over the batched simulator, and the observation that policies share.

- :func:`parallel_env` (:mod:`dfcoa_opt.envs.parallel`): a PettingZoo
  ``ParallelEnv`` of one run, one agent per robot (``robot_0`` ...).
- :func:`vector_env` (:mod:`dfcoa_opt.envs.vector`): a gymnasium ``VectorEnv``
  whose E sub-environments are the E slots of one batched
  :class:`~dfcoa_opt.sim.stepper.Stepper`, each a team with an ``(N, D)``
  observation and an ``(N, 2)`` action, reset in its slot when its run ends.
- :func:`sb3_vec_env` (:mod:`dfcoa_opt.envs.sb3`): a Stable-Baselines3
  ``VecEnv`` of every robot of E teams over one ``vector_env`` (parameter
  sharing); it needs the ``rl`` extra.
- :func:`torchrl_env` (:mod:`dfcoa_opt.envs.torchrl`): a torchrl ``EnvBase``
  over one ``vector_env``, batch ``[E]``, the robots as the group ``"robot"``
  ``[E, N]``; it needs the ``rl`` extra.
- :class:`RewardSpec` (:mod:`dfcoa_opt.envs.rewards`): the reward's weights;
  the reward comes from the toolkit's metrics (paper 000 eq 6-7, progress
  along the leader's path) and outcomes (collision, success, deadlock).
- :mod:`dfcoa_opt.control.features`: one robot's observation as a flat vector
  (:class:`~dfcoa_opt.control.features.ObservationSpec`, ``flatten``), shared by
  the environments and the ``policy:PATH`` controllers.
- :mod:`dfcoa_opt.envs.core`: the engine both environments share (numpy only),
  and :data:`~dfcoa_opt.envs.core.OUTCOME_CODES`, the integer code of each
  episode outcome in the infos.

Both environments need the ``envs`` extra (``pip install -e '.[envs]'``:
pettingzoo and gymnasium); they are imported on first use, so neither
``import dfcoa_opt`` nor ``import dfcoa_opt.envs`` imports them. Observation
layout, action, reward, episode ends, seeds and speed: ``docs/envs.md``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from dfcoa_opt.envs.core import OUTCOME_CODES, OUTCOME_NAMES
    from dfcoa_opt.envs.parallel import FormationParallelEnv, parallel_env
    from dfcoa_opt.envs.rewards import RewardSpec
    from dfcoa_opt.envs.sb3 import FormationSB3VecEnv, sb3_vec_env
    from dfcoa_opt.envs.torchrl import FormationTorchEnv, torchrl_env
    from dfcoa_opt.envs.vector import FormationVectorEnv, vector_env

__all__ = ["OUTCOME_CODES", "OUTCOME_NAMES", "FormationParallelEnv", "FormationSB3VecEnv",
           "FormationTorchEnv", "FormationVectorEnv", "RewardSpec", "parallel_env",
           "sb3_vec_env", "torchrl_env", "vector_env"]

_LAZY = {"parallel_env": "parallel", "FormationParallelEnv": "parallel",
         "vector_env": "vector", "FormationVectorEnv": "vector", "RewardSpec": "rewards",
         "sb3_vec_env": "sb3", "FormationSB3VecEnv": "sb3",
         "torchrl_env": "torchrl", "FormationTorchEnv": "torchrl",
         "OUTCOME_CODES": "core", "OUTCOME_NAMES": "core"}


def __getattr__(name: str) -> Any:
    """Import an environment's module on first use (pettingzoo, gymnasium only then)."""
    if name not in _LAZY:
        raise AttributeError(f"module 'dfcoa_opt.envs' has no attribute {name!r}")
    from importlib import import_module

    return getattr(import_module(f"dfcoa_opt.envs.{_LAZY[name]}"), name)


def __dir__() -> list[str]:
    return sorted(list(globals()) + __all__)
