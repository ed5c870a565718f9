"""``learned``: a policy network cloned from ``goto_slot+cbf`` by BC + DAgger (numpy only).

- :mod:`~comparisons.learned.controller`: the controller ``Learned`` (registered as
  ``learned``), running the shipped ``learned.json`` / ``learned.npz``;
- :mod:`~comparisons.learned.train`: the training (reproduces the shipped files);
- :mod:`~comparisons.learned.dagger`: the teacher/student mixture that collects data;
- :mod:`~comparisons.learned.mlp`: the numpy MLP and Adam;
- :mod:`~comparisons.learned.evaluate`: outcomes over seeds 0-19.

Notes: ``docs/methods/learned.md``.
"""

from comparisons.learned.controller import Learned

__all__ = ["Learned"]
