"""Neighbour queries: the K nearest other robots within a radius.

Small teams use one vectorised distance matrix (:func:`proximity`: one
compiled all-pairs loop); larger ones a ``scipy.spatial.cKDTree``. Both give
the same table (a test checks it); the switch-over sizes were chosen by
measurement (``benchmarks/``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from dfcoa_opt.core.geometry import pairwise_distances

#: Teams up to this size use the dense distance matrix in :func:`neighbour_table`.
DENSE_MAX = 48
#: Teams up to this size get :func:`proximity` from one compiled all-pairs loop, larger
#: ones from k-d tree queries. Measured (2026-11-25, median of 200): the loop 14 / 42 /
#: 87 / 307 us at N = 49 / 100 / 150 / 250, the tree path 86 / 119 / 164 / 311 us.
KERNEL_MAX = 200


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
    if n <= KERNEL_MAX:
        idx, dist, closest, keys = _dense_proximity(np.ascontiguousarray(points, dtype=float),
                                                    float(radius), min(k_max, n - 1),
                                                    float(contact))
        return Proximity(idx, dist, closest, keys)
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


@numba.njit(cache=True)
def _dense_proximity(points, radius, k, contact):  # pragma: no cover - numba
    """:func:`proximity` of a small team in one loop (same numbers as the dense numpy path)."""
    n = points.shape[0]
    idx = np.full((n, k), -1, dtype=np.intp)
    dist = np.full((n, k), np.inf)
    keys = np.empty(n * (n - 1) // 2, dtype=np.int64)
    closest, n_keys = _proximity_block(points, 0, n, radius, k, contact, idx, dist, keys, 0)
    return idx, dist, closest, keys[:n_keys]


@numba.njit(cache=True)
def _proximity_block(points, start, n, radius, k, contact, idx, dist, keys,
                     n_keys):  # pragma: no cover - numba
    """Rows ``start .. start + n`` of ``points`` as one team: :func:`proximity`'s loop.

    Distances are ``sqrt(dx * dx + dy * dy)`` as in
    :func:`~dfcoa_opt.core.geometry.pairwise_distances`; each row keeps its ``k``
    nearest by insertion (ties by index, as a stable argsort). Indices and
    contact keys ``i * n + j`` are within the team; ``idx``/``dist`` (filled
    with -1 / inf) get the team's rows, ``keys`` its keys from ``n_keys`` on.

    Returns:
        ``(closest centre distance of the team, n_keys after its keys)``.
    """
    closest = np.inf
    row = np.empty(n)
    for i in range(n):
        for j in range(n):
            if j == i:
                row[j] = np.inf
                continue
            dx = points[start + i, 0] - points[start + j, 0]
            dy = points[start + i, 1] - points[start + j, 1]
            row[j] = math.sqrt(dx * dx + dy * dy)
            if j > i and row[j] < contact:
                keys[n_keys] = i * n + j
                n_keys += 1
        filled = 0
        r = start + i
        for j in range(n):
            d = row[j]
            if d < closest:
                closest = d
            if k == 0 or (filled == k and not d < dist[r, k - 1]):
                continue
            pos = filled if filled < k else k - 1
            while pos > 0 and d < dist[r, pos - 1]:  # strict: equal distances keep index order
                dist[r, pos] = dist[r, pos - 1]
                idx[r, pos] = idx[r, pos - 1]
                pos -= 1
            dist[r, pos] = d
            idx[r, pos] = j
            if filled < k:
                filled += 1
        for m in range(k):
            if not dist[r, m] <= radius:
                idx[r, m] = -1
                dist[r, m] = np.inf
    return closest, n_keys


@dataclass(frozen=True)
class BatchProximity:
    """:class:`Proximity` of E teams of N robots at once (team e = rows ``e*N .. e*N+N-1``).

    Attributes:
        index: ``(E*N, K)`` neighbour indices within each team (-1 padded).
        distance: ``(E*N, K)`` their distances, m (inf padded).
        min_distance: ``(E,)`` each team's smallest centre distance, m.
        contact_keys: Every team's contact keys (``i * N + j``, i < j), concatenated.
        key_ptr: ``(E + 1,)`` team e's keys are ``contact_keys[key_ptr[e]:key_ptr[e + 1]]``.
    """

    index: NDArray[np.intp]
    distance: NDArray[np.float64]
    min_distance: NDArray[np.float64]
    contact_keys: NDArray[np.int64]
    key_ptr: NDArray[np.int64]

    def team(self, e: int, n: int) -> Proximity:
        """Team ``e``'s :class:`Proximity` (views)."""
        rows = slice(e * n, (e + 1) * n)
        return Proximity(self.index[rows], self.distance[rows], float(self.min_distance[e]),
                         self.contact_keys[self.key_ptr[e]:self.key_ptr[e + 1]])


def batch_proximity(points: NDArray[np.float64], n: int, radius: float, k_max: int,
                    contact: float) -> BatchProximity:
    """:func:`proximity` of every team of ``n`` consecutive rows, the same numbers team by team.

    Teams up to :data:`KERNEL_MAX` go through one compiled call for the whole
    batch; larger ones through :func:`proximity`, one team at a time.

    Args:
        points: ``(E*N, 2)`` robot positions, m, team after team (E >= 1).
        n: Robots per team.
        radius: Communication radius, m.
        k_max: Most neighbours per robot.
        contact: Pairs with centre distance below this (m) are in contact.
    """
    e = len(points) // n if n else 0
    if n < 2 or n > KERNEL_MAX:
        teams = [proximity(points[i * n:(i + 1) * n], radius, k_max, contact) for i in range(e)]
        ptr = np.zeros(e + 1, dtype=np.int64)
        np.cumsum([len(t.contact_keys) for t in teams], out=ptr[1:])
        return BatchProximity(np.concatenate([t.index for t in teams]),
                              np.concatenate([t.distance for t in teams]),
                              np.array([t.min_distance for t in teams], dtype=float),
                              np.concatenate([t.contact_keys for t in teams]).astype(np.int64),
                              ptr)
    idx, dist, closest, keys, ptr = _batch_proximity(
        np.ascontiguousarray(points, dtype=float), n, float(radius), min(k_max, n - 1),
        float(contact))
    return BatchProximity(idx, dist, closest, keys, ptr)


@numba.njit(cache=True)
def _batch_proximity(points, n, radius, k, contact):  # pragma: no cover - numba
    """:func:`batch_proximity`'s compiled path: :func:`_proximity_block` team by team."""
    e = points.shape[0] // n
    idx = np.full((e * n, k), -1, dtype=np.intp)
    dist = np.full((e * n, k), np.inf)
    keys = np.empty(e * (n * (n - 1) // 2), dtype=np.int64)
    closest = np.empty(e)
    ptr = np.zeros(e + 1, dtype=np.int64)
    n_keys = 0
    for t in range(e):
        closest[t], n_keys = _proximity_block(points, t * n, n, radius, k, contact, idx, dist,
                                              keys, n_keys)
        ptr[t + 1] = n_keys
    return idx, dist, closest, keys[:n_keys], ptr


def new_contacts(prev_keys: NDArray[np.int64], prev_ptr: NDArray[np.int64],
                 keys: NDArray[np.int64], ptr: NDArray[np.int64]) -> NDArray[np.int64]:
    """How many of each team's contact keys are not among its previous ones.

    Args:
        prev_keys: The teams' sorted keys of the previous step, concatenated.
        prev_ptr: ``(E + 1,)`` their offsets.
        keys: The sorted keys of this step, concatenated.
        ptr: ``(E + 1,)`` their offsets.

    Returns:
        ``(E,)`` counts: the robot pairs whose contact began at this step.
    """
    return _new_contacts(prev_keys, prev_ptr, keys, ptr)


@numba.njit(cache=True)
def _new_contacts(prev_keys, prev_ptr, keys, ptr):  # pragma: no cover - numba
    """:func:`new_contacts` by merging each team's two sorted lists."""
    e = ptr.shape[0] - 1
    out = np.zeros(e, dtype=np.int64)
    for t in range(e):
        i, stop = prev_ptr[t], prev_ptr[t + 1]
        for q in range(ptr[t], ptr[t + 1]):
            while i < stop and prev_keys[i] < keys[q]:
                i += 1
            if not (i < stop and prev_keys[i] == keys[q]):
                out[t] += 1
    return out


def gather(index: NDArray[np.intp], pose: NDArray[np.float64],
           velocity: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64],
                                                   NDArray[np.float64]]:
    """The neighbours' broadcast positions, velocities and headings, 0 in padded slots.

    The values are copies of the rows ``pose[index]`` and ``velocity[index]`` (one
    compiled pass instead of a gather and a mask per array).

    Args:
        index: ``(N, K)`` neighbour indices, -1 where padded.
        pose: ``(N, 3)`` broadcast poses (x m, y m, theta rad).
        velocity: ``(N, 2)`` world velocities, m/s.

    Returns:
        ``(position (N, K, 2) m, velocity (N, K, 2) m/s, heading (N, K) rad)``.
    """
    return _gather(np.ascontiguousarray(index, dtype=np.intp),
                   np.ascontiguousarray(pose, dtype=float),
                   np.ascontiguousarray(velocity, dtype=float))


@numba.njit(cache=True)
def _gather(index, pose, velocity):  # pragma: no cover - numba
    """:func:`gather`'s loop."""
    n, k = index.shape
    position = np.zeros((n, k, 2))
    vel = np.zeros((n, k, 2))
    heading = np.zeros((n, k))
    for i in range(n):
        for j in range(k):
            m = index[i, j]
            if m >= 0:
                position[i, j, 0] = pose[m, 0]
                position[i, j, 1] = pose[m, 1]
                vel[i, j, 0] = velocity[m, 0]
                vel[i, j, 1] = velocity[m, 1]
                heading[i, j] = pose[m, 2]
    return position, vel, heading
