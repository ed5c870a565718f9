"""Obstacle rings and RVO2's obstacle k-d tree for :mod:`comparisons.orca.obstacles`.

:func:`prepare_obstacles` turns polygons (counter-clockwise, or two-vertex
segments seen from both sides) into vertex rings with unit edge directions and
convexity flags, and rebuilds RVO2's obstacle tree in single precision,
splitting edges exactly where RVO2 does, so that the rings and the visiting
order of equidistant edges are RVO2's. The tree is built in numba (the
splitter search is a vectorised pass per candidate edge), with each node's
subtree bounding box for the search. :func:`merge_obstacles` puts the trees of
several worlds (the runs of a batch) in one set, one root per world.
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
        roots: ``(W,)`` root node of each world (one world unless merged by
            :func:`merge_obstacles`), -1 for a world without edges.
        bboxes: ``(W, 4)`` the bounding box of each world's vertices, m.
        boxes: ``(T, 4)`` per tree node, the bounding box of the edges of its
            subtree (the node's own edge included), m: a search may skip a
            subtree whose box is out of its range.
    """

    points: FloatArray
    next: IntArray
    prev: IntArray
    directions: FloatArray
    convex: NDArray[np.bool_]
    tree: IntArray
    depth: int
    bbox: FloatArray
    roots: IntArray
    bboxes: FloatArray
    boxes: FloatArray

    @property
    def n_edges(self) -> int:
        """Number of directed edges (= vertices, after splitting)."""
        return len(self.points)


def _left_of(a, b, c):
    """RVO2's ``leftOf(a, b, c) = det(a - c, b - a)`` (> 0: ``c`` left of ``a -> b``)."""
    return (a[..., 0] - c[..., 0]) * (b[..., 1] - a[..., 1]) - \
        (a[..., 1] - c[..., 1]) * (b[..., 0] - a[..., 0])


@numba.njit(cache=True, inline="always")
def _side(ax, ay, bx, by, cx, cy):  # pragma: no cover - numba
    """:func:`_left_of` of one point, in the precision of its arguments (float32 here)."""
    return (ax - cx) * (by - ay) - (ay - cy) * (bx - ax)


@numba.njit(cache=True)
def _grown(arr, size):  # pragma: no cover - numba
    """A copy of C-contiguous ``arr`` with room for ``size`` rows (the first ``len(arr)`` copied).

    Copied element by element through flat views: a slice assignment would
    compile numba's shape-mismatch error path, about a second per signature.
    """
    out = np.empty((size,) + arr.shape[1:], arr.dtype)
    src, dst = arr.reshape(arr.size), out.reshape(out.size)
    for k in range(src.shape[0]):
        dst[k] = src[k]
    return out


@numba.njit(cache=True, inline="always")
def _count(ax, ay, dx, dy, x1, y1, x2, y2, lo, hi, eps):  # pragma: no cover - numba
    """Edges ``lo .. hi-1`` left of (or crossing) and right of (or crossing) a line.

    The line starts at ``(ax, ay)`` with direction ``(dx, dy)``; edge ``j`` runs
    from ``(x1[j], y1[j])`` to ``(x2[j], y2[j])``. Float32, :func:`_side`'s
    operations: left when both end points are ``>= -eps``, right when both are
    ``<= eps`` and it is not left, crossing otherwise (counted on both sides).
    """
    n_left = 0
    n_right = 0
    for j in range(lo, hi):
        s1 = (ax - x1[j]) * dy - (ay - y1[j]) * dx
        s2 = (ax - x2[j]) * dy - (ay - y2[j]) * dx
        left = (s1 >= -eps) & (s2 >= -eps)
        right = (s1 <= eps) & (s2 <= eps)
        n_left += 1 if left or not right else 0
        n_right += 0 if left else 1
    return n_left, n_right


@numba.njit(cache=True)
def _splitter(members, pts, nxt, eps, scratch):  # pragma: no cover - numba
    """Index in ``members`` of RVO2's splitter edge.

    For each candidate edge, the other edges are counted left of its line,
    right of it or crossing it (:func:`_count`, one vectorisable pass over all
    edges, less the candidate's own count); the splitter has the fewest edges
    on its larger side, then on its smaller side, the first such. ``scratch``:
    ``(4, >= len(members))`` room for the edges' end points.
    """
    m = members.shape[0]
    if m == 1:
        return 0
    x1, y1, x2, y2 = scratch[0, :m], scratch[1, :m], scratch[2, :m], scratch[3, :m]
    for k in range(m):
        x1[k], y1[k] = pts[members[k], 0], pts[members[k], 1]
        x2[k], y2[k] = pts[nxt[members[k]], 0], pts[nxt[members[k]], 1]
    best, best_hi, best_lo = 0, m + 1, m + 1
    for i in range(m):
        ax, ay = x1[i], y1[i]
        dx, dy = x2[i] - ax, y2[i] - ay
        n_left, n_right = _count(ax, ay, dx, dy, x1, y1, x2, y2, 0, m, eps)
        self_left, self_right = _count(ax, ay, dx, dy, x1, y1, x2, y2, i, i + 1, eps)
        n_left -= self_left
        n_right -= self_right
        hi, lo = max(n_left, n_right), min(n_left, n_right)
        if hi < best_hi or (hi == best_hi and lo < best_lo):
            best, best_hi, best_lo = i, hi, lo
    return best


@numba.njit(cache=True, error_model="numpy")
def _build_tree(pts, points, nxt, prv, dirs, convex, eps):  # pragma: no cover - numba
    """RVO2's obstacle-tree construction (single precision), splitting edges.

    Depth first, left subtree before right, as RVO2's recursion (the order of
    the new vertices). An edge that crosses the splitter's line is cut there:
    the new vertex (float32, convex, the edge's direction) starts the second
    piece. Returns the vertex arrays extended by the new vertices, the nodes
    ``(edge, left, right)`` and the depth.
    """
    n = pts.shape[0]
    cap = 2 * n + 16
    pts, points, nxt, prv = _grown(pts, cap), _grown(points, cap), _grown(nxt, cap), \
        _grown(prv, cap)
    dirs, convex = _grown(dirs, cap), _grown(convex, cap)
    nodes = np.empty((cap, 3), np.int64)
    n_nodes = 0
    depth = 0
    todo = [(np.arange(n), -1, 0, 1)]
    scratch = np.empty((4, n), pts.dtype)
    while len(todo) > 0:
        members, parent, side, level = todo.pop()
        m = members.shape[0]
        if m == 0:
            continue
        if m > scratch.shape[1]:
            scratch = np.empty((4, 2 * m), pts.dtype)
        best = _splitter(members, pts, nxt, eps, scratch)
        i = members[best]
        ax, ay = pts[i, 0], pts[i, 1]
        bx, by = pts[nxt[i], 0], pts[nxt[i], 1]
        abx, aby = bx - ax, by - ay
        lefts = np.empty(m, np.int64)
        rights = np.empty(m, np.int64)
        n_l = 0
        n_r = 0
        for jj in range(m):
            if jj == best:
                continue
            j = members[jj]
            j2 = nxt[j]
            s1 = _side(ax, ay, bx, by, pts[j, 0], pts[j, 1])
            s2 = _side(ax, ay, bx, by, pts[j2, 0], pts[j2, 1])
            if s1 >= -eps and s2 >= -eps:
                lefts[n_l] = j
                n_l += 1
            elif s1 <= eps and s2 <= eps:
                rights[n_r] = j
                n_r += 1
            else:  # edge j crosses the splitter's line: cut it there
                t = (abx * (pts[j, 1] - ay) - aby * (pts[j, 0] - ax)) / \
                    (abx * (pts[j, 1] - pts[j2, 1]) - aby * (pts[j, 0] - pts[j2, 0]))
                new = n
                n += 1
                if n > pts.shape[0]:
                    cap = 2 * n
                    pts, points, nxt, prv = _grown(pts, cap), _grown(points, cap), \
                        _grown(nxt, cap), _grown(prv, cap)
                    dirs, convex, nodes = _grown(dirs, cap), _grown(convex, cap), \
                        _grown(nodes, cap)
                pts[new, 0] = pts[j, 0] + t * (pts[j2, 0] - pts[j, 0])
                pts[new, 1] = pts[j, 1] + t * (pts[j2, 1] - pts[j, 1])
                points[new, 0], points[new, 1] = np.float64(pts[new, 0]), np.float64(pts[new, 1])
                dirs[new, 0], dirs[new, 1] = dirs[j, 0], dirs[j, 1]
                convex[new] = True
                nxt[new] = j2
                prv[new] = j
                nxt[j] = new
                prv[j2] = new
                if s1 > 0.0:
                    lefts[n_l] = j
                    rights[n_r] = new
                else:
                    rights[n_r] = j
                    lefts[n_l] = new
                n_l += 1
                n_r += 1
        node = n_nodes
        n_nodes += 1
        nodes[node, 0], nodes[node, 1], nodes[node, 2] = i, -1, -1
        if parent >= 0:
            nodes[parent, side] = node
        depth = max(depth, level)
        todo.append((rights[:n_r].copy(), node, 2, level + 1))
        todo.append((lefts[:n_l].copy(), node, 1, level + 1))
    return (pts[:n].copy(), points[:n].copy(), nxt[:n].copy(), prv[:n].copy(), dirs[:n].copy(),
            convex[:n].copy(), nodes[:n_nodes].copy(), depth)


@numba.njit(cache=True)
def _subtree_boxes(tree, points, nxt):  # pragma: no cover - numba
    """``(T, 4)`` bounding box of each node's subtree edges (children follow their parent)."""
    boxes = np.empty((tree.shape[0], 4))
    for node in range(tree.shape[0] - 1, -1, -1):
        a, b = tree[node, 0], nxt[tree[node, 0]]
        boxes[node, 0] = min(points[a, 0], points[b, 0])
        boxes[node, 1] = min(points[a, 1], points[b, 1])
        boxes[node, 2] = max(points[a, 0], points[b, 0])
        boxes[node, 3] = max(points[a, 1], points[b, 1])
        for side in (1, 2):
            child = tree[node, side]
            if child >= 0:
                boxes[node, 0] = min(boxes[node, 0], boxes[child, 0])
                boxes[node, 1] = min(boxes[node, 1], boxes[child, 1])
                boxes[node, 2] = max(boxes[node, 2], boxes[child, 2])
                boxes[node, 3] = max(boxes[node, 3], boxes[child, 3])
    return boxes


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
    rings = [np.asarray(poly, dtype=np.float64).reshape(-1, 2) for poly in polygons]
    sizes = np.array([len(v) for v in rings], dtype=np.int64)
    if (sizes < 2).any():
        raise ValueError("an obstacle needs at least two vertices")
    # every ring at once: vertex i's ring starts at first[i] and has size[i] vertices
    size = np.repeat(sizes, sizes)
    first = np.repeat(np.cumsum(sizes) - sizes, sizes)
    local = np.arange(len(size)) - first
    nxt = first + (local + 1) % size
    prv = first + (local - 1) % size
    points = np.concatenate(rings) if rings else np.zeros((0, 2))
    if np.any(np.all(points[nxt] == points, axis=1)):
        raise ValueError("an obstacle has a zero-length edge (repeated vertex)")
    pts32 = points.astype(np.float32)
    edge = points[nxt] - points
    length = np.array([math.hypot(x, y) for x, y in edge.tolist()]).reshape(-1)
    dirs = np.ascontiguousarray(edge / length[:, None]).reshape(-1, 2)
    convex = (size == 2) | (_left_of(pts32[prv], pts32, pts32[nxt]) >= 0.0)
    pts32, points, nxt, prv, dirs, convex, nodes, depth = _build_tree(
        pts32, points, nxt, prv, dirs, convex, np.float32(EPSILON))
    bbox = (np.concatenate((points.min(axis=0), points.max(axis=0))) if len(points)
            else np.array([np.inf, np.inf, -np.inf, -np.inf]))
    return ObstacleSet(points=points, next=nxt, prev=prv, directions=dirs, convex=convex,
                       tree=nodes, depth=int(depth), bbox=bbox,
                       roots=np.array([0 if len(nodes) else -1], np.int64),
                       bboxes=bbox[None].copy(), boxes=_subtree_boxes(nodes, points, nxt))


def merge_obstacles(sets: Sequence[ObstacleSet]) -> ObstacleSet:
    """Several worlds' obstacle sets as one, each world keeping its own tree.

    Vertex and node indices of world ``w`` are shifted past those of the
    worlds before it; ``roots[w]`` and ``bboxes[w]`` are its tree's root and box.
    An agent that searches from its world's root visits that world's edges in
    the same order, with the same single-precision keys, as in the world's own
    set: its lines are the same, bit for bit (one kernel call for a batch of
    runs whose seeded clutter fields differ).

    Args:
        sets: One prepared set per world (each with one world).

    Returns:
        The merged set (``roots`` and ``bboxes`` have one row per world).
    """
    v_off = np.cumsum([0, *(s.n_edges for s in sets)])
    n_off = np.cumsum([0, *(len(s.tree) for s in sets)])
    trees = [np.column_stack((s.tree[:, 0] + v_off[w],
                              np.where(s.tree[:, 1:] >= 0, s.tree[:, 1:] + n_off[w], -1)))
             for w, s in enumerate(sets)]
    points = np.concatenate([s.points for s in sets]).reshape(-1, 2)
    bbox = (np.concatenate((points.min(axis=0), points.max(axis=0))) if len(points)
            else np.array([np.inf, np.inf, -np.inf, -np.inf]))
    return ObstacleSet(points=points,
                       next=np.concatenate([s.next + v_off[w] for w, s in enumerate(sets)]),
                       prev=np.concatenate([s.prev + v_off[w] for w, s in enumerate(sets)]),
                       directions=np.concatenate([s.directions for s in sets]).reshape(-1, 2),
                       convex=np.concatenate([s.convex for s in sets]),
                       tree=np.concatenate(trees).reshape(-1, 3).astype(np.int64),
                       depth=max(s.depth for s in sets), bbox=bbox,
                       roots=np.array([n_off[w] if len(s.tree) else -1
                                       for w, s in enumerate(sets)], np.int64),
                       bboxes=np.stack([s.bbox for s in sets]),
                       boxes=np.concatenate([s.boxes for s in sets]).reshape(-1, 4))
