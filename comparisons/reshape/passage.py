"""``reshape_passage``: ``reshape`` with its coordination layer (docs/methods/reshape_passage.md).

The same planner, tracking and filter as :class:`~comparisons.reshape.controller.Reshape`,
with ``coordinate`` on and ``yield_time`` 1 s:

- a column on a route is led by its front robot, so it files through a
  passage in order instead of standing where its centroid is a fixed point;
- a formation stays on its route until it has passed the blocked stretch;
- a stuck team (:class:`~comparisons.reshape.progress.ProgressMonitor`:
  progress along the leader's path, told apart from a queue or a team waiting
  for a walker) takes a route through the whole map for ``recover_time``; on
  it the robots take the route's slots in the order they stand (robots that
  met head-on in a passage trade places instead of pushing);
- a team back within reach of its slots leaves its hold for them, and a team
  that got ahead of its leader along the path goes back to its slots;
- the goal's formation is taken where the leader stops;
- the tracking filter grows each moving disc by its speed times ``yield_time``.
"""

from __future__ import annotations

from dataclasses import dataclass

from comparisons.reshape.controller import Reshape
from comparisons.reshape.params import ReshapeParams
from dfcoa_opt.control.registry import register
from dfcoa_opt.core.params import param

__all__ = ["Passage", "PassageParams"]


@dataclass(frozen=True)
class PassageParams(ReshapeParams):
    """Parameters of ``reshape_passage`` (``[controllers.reshape_passage]``).

    ``reshape``'s, with the coordination layer on.
    """

    coordinate: bool = param(True, doc="The coordination layer "
                                       "(docs/methods/reshape_passage.md).")
    yield_time: float = param(1.0, doc="The tracking filter grows each sensed moving disc "
                                       "by its speed times this: robots give way earlier "
                                       "to faster discs.", unit="s", ge=0.0, tune=(0.0, 2.0))


@register("reshape_passage")
class Passage(Reshape):
    """Reshaping formation with a coordination layer: queues, recovery, yielding."""

    Params = PassageParams
