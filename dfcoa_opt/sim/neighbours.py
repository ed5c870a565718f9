"""Neighbour queries: the K nearest other robots within a radius.

Small teams use one vectorised distance matrix; larger ones a
``scipy.spatial.cKDTree``. Both give the same table (a test checks it); the
switch-over size was chosen by measurement (``benchmarks/``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from dfcoa_opt.geometry import pairwise_distances

#: Teams up to this size use the dense distance matrix.
DENSE_MAX = 48


def neighbour_table(points: NDArray[np.float64], radius: float,
                    k_max: int) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
    """The ``k_max`` nearest other points within ``radius`` of each point.

    Args:
        points: ``(N, 2)`` positions, m.
        radius: Communication radius, m (may be inf).
        k_max: Most neighbours per point.

    Returns:
        ``(index (N, K), distance (N, K))`` with ``K = min(k_max, N - 1)``,
        sorted by distance (ties by index), padded with -1 / inf.
    """
    idx, dist, _ = _table(points, radius, k_max)
    return idx, dist


def _table(points: NDArray[np.float64], radius: float,
           k_max: int) -> tuple[NDArray[np.intp], NDArray[np.float64], cKDTree | None]:
    """:func:`neighbour_table` and the k-d tree it built (None on the dense path)."""
    n = len(points)
    k = max(min(k_max, n - 1), 0)
    if k == 0:
        return np.full((n, 0), -1, dtype=np.intp), np.zeros((n, 0)), None
    tree = None
    if n <= DENSE_MAX:
        d = pairwise_distances(points)
        order = np.argsort(d, axis=1, kind="stable")[:, :k]
        dist = np.take_along_axis(d, order, axis=1)
    else:
        tree = cKDTree(points)
        ub = radius * (1 + 1e-12) if np.isfinite(radius) else np.inf
        dist, order = tree.query(points, k=k + 1, distance_upper_bound=ub)
        dist, order = dist[:, 1:], order[:, 1:]
        # the tree returns self first unless a duplicate point ties; drop self explicitly
        self_hit = order == np.arange(n)[:, None]
        if self_hit.any():  # rare: coincident points; recompute those rows densely
            dist, order = _fix_self(points, dist, order, k)
    inside = dist <= radius
    idx = np.where(inside, order, -1).astype(np.intp)
    return idx, np.where(inside, dist, np.inf), tree


def _fix_self(points, dist, order, k):  # pragma: no cover - coincident points only
    n = len(points)
    for i in np.nonzero((order == np.arange(n)[:, None]).any(1))[0]:
        d = np.hypot(*(points - points[i]).T)
        d[i] = np.inf
        o = np.argsort(d, kind="stable")[:k]
        order[i], dist[i] = o, d[o]
    return dist, order


@dataclass(frozen=True)
class Proximity:
    """Everything the simulator needs about robot-robot distances at one step.

    Attributes:
        index: ``(N, K)`` neighbour indices (-1 padded), nearest first.
        distance: ``(N, K)`` their distances, m (inf padded).
        min_distance: Smallest centre distance between two robots, m (inf if N < 2).
        contact_keys: ``(P,)`` int64 keys ``i * N + j`` (i < j) of pairs closer
            than the contact distance.
    """

    index: NDArray[np.intp]
    distance: NDArray[np.float64]
    min_distance: float
    contact_keys: NDArray[np.int64]


def proximity(points: NDArray[np.float64], radius: float, k_max: int,
              contact: float) -> Proximity:
    """Neighbour table, closest pair distance and contacting pairs in one pass.

    Args:
        points: ``(N, 2)`` robot positions, m.
        radius: Communication radius, m.
        k_max: Most neighbours per robot.
        contact: Pairs with centre distance below this (m) are in contact.
    """
    n = len(points)
    if n < 2:
        return Proximity(np.full((n, 0), -1, dtype=np.intp), np.zeros((n, 0)), np.inf,
                         np.zeros(0, dtype=np.int64))
    if n <= DENSE_MAX:
        d = pairwise_distances(points)
        i, j = np.nonzero(np.triu(d < contact, 1))
        keys = (i * n + j).astype(np.int64)
        k = min(k_max, n - 1)
        order = np.argsort(d, axis=1, kind="stable")[:, :k]
        dist = np.take_along_axis(d, order, axis=1)
        inside = dist <= radius
        return Proximity(np.where(inside, order, -1).astype(np.intp),
                         np.where(inside, dist, np.inf), float(d.min()), keys)
    idx, dist, tree = _table(points, radius, k_max)
    if tree is None:  # k_max = 0
        tree = cKDTree(points)
    # the closest pair: from the table when any robot has a neighbour in range (a robot
    # without one is farther than that from everyone), else from an unbounded query
    nearest = dist[:, 0] if dist.shape[1] and np.isfinite(dist[:, 0]).any() else \
        tree.query(points, k=2)[0][:, 1]
    pairs = tree.query_pairs(contact, output_type="ndarray")
    pairs = pairs[np.linalg.norm(points[pairs[:, 0]] - points[pairs[:, 1]], axis=1) < contact]
    keys = (pairs.min(1).astype(np.int64) * n + pairs.max(1)).astype(np.int64)
    return Proximity(idx, dist, float(nearest.min()), np.sort(keys))
