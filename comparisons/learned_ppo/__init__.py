"""``learned_ppo``: a policy network trained by PPO (Stable-Baselines3) on the environments.

- :mod:`~comparisons.learned_ppo.controller`: the controller ``LearnedPPO`` (registered
  as ``learned_ppo``), running the shipped ``learned_ppo.json`` / ``learned_ppo.npz``
  with numpy only;
- :mod:`~comparisons.learned_ppo.train`: the training (the ``rl`` extra: torch,
  stable-baselines3), which writes those files and the learning curve;
- :mod:`~comparisons.learned_ppo.vec`: SB3 glue (several batches as one, unit actions).

Notes: ``docs/methods/learned.md``.
"""

from comparisons.learned_ppo.controller import LearnedPPO

__all__ = ["LearnedPPO"]
