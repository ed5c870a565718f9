"""``virtual_spring``: paper 004's virtual-spring consensus formation.

- :mod:`~comparisons.virtual_spring.controller`: the controllers
  ``VirtualSpring`` (registered as ``virtual_spring``) and
  ``VirtualSpringBasic`` (``virtual_spring_basic``, the paper's model without
  improvement);
- :mod:`~comparisons.virtual_spring.equations`: paper 004's eq 1-14 in
  vectorised numpy;
- :mod:`~comparisons.virtual_spring.conflict`: the velocity-obstacle conflict
  resolution, eq 15-17.

Notes: ``docs/methods/virtual_spring.md``.
"""

from comparisons.virtual_spring.controller import VirtualSpring, VirtualSpringBasic

__all__ = ["VirtualSpring", "VirtualSpringBasic"]
