"""Safe discrete-time mode: half-planes that forbid overlap at the next sampling instant.

ORCA (and RVO2) guarantee collision freedom in continuous time only while every
robot's linear program is feasible; when it is not, the least-violation
velocity may overlap (RVO2's Circle-250 at dt = 0.25 s comes to 2.37 m between
centres, 3.0 m being contact). This mode adds, for every pair that could touch
within one step, a linear constraint that keeps them apart at ``t + dt``
whatever the other robot does within its own constraint, and keeps these
constraints *hard* (never relaxed by the least-violation fallback).

Pair ``i, j`` at distance ``d`` with combined radius ``R`` and unit normal
``n = (p_i - p_j) / d``: since ``||x|| >= n . x``,

    ||p_i' - p_j'|| >= d + dt n . (v_i - v_j) >= R   if   n . v_i >= (R - d) / (2 dt)

and robot ``j`` takes the mirrored half (responsibility 1/2). For a static
segment with nearest point ``q`` and ``n = (p - q) / ||p - q||``, the whole
segment lies in ``n . (x - q) <= 0`` (projection onto a convex set), so
``n . v >= (r - ||p - q||) / dt`` keeps the robot off it (full
responsibility). While nothing overlaps, every right-hand side is <= 0, so
``v = 0`` satisfies all of them: the hard set is always feasible, and by
induction no overlap ever appears at a sampling instant. Pairs are found by a
radius query that is symmetric (all robots within ``R + 2 v_max dt``), unlike
the k-nearest ORCA neighbours, so both robots of a pair always apply their half.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from comparisons.orca.neighbours import knn_within
from dfcoa_opt.core.geometry import closest_point_on_segment, take_rows

FloatArray = NDArray[np.float64]
#: Most robots within one step's reach of a robot; disc packing allows at most
#: about 20 at the default reach, so hitting it means the input overlaps.
MAX_PAIRS = 32


def halfplane_lines(normal: FloatArray, bound: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``n . v >= c`` as :mod:`comparisons.orca.lp` lines: point ``c n``, direction ``(n_y, -n_x)``.

    Args:
        normal: ``(..., 2)`` unit normals.
        bound: ``(...)`` right-hand sides ``c``, m/s.

    Returns:
        ``(points, directions)``, each ``(..., 2)``.
    """
    points = bound[..., None] * normal
    directions = np.stack((normal[..., 1], -normal[..., 0]), axis=-1)
    return points, directions


def robot_safety_lines(pos: FloatArray, radius: FloatArray, max_speed: FloatArray, dt: float
                       ) -> tuple[FloatArray, FloatArray, NDArray[np.int64]]:
    """Hard half-planes keeping every pair of robots apart at the next step.

    Args:
        pos: ``(N, 2)`` positions, m.
        radius: ``(N,)`` radii, m.
        max_speed: ``(N,)`` speed limits, m/s.
        dt: Step, s.

    Returns:
        ``(points (N, K, 2), directions (N, K, 2), count (N,))`` with
        ``K = MAX_PAIRS``, nearest pair first.

    Raises:
        ValueError: A robot has more than ``MAX_PAIRS`` robots within reach
            (only possible when robots already overlap).
    """
    n = len(pos)
    reach = 2.0 * float(np.max(radius)) + 2.0 * float(np.max(max_speed)) * dt
    idx, count = knn_within(pos, MAX_PAIRS, reach)
    if n and count.max(initial=0) >= MAX_PAIRS:
        raise ValueError(f"more than {MAX_PAIRS - 1} robots within {reach:.3g} m of one robot; "
                         "the safe mode needs a non-overlapping start")
    rel = pos[:, None, :] - np.take(pos, idx, axis=0)  # (N, K, 2), from the neighbour to me
    dist = np.linalg.norm(rel, axis=-1)
    used = np.arange(MAX_PAIRS)[None, :] < count[:, None]
    safe_dist = np.where(used & (dist > 0.0), dist, 1.0)
    normal = np.where(used[..., None], rel / safe_dist[..., None], np.array([1.0, 0.0]))
    need = radius[:, None] + np.take(radius, idx)
    bound = np.where(used, (need - dist) / (2.0 * dt), -np.inf)
    points, directions = halfplane_lines(normal, np.where(used, bound, 0.0))
    return points, directions, count


def segment_safety_lines(pos: FloatArray, radius: FloatArray, max_speed: FloatArray, dt: float,
                         segments: FloatArray) -> tuple[FloatArray, FloatArray, NDArray[np.int64]]:
    """Hard half-planes keeping every robot off static segments at the next step.

    Args:
        pos: ``(N, 2)`` positions, m.
        radius: ``(N,)`` radii, m.
        max_speed: ``(N,)`` speed limits, m/s.
        dt: Step, s.
        segments: ``(E, 2, 2)`` segment end points (polygon edges), m; or
            ``(N, E, 2, 2)``, each robot's own (a batch of runs in different
            worlds, padded with segments out of reach).

    Returns:
        ``(points (N, E', 2), directions (N, E', 2), count (N,))``, the segments
        within one step's reach of each robot first (nearest first).
    """
    n = len(pos)
    if segments.shape[-3] == 0:
        return np.zeros((n, 0, 2)), np.zeros((n, 0, 2)), np.zeros(n, np.int64)
    q = closest_point_on_segment(pos[:, None, :], segments[..., 0, :],
                                 segments[..., 1, :])  # (N, E, 2)
    rel = pos[:, None, :] - q
    dist = np.linalg.norm(rel, axis=-1)
    reach = radius + max_speed * dt
    near = dist < reach[:, None]
    order = np.argsort(np.where(near, dist, np.inf), axis=1, kind="stable")
    count = near.sum(axis=1)
    width = max(int(count.max(initial=0)), 1)
    order = order[:, :width]
    dist, rel = take_rows(dist, order), take_rows(rel, order)
    used = np.arange(width)[None, :] < count[:, None]
    normal = rel / np.where(dist > 0.0, dist, 1.0)[..., None]
    bound = np.where(used, (radius[:, None] - dist) / dt, 0.0)
    points, directions = halfplane_lines(normal, bound)
    return points, directions, count


def scale_into(vel: FloatArray, points: FloatArray, directions: FloatArray,
               count: NDArray[np.int64]) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Shrink each velocity towards 0 until it satisfies its hard lines.

    The safe-mode lines all contain ``v = 0`` while nothing overlaps, so the
    admissible scales of ``v`` form an interval ``[0, s_max]``; the largest is
    taken. This guards the guarantee against a degenerate linear program (for
    example a robot boxed in by touching neighbours, whose lines all pass
    through the origin and leave only ``v = 0``), where the least-violation
    fallback may not keep hard lines exactly. A line that excludes ``v = 0``
    (the robots already overlap) cannot be met by shrinking and sets no scale.

    Args:
        vel: ``(N, 2)`` candidate velocities, m/s.
        points: ``(N, H, 2)`` line points, m/s.
        directions: ``(N, H, 2)`` unit directions (allowed side on the left).
        count: ``(N,)`` lines used per robot.

    Returns:
        ``(velocities (N, 2), scaled (N,) bool)``.
    """
    h = points.shape[1]
    used = np.arange(h)[None, :] < count[:, None]
    # line k: det(d, p - s v) <= 0  <=>  s * det(d, v) >= det(d, p) =: c (c <= 0 at the origin)
    c = directions[..., 0] * points[..., 1] - directions[..., 1] * points[..., 0]
    a = directions[..., 0] * vel[:, None, 1] - directions[..., 1] * vel[:, None, 0]
    bad = used & (a < c)  # violated at s = 1; then a < c <= 0 and s <= c / a < 1
    # a line that excludes the origin (c > 0: the robots already overlap) cannot be
    # met by shrinking v, so it sets no scale (a may then be 0)
    shrink = bad & (a < 0.0)
    ratio = np.divide(c, a, out=np.ones_like(a), where=shrink)
    s = np.clip(ratio.min(axis=1, initial=1.0), 0.0, 1.0)
    return vel * s[:, None], bad.any(axis=1)
