"""World family ``corridors``: one winding corridor from the start's room to the goal's room.

The corridor's centre line is axis-aligned: it leaves the start eastwards,
turns up or down into a vertical leg, turns back east at a new height, and so
on; the last leg brings it to the goal's height. A world draws its number of
turns (even: each leg turns twice) from ``turns``, the legs' positions (one in
each equal slice of the span between the start's and the goal's free discs),
the heights between them (uniform, at least ``min_leg`` from the previous
height) and every segment's width (uniform in ``width``). Each segment is a
free rectangle as wide as its width, reaching half its width beyond its ends;
the start and the goal sit in free squares as wide as their free discs.
Everything else in the map is wall, as few rectangles
(:func:`~dfcoa_opt.world.generate.rects.mask_rectangles` on the grid of every
rectangle's edges).

Facts of a draw: ``turns`` (the corners of the centre line where it changes
direction: fewer than drawn when a leg has no length, e.g. one leg between a
start and a goal at one height), ``widths`` (every segment's width, in order along
the corridor) and ``centre_line`` (its corner points, m).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dfcoa_opt.core.params import param
from dfcoa_opt.world.generate import Generated, Layout, check_range, register_family
from dfcoa_opt.world.generate.rects import mask_rectangles
from dfcoa_opt.world.shapes import Rectangle

#: Draws of a leg's height before the leg's least length is given up.
_LEVEL_TRIES = 100


@dataclass(frozen=True)
class CorridorsParams:
    """Options of the ``corridors`` family (``[world.generate.options]``)."""

    width: tuple[float, float] = param((1.2, 3.2), doc="Range of a segment's width.", unit="m",
                                       gt=0.0)
    turns: tuple[int, int] = param((4, 8), doc="Range of the number of 90-degree turns (even "
                                               "numbers only are drawn: each leg turns twice; "
                                               "with the start and the goal at one height, the "
                                               "first and last legs meet it, so 2 is straight).",
                                   ge=2, le=40)
    min_leg: float = param(2.0, doc="Least length of a vertical leg.", unit="m", gt=0.0)
    wall: float = param(0.5, doc="Least wall between a segment and the map's edge.", unit="m",
                        ge=0.0)

    def check(self, src: str, key: str) -> None:
        """Ranges in order, and room for an even number of turns."""
        check_range(self.width, src, f"{key}.width")
        check_range(self.turns, src, f"{key}.turns")
        if self.turns[0] % 2 and self.turns[0] == self.turns[1]:
            from dfcoa_opt.core.errors import ScenarioError

            raise ScenarioError(src, f"{key}.turns", f"[{self.turns[0]}, {self.turns[1]}] holds "
                                                     "no even number of turns")


def _segment(a: tuple[float, float], b: tuple[float, float], w: float) -> Rectangle:
    """The free rectangle of the axis-aligned segment ``a -> b``, ``w`` wide, reaching w/2 on."""
    h = w / 2
    return Rectangle((min(a[0], b[0]) - h, min(a[1], b[1]) - h),
                     (max(a[0], b[0]) + h, max(a[1], b[1]) + h))


@register_family("corridors", params=CorridorsParams)
def corridors(p: CorridorsParams, rng: np.random.Generator, layout: Layout) -> Generated:
    """Draw one winding corridor (see the module docstring)."""
    x0, x1, y0, y1 = layout.extent
    even = [t for t in range(p.turns[0], p.turns[1] + 1) if t % 2 == 0]
    turns = int(even[int(rng.integers(len(even)))])
    legs = turns // 2
    lo, hi = layout.span()
    slot = (hi - lo) / legs
    xs_leg = lo + slot * (np.arange(legs) + rng.uniform(0.25, 0.75, size=legs))
    widths = rng.uniform(p.width[0], p.width[1], size=2 * legs + 1)
    y_lo = y0 + p.wall + p.width[1] / 2
    y_hi = y1 - p.wall - p.width[1] / 2
    level, goal_y = float(layout.start[1]), float(layout.goal[1])
    levels = []
    for i in range(legs - 1):
        last = i == legs - 2
        for _ in range(_LEVEL_TRIES):
            y = float(rng.uniform(y_lo, y_hi))
            if abs(y - level) >= p.min_leg and (not last or abs(y - goal_y) >= p.min_leg):
                break
        levels.append(y)
        level = y
    levels.append(goal_y)
    line = [tuple(map(float, layout.start))]
    for x, y in zip(xs_leg, levels, strict=True):
        line += [(float(x), line[-1][1]), (float(x), y)]
    line.append(tuple(map(float, layout.goal)))
    free = [_segment(a, b, float(w))
            for a, b, w in zip(line[:-1], line[1:], widths, strict=True)]
    for (cx, cy), r in zip(*layout.keep_points(), strict=True):
        free.append(Rectangle((cx - r, cy - r), (cx + r, cy + r)))
    xs = np.unique(np.clip([x0, x1, *(v for f in free for v in (f.min[0], f.max[0]))], x0, x1))
    ys = np.unique(np.clip([y0, y1, *(v for f in free for v in (f.min[1], f.max[1]))], y0, y1))
    cx, cy = np.meshgrid((xs[:-1] + xs[1:]) / 2, (ys[:-1] + ys[1:]) / 2)
    centres = np.column_stack((cx.ravel(), cy.ravel()))
    covered = np.zeros(len(centres), dtype=bool)
    for f in free:
        covered |= f.contains(centres)
    walls = mask_rectangles(~covered.reshape(cx.shape), xs, ys)
    bends = sum(1 for a, b, c in zip(line, line[1:], line[2:], strict=False)
                if (b[0] - a[0]) * (c[1] - b[1]) != 0 or (b[1] - a[1]) * (c[0] - b[0]) != 0)
    facts = {"turns": bends, "widths": [float(w) for w in widths],
             "centre_line": [list(q) for q in line]}
    return Generated(shapes=walls, facts=facts)
