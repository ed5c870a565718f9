"""Obstacle rings and RVO2's obstacle k-d tree for :mod:`comparisons.orca.obstacles`.

:func:`prepare_obstacles` turns polygons (counter-clockwise, or two-vertex
segments seen from both sides) into vertex rings with unit edge directions and
convexity flags, and rebuilds RVO2's obstacle tree in single precision,
splitting edges exactly where RVO2 does, so that the rings and the visiting
order of equidistant edges are RVO2's.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from comparisons.orca.lp import EPSILON

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@dataclass(frozen=True)
class ObstacleSet:
    """Obstacle vertex rings and RVO2's obstacle k-d tree, as flat arrays.

    Attributes:
        points: ``(V, 2)`` vertex positions, m.
        next: ``(V,)`` index of the next vertex of the ring (the edge ``k -> next[k]``).
        prev: ``(V,)`` index of the previous vertex of the ring.
        directions: ``(V, 2)`` unit direction of edge ``k`` (a split piece keeps its
            parent's direction).
        convex: ``(V,)`` True when vertex ``k`` is convex (always for segments and
            for vertices made by splitting).
        tree: ``(V, 3)`` k-d tree nodes ``(edge, left child, right child)``, -1 for
            none; node 0 is the root (an empty set has no nodes).
        depth: Depth of the tree (nodes on the longest root-to-leaf path).
        bbox: ``(4,)`` ``(x_min, y_min, x_max, y_max)`` of all vertices, m.
    """

    points: FloatArray
    next: IntArray
    prev: IntArray
    directions: FloatArray
    convex: NDArray[np.bool_]
    tree: IntArray
    depth: int
    bbox: FloatArray

    @property
    def n_edges(self) -> int:
        """Number of directed edges (= vertices, after splitting)."""
        return len(self.points)


def _left_of(a, b, c):
    """RVO2's ``leftOf(a, b, c) = det(a - c, b - a)`` (> 0: ``c`` left of ``a -> b``)."""
    return (a[..., 0] - c[..., 0]) * (b[..., 1] - a[..., 1]) - \
        (a[..., 1] - c[..., 1]) * (b[..., 0] - a[..., 0])


@numba.njit(cache=True)
def _side_counts(p1, p2, eps):  # pragma: no cover - numba
    """Per candidate splitter (edge ``i``), the other edges left or crossing / right or crossing.

    In float32, with :func:`_left_of`'s operations: edge ``j`` is left of the
    line of edge ``i`` when both its end points are (``>= -eps``), right when
    both are (``<= eps``) and it is not left, crossing otherwise.
    """
    n = p1.shape[0]
    n_left = np.zeros(n, np.int64)
    n_right = np.zeros(n, np.int64)
    for i in range(n):
        ax, ay, bx, by = p1[i, 0], p1[i, 1], p2[i, 0], p2[i, 1]
        for j in range(n):
            if j == i:
                continue
            s1 = (ax - p1[j, 0]) * (by - ay) - (ay - p1[j, 1]) * (bx - ax)
            s2 = (ax - p2[j, 0]) * (by - ay) - (ay - p2[j, 1]) * (bx - ax)
            left = s1 >= -eps and s2 >= -eps
            right = not left and s1 <= eps and s2 <= eps
            if not right:
                n_left[i] += 1
            if not left:
                n_right[i] += 1
    return n_left, n_right


def _build_tree(pts32, nxt, prv, dirs, convex, points):
    """RVO2's obstacle-tree construction (single precision), splitting edges in place.

    The lists (``pts32`` float32 vertices, ``points`` their float64 copies, ring
    links, directions, convexity) are extended and relinked as edges are split.
    Returns the node list ``[edge, left, right]`` and the tree depth.
    """
    eps = np.float32(EPSILON)
    nodes: list[list[int]] = []
    depth = 0
    # depth-first, left before right, as RVO2's recursion (the order of the new vertices)
    todo: list[tuple[list[int], int, int, int]] = [(list(range(len(pts32))), -1, 0, 1)]
    while todo:
        members, parent, side, level = todo.pop()
        if not members:
            continue
        p1 = np.array([pts32[j] for j in members], np.float32)
        p2 = np.array([pts32[nxt[j]] for j in members], np.float32)
        n_left, n_right = _side_counts(p1, p2, eps)
        big, small = np.maximum(n_left, n_right), np.minimum(n_left, n_right)
        # splitter: fewest edges on the larger side, then on the smaller; first such
        best = int(np.lexsort((small, big))[0])
        # side of every edge's end points w.r.t. the splitter
        s1 = _left_of(p1[best], p2[best], p1)
        s2 = _left_of(p1[best], p2[best], p2)
        left = (s1 >= -eps) & (s2 >= -eps)
        right = ~left & (s1 <= eps) & (s2 <= eps)
        i = members[best]
        a, b = pts32[i], pts32[nxt[i]]
        lefts, rights = [], []
        for jj, j in enumerate(members):
            if jj == best:
                continue
            if left[jj]:
                lefts.append(j)
            elif right[jj]:
                rights.append(j)
            else:  # edge j crosses the splitter's line: cut it there
                j2 = nxt[j]
                ab = b - a
                t = (ab[0] * (pts32[j][1] - a[1]) - ab[1] * (pts32[j][0] - a[0])) / \
                    (ab[0] * (pts32[j][1] - pts32[j2][1]) - ab[1] * (pts32[j][0] - pts32[j2][0]))
                new = len(pts32)
                pts32.append(pts32[j] + t * (pts32[j2] - pts32[j]))
                points.append(pts32[-1].astype(np.float64))
                dirs.append(dirs[j])
                convex.append(True)
                nxt.append(j2)
                prv.append(j)
                nxt[j] = new
                prv[j2] = new
                if s1[jj] > 0.0:
                    lefts.append(j)
                    rights.append(new)
                else:
                    rights.append(j)
                    lefts.append(new)
        node = len(nodes)
        nodes.append([i, -1, -1])
        if parent >= 0:
            nodes[parent][side] = node
        depth = max(depth, level)
        todo.append((rights, node, 2, level + 1))
        todo.append((lefts, node, 1, level + 1))
    return nodes, depth


def prepare_obstacles(polygons: Sequence[ArrayLike]) -> ObstacleSet:
    """Vertex rings and k-d tree of obstacles (RVO2's ``addObstacle``, ``processObstacles``).

    Args:
        polygons: Obstacles in order, each ``(M, 2)`` vertices in m: a polygon
            listed counter-clockwise (``M >= 3``) or a segment (``M == 2``).

    Returns:
        The :class:`ObstacleSet`.

    Raises:
        ValueError: If an obstacle has fewer than two vertices or a zero-length edge.
    """
    pts32, points, nxt, prv, dirs, convex = [], [], [], [], [], []
    for poly in polygons:
        v = np.asarray(poly, dtype=np.float64).reshape(-1, 2)
        m = len(v)
        if m < 2:
            raise ValueError("an obstacle needs at least two vertices")
        if not np.all(np.any(np.roll(v, -1, axis=0) != v, axis=1)):
            raise ValueError("an obstacle has a zero-length edge (repeated vertex)")
        v32 = v.astype(np.float32)
        base = len(pts32)
        for k in range(m):
            edge = v[(k + 1) % m] - v[k]
            pts32.append(v32[k])
            points.append(v[k])
            nxt.append(base + (k + 1) % m)
            prv.append(base + (k - 1) % m)
            dirs.append(edge / math.hypot(edge[0], edge[1]))
            convex.append(m == 2 or bool(_left_of(v32[(k - 1) % m], v32[k],
                                                  v32[(k + 1) % m]) >= 0.0))
    nodes, depth = _build_tree(pts32, nxt, prv, dirs, convex, points)
    points = np.array(points, np.float64).reshape(-1, 2)
    bbox = (np.concatenate((points.min(axis=0), points.max(axis=0))) if len(points)
            else np.array([np.inf, np.inf, -np.inf, -np.inf]))
    return ObstacleSet(points=points, next=np.array(nxt, np.int64),
                       prev=np.array(prv, np.int64),
                       directions=np.array(dirs, np.float64).reshape(-1, 2),
                       convex=np.array(convex, np.bool_),
                       tree=np.array(nodes, np.int64).reshape(-1, 3), depth=depth, bbox=bbox)
