"""World family ``rooms``: a row of rooms between the start and the goal, joined by doorways.

The span between the start's and the goal's free discs is cut by walls across
the whole map height into ``rooms`` rooms (the start's and the goal's rooms
included: ``rooms - 1`` walls). The walls are evenly spaced, each moved by up
to a quarter of the spacing. Each wall has ``doors`` doorways, each of a width
drawn uniformly from ``door_width`` and centred at a uniformly drawn height,
with at least ``door_gap`` of wall between two doorways and between a doorway
and the map's edge. With the default widths, about two doorways in three are
narrower than a 5-robot V: the team must squeeze or file through.

Facts of a draw: ``rooms``, ``door_widths`` (every doorway, wall after wall,
bottom to top), ``door_centres`` (their heights, m) and ``walls`` (the walls'
x, m).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dfcoa_opt.core.params import param
from dfcoa_opt.world.generate import Generated, Layout, check_range, register_family
from dfcoa_opt.world.shapes import Rectangle, Shape

#: Draws of a wall's doorway heights before it takes one doorway fewer.
_DOOR_TRIES = 50


@dataclass(frozen=True)
class RoomsParams:
    """Options of the ``rooms`` family (``[world.generate.options]``)."""

    rooms: tuple[int, int] = param((3, 5), doc="Range of the number of rooms from start to "
                                               "goal (walls = rooms - 1).", ge=2, le=50)
    door_width: tuple[float, float] = param((1.0, 3.6), doc="Range of a doorway's width.",
                                            unit="m", gt=0.0)
    doors: tuple[int, int] = param((1, 2), doc="Range of the number of doorways per wall.",
                                   ge=1, le=10)
    wall_thickness: float = param(0.2, doc="Thickness of a wall.", unit="m", gt=0.0)
    door_gap: float = param(0.5, doc="Least wall between two doorways, and between a doorway "
                                     "and the map's edge.", unit="m", ge=0.0)

    def check(self, src: str, key: str) -> None:
        """Ranges in order."""
        for name in ("rooms", "door_width", "doors"):
            check_range(getattr(self, name), src, f"{key}.{name}")


def _doorways(p: RoomsParams, rng: np.random.Generator, y0: float, y1: float
              ) -> list[tuple[float, float]]:
    """``[(centre, width), ...]`` of one wall, bottom to top."""
    count = int(rng.integers(p.doors[0], p.doors[1] + 1))
    widths = rng.uniform(p.door_width[0], p.door_width[1], size=count)
    while count > 0:
        for _ in range(_DOOR_TRIES):
            lo = y0 + p.door_gap + widths[:count] / 2
            hi = y1 - p.door_gap - widths[:count] / 2
            if np.any(hi < lo):
                break
            centres = rng.uniform(lo, hi)
            order = np.argsort(centres, kind="stable")
            c, w = centres[order], widths[:count][order]
            if np.all(c[1:] - w[1:] / 2 - (c[:-1] + w[:-1] / 2) >= p.door_gap):
                return [(float(a), float(b)) for a, b in zip(c, w, strict=True)]
        count -= 1
    raise ValueError("no doorway fits the wall")


@register_family("rooms", params=RoomsParams)
def rooms(p: RoomsParams, rng: np.random.Generator, layout: Layout) -> Generated:
    """Draw one world of rooms (see the module docstring)."""
    _, _, y0, y1 = layout.extent
    lo, hi = layout.span()
    n_rooms = int(rng.integers(p.rooms[0], p.rooms[1] + 1))
    spacing = (hi - lo) / (n_rooms - 1)
    base = lo + spacing * (np.arange(n_rooms - 1) + 0.5)
    walls = base + rng.uniform(-0.25, 0.25, size=len(base)) * spacing
    shapes: list[Shape] = []
    widths: list[float] = []
    centres: list[float] = []
    half = p.wall_thickness / 2
    for x in walls:
        doors = _doorways(p, rng, y0, y1)
        edges = [y0, *(e for c, w in doors for e in (c - w / 2, c + w / 2)), y1]
        for a, b in zip(edges[::2], edges[1::2], strict=True):
            if b > a:
                shapes.append(Rectangle((float(x - half), a), (float(x + half), b)))
        widths += [w for _, w in doors]
        centres += [c for c, _ in doors]
    facts = {"rooms": n_rooms, "door_widths": widths, "door_centres": centres,
             "walls": [float(x) for x in walls]}
    return Generated(shapes=tuple(shapes), facts=facts)
