"""Seeded random clutter: a field of circular obstacles with a given density.

Used by the ``[world.clutter]`` scenario section (``scenarios/bench/clutter.toml``).
The field depends only on its seed, so a benchmark sweep that varies the run
seed sees a new field per seed, and the same seed always gives the same field.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.world.shapes import Circle

#: Candidates drawn per batch (vectorised rejection sampling).
_BATCH = 256
#: Give up after this many batches without reaching the density.
_MAX_BATCHES = 200


def random_discs(rng: np.random.Generator, region: tuple[float, float, float, float],
                 density: float, radius_min: float, radius_max: float,
                 keep_points: NDArray[np.float64], keep_radius: NDArray[np.float64],
                 gap: float = 0.0) -> tuple[Circle, ...]:
    """Non-overlapping discs until their area is ``density`` times the region's.

    Centres are uniform in ``region``, radii uniform in ``[radius_min, radius_max]``.
    A candidate is rejected when it comes closer than ``keep_radius[k]`` to
    ``keep_points[k]`` or closer than ``gap`` to an accepted disc. Candidates are
    drawn in batches of 256 and tested in draw order, so the result is a pure
    function of the generator's state.

    Args:
        rng: The generator (consumed).
        region: ``(x0, y0, x1, y1)`` box for the centres, m.
        density: Target covered fraction of the region's area, in [0, 1).
        radius_min: Smallest radius, m.
        radius_max: Largest radius, m.
        keep_points: ``(K, 2)`` points to keep clear, m.
        keep_radius: ``(K,)`` clear distance around each point (to the disc's edge), m.
        gap: Smallest free distance between two discs, m.

    Returns:
        The discs, in acceptance order. Fewer than asked when the region fills
        up (after 200 batches without reaching the density).
    """
    x0, y0, x1, y1 = region
    target = density * (x1 - x0) * (y1 - y0)
    keep_points = np.asarray(keep_points, dtype=float).reshape(-1, 2)
    keep_radius = np.asarray(keep_radius, dtype=float).reshape(-1)
    centres = np.empty((0, 2))
    radii = np.empty(0)
    area = 0.0
    for _ in range(_MAX_BATCHES):
        if area >= target:
            break
        c = rng.uniform((x0, y0), (x1, y1), size=(_BATCH, 2))
        r = rng.uniform(radius_min, radius_max, size=_BATCH)
        rel = c[:, None, :] - keep_points[None]
        d_keep = np.hypot(rel[..., 0], rel[..., 1]) - r[:, None]  # no overflow for far points
        ok = np.all(d_keep >= keep_radius[None, :], axis=1)
        for j in np.flatnonzero(ok):
            if area >= target:
                break
            if len(radii) and np.any(np.hypot(*(centres - c[j]).T) < radii + r[j] + gap):
                continue
            centres = np.vstack((centres, c[j]))
            radii = np.append(radii, r[j])
            area += np.pi * r[j] ** 2
    return tuple(Circle((float(cx), float(cy)), float(rr)) for (cx, cy), rr in
                 zip(centres, radii, strict=True))
