"""World family ``crowd``: an open or lightly cluttered field crossed by moving discs.

Each disc crosses the straight line from the start to the goal: it picks a
crossing point on that line (uniformly between the start's and the goal's free
discs) and a direction at least 30 degrees off the line
(uniform over both sides), and walks the chord of the map through that point
back and forth (``end = "bounce"``), waiting first at the end farther from the
start, at a speed drawn from ``speed``, from a
time drawn in ``[0, start_delay]``. Its radius is drawn from ``radius``.
A static clutter of discs of ``density`` (0: none) may be added, kept clear of
the start's and the goal's free discs (:func:`~dfcoa_opt.world.clutter.random_discs`).

``count`` is one number, not a range: a batch steps runs with as many moving
discs. Facts of a draw: ``count``, ``speeds`` (m/s), ``radii`` (m), ``start_times``
(s) and ``static`` (the number of static discs).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dfcoa_opt.core.params import param
from dfcoa_opt.world.clutter import random_discs
from dfcoa_opt.world.dynamic import MovingDisc
from dfcoa_opt.world.generate import Generated, Layout, check_range, register_family

#: Least angle between a disc's track and the start-goal line, rad.
MIN_CROSSING_ANGLE = math.radians(30.0)


@dataclass(frozen=True)
class CrowdParams:
    """Options of the ``crowd`` family (``[world.generate.options]``)."""

    count: int = param(6, doc="Number of moving discs (one number, so that the runs of a "
                              "batch move as many).", ge=0, le=1000)
    speed: tuple[float, float] = param((0.2, 0.5), doc="Range of a disc's speed.", unit="m/s",
                                       gt=0.0)
    radius: tuple[float, float] = param((0.2, 0.35), doc="Range of a disc's radius.", unit="m",
                                        gt=0.0)
    start_delay: float = param(30.0, doc="A disc starts moving at a time drawn in [0, this].",
                               unit="s", ge=0.0)
    density: float = param(0.0, doc="Static clutter: fraction of the map covered by fixed "
                                    "discs (0: an open field).", ge=0.0, lt=0.5)
    clutter_radius: tuple[float, float] = param((0.2, 0.4), doc="Range of a static disc's "
                                                                "radius.", unit="m", gt=0.0)

    def check(self, src: str, key: str) -> None:
        """Ranges in order."""
        for name in ("speed", "radius", "clutter_radius"):
            check_range(getattr(self, name), src, f"{key}.{name}")


def _chord(point: np.ndarray, direction: np.ndarray, box: tuple[float, float, float, float]
           ) -> tuple[tuple[float, float], tuple[float, float]]:
    """Where the line through ``point`` along ``direction`` leaves ``box`` (both ways)."""
    x0, x1, y0, y1 = box
    ts = []
    for k, (a, b) in enumerate(((x0, x1), (y0, y1))):
        if abs(direction[k]) > 1e-12:
            ts += [(a - point[k]) / direction[k], (b - point[k]) / direction[k]]
    lo = max(t for t in ts if t <= 0)
    hi = min(t for t in ts if t >= 0)
    p, q = point + lo * direction, point + hi * direction
    return (float(p[0]), float(p[1])), (float(q[0]), float(q[1]))


@register_family("crowd", params=CrowdParams)
def crowd(p: CrowdParams, rng: np.random.Generator, layout: Layout) -> Generated:
    """Draw one crowd (see the module docstring)."""
    x0, x1, y0, y1 = layout.extent
    start, goal = np.asarray(layout.start, float), np.asarray(layout.goal, float)
    line = goal - start
    length = float(np.hypot(*line))
    along = line / length if length > 0 else np.array([1.0, 0.0])
    u_lo = min(layout.start_clear / length, 1.0) if length > 0 else 0.0
    u_hi = max(1.0 - layout.goal_clear / length, u_lo) if length > 0 else 0.0
    discs = []
    for _ in range(p.count):
        r = float(rng.uniform(*p.radius))
        point = start + float(rng.uniform(u_lo, u_hi)) * line
        angle = float(rng.uniform(MIN_CROSSING_ANGLE, math.pi - MIN_CROSSING_ANGLE))
        angle *= 1.0 if rng.random() < 0.5 else -1.0
        c, s = math.cos(angle), math.sin(angle)
        direction = np.array([c * along[0] - s * along[1], s * along[0] + c * along[1]])
        a, b = _chord(point, direction, (x0 + r, x1 - r, y0 + r, y1 - r))
        if np.hypot(*(np.subtract(a, start))) < np.hypot(*(np.subtract(b, start))):
            a, b = b, a  # it waits at the end farther from the team's start
        discs.append(MovingDisc(r, float(rng.uniform(*p.speed)), (a, b),
                                float(rng.uniform(0.0, p.start_delay)), "bounce"))
    static = ()
    if p.density > 0:
        points, radii = layout.keep_points()
        static = random_discs(rng, (x0, y0, x1, y1), p.density, *p.clutter_radius, points, radii)
    facts = {"count": p.count, "speeds": [d.speed for d in discs],
             "radii": [d.radius for d in discs], "start_times": [d.start_time for d in discs],
             "static": len(static)}
    return Generated(shapes=static, discs=tuple(discs), facts=facts)
