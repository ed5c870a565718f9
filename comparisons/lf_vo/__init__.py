"""``lf_vo``: paper 002's leader-follower V formation with a sampled velocity obstacle.

- :mod:`~comparisons.lf_vo.controller`: the controller ``LeaderFollowerVO``
  (registered as ``lf_vo``);
- :mod:`~comparisons.lf_vo.equations`: paper 002's equations (eq 4-12) in
  vectorised numpy, the reference;
- :mod:`~comparisons.lf_vo.kernel`: the numba kernel of the sampled velocity
  obstacle, bit for bit the reference;
- :mod:`~comparisons.lf_vo.choose`: the numba choice of each robot's sample.

Notes: ``docs/methods/lf_vo.md``.
"""

from comparisons.lf_vo.controller import LeaderFollowerVO

__all__ = ["LeaderFollowerVO"]
