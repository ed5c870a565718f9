"""Difficulty metrics of a world, measured along the leader's reference path (docs/metrics.md).

BARN (Perille et al., 2020) describes a world by five numbers measured on the
cells of the path that its robot should take; here they are measured in
metres at points at most :data:`SAMPLE_SPACING` m apart along the leader's
planned path (:func:`~dfcoa_opt.planning.postprocess.sample_path`), by
casting :data:`RAYS` rays (every 22.5 degrees) on the world's occupancy grid,
each up to :data:`RAY_RANGE` m, and stopping at the map's edge (the world ends
there; the leader's planner never leaves it):

- :func:`clearance_along`: distance to the closest static obstacle (exact shapes);
- :func:`visibility`: the mean ray length;
- :func:`dispersion`: how often consecutive rays switch between hitting
  something within :data:`DISPERSION_RADIUS` m and not;
- :func:`characteristic_dimension`: the narrowest width through the point, the
  smallest sum of two opposite rays;
- :func:`tortuosity`: path length over the straight distance.

Three more are for formations and moving obstacles:

- :func:`narrowest_passage_ratio`: the smallest characteristic dimension along
  the path over the formation's width (:func:`dfcoa_opt.scenario.formation.team_width`);
- :func:`narrow_passages`: stretches of the path narrower than the formation;
- :func:`moving_crossings`: how often moving discs cross the path while the
  leader would travel it.

:func:`difficulty_index` combines them, each normalised to [0, 1] by fixed
reference scales chosen before any result was seen (:data:`INDEX_SCALES`).
:func:`world_difficulty` gives all of them for a scenario, as the ``world_*``
keys every result row carries.
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Mapping
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.core.polygons import segments_cross
from dfcoa_opt.planning.postprocess import path_length, sample_path
from dfcoa_opt.scenario.formation import team_width
from dfcoa_opt.scenario.scenario import Scenario
from dfcoa_opt.world.dynamic import DynamicObstacles
from dfcoa_opt.world.grid import OccupancyGrid
from dfcoa_opt.world.lidar_kernel import cast_grid

FloatArray = NDArray[np.float64]

#: Rays cast around each path sample, evenly spaced (an even number: opposite pairs).
RAYS = 16
#: Longest ray, m.
RAY_RANGE = 10.0
#: A ray shorter than this hits something (dispersion), m.
DISPERSION_RADIUS = 3.0
#: Distance between two path samples, m.
SAMPLE_SPACING = 0.1

#: Each metric's reference scale and direction in :func:`difficulty_index`: ``(key, scale,
#: harder_when)``; a value normalises to ``clip(v / scale, 0, 1)`` when larger is harder,
#: else ``1 - clip(v / scale, 0, 1)`` (tortuosity: ``clip((v - 1) / scale, 0, 1)``).
INDEX_SCALES = (
    ("world_clearance", 2.0, "smaller"),                # m: 2 m from every obstacle is open
    ("world_visibility", RAY_RANGE, "smaller"),         # m: the ray range
    ("world_dispersion", 4.0, "larger"),                # switches among 16 rays
    ("world_characteristic_dimension", 8.0, "smaller"),  # m: three V widths
    ("world_tortuosity", 1.0, "larger"),                # a path twice the straight line
    ("world_narrowest_ratio", 1.0, "smaller"),          # the formation fits head-on
    ("world_narrow_passages", 4.0, "larger"),           # passages narrower than the team
    ("world_crossings", 10.0, "larger"),                # moving discs across the path
)


@numba.njit(cache=True)
def _rays_kernel(points, ux, uy, reach, dist, ox, oy, h, x1, y1):  # pragma: no cover - numba
    out = np.empty((points.shape[0], ux.shape[0]))
    for i in range(points.shape[0]):
        px, py = points[i, 0], points[i, 1]
        for k in range(ux.shape[0]):
            edge = reach
            if ux[k] > 0.0:
                edge = min(edge, (x1 - px) / ux[k])
            elif ux[k] < 0.0:
                edge = min(edge, (ox - px) / ux[k])
            if uy[k] > 0.0:
                edge = min(edge, (y1 - py) / uy[k])
            elif uy[k] < 0.0:
                edge = min(edge, (oy - py) / uy[k])
            edge = max(edge, 0.0)
            out[i, k] = min(cast_grid(px, py, ux[k], uy[k], edge, dist, ox, oy, h, True), edge)
    return out


def ray_lengths(grid: OccupancyGrid, points: FloatArray, rays: int = RAYS,
                reach: float = RAY_RANGE) -> FloatArray:
    """Length of ``rays`` rays from each point to the first occupied cell or the map's edge.

    Ray ``k`` points at ``2 pi k / rays`` (counter-clockwise from +x). Exact
    against the occupied cell squares (the LiDAR's ray walk,
    :func:`~dfcoa_opt.world.lidar_kernel.cast_grid`), capped at ``reach``.

    Args:
        grid: The world's occupancy grid.
        points: ``(S, 2)`` m.
        rays: Number of rays.
        reach: Longest ray, m.

    Returns:
        ``(S, rays)`` lengths in m; 0 from a point inside an occupied cell.
    """
    a = 2.0 * np.pi * np.arange(rays) / rays
    x0, x1, y0, y1 = grid.extent
    return _rays_kernel(np.ascontiguousarray(points, dtype=float), np.cos(a), np.sin(a),
                        float(reach), grid.distance_field, x0, y0, grid.cell_size, x1, y1)


def clearance_along(scenario: Scenario, points: FloatArray) -> FloatArray:
    """Distance from each point to the closest static obstacle (exact shapes), ``(S,)`` m.

    BARN's "distance to closest obstacle", capped at :data:`RAY_RANGE`.
    """
    return scenario.world.clearance(points, RAY_RANGE)


def visibility(lengths: FloatArray) -> FloatArray:
    """BARN's average visibility: each point's mean ray length, ``(S,)`` m."""
    return lengths.mean(axis=1)


def dispersion(lengths: FloatArray, radius: float = DISPERSION_RADIUS) -> FloatArray:
    """BARN's dispersion: switches between hit and open around each point's rays, ``(S,)``.

    A ray *hits* when it is shorter than ``radius``; the count runs around the
    circle (the last ray is next to the first), so it is even.
    """
    hit = lengths < radius
    return np.count_nonzero(hit != np.roll(hit, -1, axis=1), axis=1).astype(float)


def characteristic_dimension(lengths: FloatArray) -> FloatArray:
    """BARN's characteristic dimension: the narrowest width through each point, ``(S,)`` m.

    The smallest, over the ``rays / 2`` axes, of the two opposite rays' sum.
    """
    half = lengths.shape[1] // 2
    return (lengths[:, :half] + lengths[:, half:2 * half]).min(axis=1)


def tortuosity(path: FloatArray) -> float:
    """Path length over the straight distance from its start to its end (1 = straight)."""
    p = np.asarray(path, dtype=float).reshape(-1, 2)
    chord = float(np.hypot(*(p[-1] - p[0])))
    return path_length(p) / chord if chord > 0 else 1.0


def narrowest_passage_ratio(width: FloatArray, formation_width: float) -> float:
    """The smallest characteristic dimension along the path over the formation's width."""
    return float(np.min(width)) / formation_width


def narrow_passages(width: FloatArray, formation_width: float) -> int:
    """Stretches of consecutive path samples narrower than the formation (each counts once)."""
    narrow = np.concatenate(([False], np.asarray(width) < formation_width))
    return int(np.count_nonzero(narrow[1:] & ~narrow[:-1]))


def moving_crossings(dynamic: DynamicObstacles, path: FloatArray, t_end: float,
                     dt: float) -> int:
    """Times a moving disc's centre crosses the path during ``[0, t_end]``.

    The discs' centres are sampled every ``dt`` s; a crossing is a proper
    intersection of a disc's step (centre at ``t`` to centre at ``t + dt``)
    with a segment of the path polyline.

    Args:
        dynamic: The moving discs.
        path: ``(P, 2)`` polyline, m.
        t_end: End of the window, s (the leader's travel time along the path).
        dt: Sampling step, s.
    """
    if len(dynamic) == 0 or t_end <= 0:
        return 0
    times = np.arange(0.0, t_end + 0.5 * dt, dt)
    pos, _ = dynamic.state(times[:, None])            # (K, M, 2)
    a, b = pos[:-1].reshape(-1, 1, 2), pos[1:].reshape(-1, 1, 2)
    p = np.asarray(path, dtype=float).reshape(-1, 2)
    c, d = p[None, :-1], p[None, 1:]
    return int(np.count_nonzero(segments_cross(a, b, c, d)))


def difficulty_index(values: Mapping[str, Any]) -> float:
    """The mean of the metrics of :data:`INDEX_SCALES`, each normalised to [0, 1] (1 = hard)."""
    parts = []
    for key, scale, harder in INDEX_SCALES:
        v = float(values[key])
        if key == "world_tortuosity":
            v -= 1.0
        x = min(max(v / scale, 0.0), 1.0)
        parts.append(x if harder == "larger" else 1.0 - x)
    return float(np.mean(parts))


#: The keys of :func:`world_difficulty`, in its order.
WORLD_KEYS = ("world_clearance", "world_visibility", "world_dispersion",
              "world_characteristic_dimension", "world_tortuosity", "world_narrowest_ratio",
              "world_narrow_passages", "world_crossings", "world_difficulty",
              "world_path_length", "world_reference_time")

_CACHE: weakref.WeakKeyDictionary[Scenario, dict[str, float]] = weakref.WeakKeyDictionary()


def world_difficulty(scenario: Scenario) -> dict[str, float]:
    """Every difficulty metric of a scenario's world, along its leader's planned path.

    Keys: ``world_clearance``, ``world_visibility``, ``world_dispersion``,
    ``world_characteristic_dimension`` (means over the path samples, m or a
    count), ``world_tortuosity``, ``world_narrowest_ratio``,
    ``world_narrow_passages``, ``world_crossings`` and ``world_difficulty``
    (:func:`difficulty_index`); and, outside the index, ``world_path_length``
    (m) and ``world_reference_time`` (s: the path at the leader's speed, the
    BARN score's optimal time). Kept per scenario object: the runs of a batch
    that share a world measure it once.
    """
    if scenario in _CACHE:
        return dict(_CACHE[scenario])
    spec = scenario.spec
    path = scenario.leader_path
    points = sample_path(path, SAMPLE_SPACING)
    lengths = ray_lengths(scenario.world.grid, points)
    width = characteristic_dimension(lengths)
    team = team_width(scenario.offsets, spec.robots.radius)
    length = path_length(path)
    out = {
        "world_clearance": float(clearance_along(scenario, points).mean()),
        "world_visibility": float(visibility(lengths).mean()),
        "world_dispersion": float(dispersion(lengths).mean()),
        "world_characteristic_dimension": float(width.mean()),
        "world_tortuosity": tortuosity(path),
        "world_narrowest_ratio": narrowest_passage_ratio(width, team),
        "world_narrow_passages": float(narrow_passages(width, team)),
        "world_crossings": float(moving_crossings(scenario.world.dynamic, path,
                                                  length / spec.leader.speed, spec.dt)),
    }
    out["world_difficulty"] = difficulty_index(out)
    out["world_path_length"] = length
    out["world_reference_time"] = length / spec.leader.speed
    out = {k: (v if math.isfinite(v) else math.nan) for k, v in out.items()}
    _CACHE[scenario] = out
    return dict(out)
