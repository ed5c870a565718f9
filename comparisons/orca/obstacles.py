"""Static polygon obstacles for ORCA, the RVO2 way ("mode (a)": one ORCA line per edge).

An obstacle is a polygon given counter-clockwise (RVO2's ``addObstacle``
convention; the free space is on the right of every directed edge) or a
two-vertex polyline, which becomes a segment seen from both sides. The
vertices form rings: vertex ``k`` starts the edge ``k -> next[k]``, with a unit
direction and a convexity flag (the turn at ``k`` is to the left or straight).

Each agent considers the edges whose supporting line has the agent strictly on
its outer (right) side and that are closer than
``time_horizon_obst * max_speed + radius``; they are visited nearest first (by
squared distance to the segment) and each yields at most one half-plane of
velocities, built against the velocity obstacle of the edge truncated at the
horizon ``time_horizon_obst``: nothing if earlier obstacle lines already push
both end points' cut-off discs out; a line through the origin when the agent
already overlaps the edge or an end vertex; otherwise the velocity is projected
onto the nearest part of the truncated cone (either end's cut-off circle, the
cut-off segment, or a leg; a leg that would point into the neighbouring edge of
a convex vertex is replaced by that edge, and projecting onto such a "foreign"
leg adds nothing). Obstacles are not reciprocal: the agent takes all of the
avoidance, and these lines are hard (never relaxed by the solver).

RVO2 splits edges while building its obstacle k-d tree (an edge crossing the
supporting line of a chosen splitter edge is cut in two, the new vertex being
convex); :func:`prepare_obstacles` rebuilds the same tree in single precision,
so the rings, and the order in which equidistant edges are visited (the tree
traversal order), are RVO2's. The line construction itself runs in double
precision, batched over agents in a numba kernel; the search skips subtrees
whose bounding box is out of range (no edge found, nor their order, changes),
and agents of different worlds (a batch of runs, :func:`merge_obstacles`) each
search their own world's tree in the same call.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from comparisons.orca.lp import EPSILON, det
from comparisons.orca.obstacle_set import ObstacleSet, merge_obstacles, prepare_obstacles
from dfcoa_opt.core.runtime.threads import kernel_threads

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

__all__ = ["ObstacleSet", "edge_line", "merge_obstacles", "obstacle_lines", "prepare_obstacles"]


@numba.njit(cache=True, inline="always", error_model="numpy")
def _seg_dist_sq(px, py, pts, a, b):  # pragma: no cover - numba
    """Squared distance from ``(px, py)`` to the segment ``pts[a] -> pts[b]``, m^2.

    Evaluated in single precision as RVO2 does: it is only the sort key of the
    neighbour edges, and an agent in a convex corner's diagonal region is at the
    same distance from both edges; RVO2 then keeps the traversal order, which
    needs the tie to be exact (in double precision the two values can differ in
    the last bits).
    """
    f = np.float32
    qx, qy = f(px), f(py)
    ax, ay = f(pts[a, 0]), f(pts[a, 1])
    bx, by = f(pts[b, 0]), f(pts[b, 1])
    ex, ey = bx - ax, by - ay
    r = ((qx - ax) * ex + (qy - ay) * ey) / (ex * ex + ey * ey)
    if r < f(0.0):
        dx, dy = qx - ax, qy - ay
    elif r > f(1.0):
        dx, dy = qx - bx, qy - by
    else:
        dx, dy = qx - (ax + r * ex), qy - (ay + r * ey)
    return float(dx * dx + dy * dy)


@numba.njit(cache=True, error_model="numpy")
def _neighbours(px, py, range_sq, far_sq, pts, nxt, tree, boxes, root, stack, nbr, nbr_d
                ):  # pragma: no cover - numba
    """Visible edges within range in RVO2's tree-traversal order, sorted stably by distance.

    The traversal starts at node ``root`` (the root of the agent's world in a
    merged set) and visits the agent's side of a node's line first, then (when
    the line is in range) the node's own edge, if the agent is on its outer
    side, and the other side. A subtree whose bounding box is farther than
    ``sqrt(far_sq)`` (the range plus a margin far above the single-precision
    error of :func:`_seg_dist_sq`) holds no edge within range: it is skipped,
    which changes neither the edges found nor their order. Returns the number
    of edges written to ``nbr``.
    """
    m = 0
    top = 0
    stack[0] = 2 * root  # entries: 2 * node + (0: descend, 1: node and far side)
    while top >= 0:
        entry = stack[top]
        top -= 1
        node = entry >> 1
        e = tree[node, 0]
        a, b = e, nxt[e]
        ex, ey = pts[b, 0] - pts[a, 0], pts[b, 1] - pts[a, 1]
        side = (pts[a, 0] - px) * ey - (pts[a, 1] - py) * ex  # leftOf(a, b, agent)
        near = tree[node, 1] if side >= 0.0 else tree[node, 2]
        far = tree[node, 2] if side >= 0.0 else tree[node, 1]
        if entry & 1 == 0:
            if _box_dist_sq(px, py, boxes[node]) > far_sq:
                continue
            top += 1
            stack[top] = 2 * node + 1
            if near >= 0:
                top += 1
                stack[top] = 2 * near
            continue
        if side * side / (ex * ex + ey * ey) < range_sq:
            if side < 0.0:
                d = _seg_dist_sq(px, py, pts, a, b)
                if d < range_sq:
                    slot = m
                    m += 1
                    while slot > 0 and d < nbr_d[slot - 1]:
                        nbr[slot] = nbr[slot - 1]
                        nbr_d[slot] = nbr_d[slot - 1]
                        slot -= 1
                    nbr[slot] = e
                    nbr_d[slot] = d
            if far >= 0:
                top += 1
                stack[top] = 2 * far
    return m


@numba.njit(cache=True, inline="always", error_model="numpy")
def _leg(rx, ry, dist_sq, radius, sign):  # pragma: no cover - numba
    """Unit direction of the tangent from the agent to the disc of ``radius`` at ``(rx, ry)``.

    ``sign = +1``: the left leg, ``-1``: the right leg (both pointing away from the agent).
    """
    leg = math.sqrt(dist_sq - radius * radius)
    return ((rx * leg - sign * ry * radius) / dist_sq,
            (sign * rx * radius + ry * leg) / dist_sq)


@numba.njit(cache=True, inline="always", error_model="numpy")
def _push(P, D, m, qx, qy, dx, dy):  # pragma: no cover - numba
    P[m, 0], P[m, 1], D[m, 0], D[m, 1] = qx, qy, dx, dy
    return m + 1


@numba.njit(cache=True, error_model="numpy")
def edge_line(px, py, vx, vy, radius, inv_tau, e, pts, nxt, prv, dirs, convex, P, D, m
              ):  # pragma: no cover - numba
    """Add the ORCA line of edge ``e`` for one agent to ``P[:m], D[:m]`` (if any).

    Args:
        px: Agent x position, m.
        py: Agent y position, m.
        vx: Agent x velocity, m/s.
        vy: Agent y velocity, m/s.
        radius: Agent radius, m.
        inv_tau: 1 / obstacle time horizon, 1/s.
        e: Edge (its first vertex).
        pts: ``(V, 2)`` obstacle vertices, m.
        nxt: ``(V,)`` next vertex of each ring.
        prv: ``(V,)`` previous vertex of each ring.
        dirs: ``(V, 2)`` unit edge directions.
        convex: ``(V,)`` vertex convexity.
        P: ``(L, 2)`` line points, m/s (rows ``< m`` are this agent's earlier lines).
        D: ``(L, 2)`` unit line directions (allowed side on the left).
        m: Lines written so far.

    Returns:
        The new number of lines (``m`` or ``m + 1``).
    """
    v1, v2 = e, nxt[e]
    r1x, r1y = pts[v1, 0] - px, pts[v1, 1] - py
    r2x, r2y = pts[v2, 0] - px, pts[v2, 1] - py
    margin = inv_tau * radius
    for j in range(m):  # cut-off discs of both ends already outside an earlier line?
        c1 = det(inv_tau * r1x - P[j, 0], inv_tau * r1y - P[j, 1], D[j, 0], D[j, 1])
        c2 = det(inv_tau * r2x - P[j, 0], inv_tau * r2y - P[j, 1], D[j, 0], D[j, 1])
        if c1 - margin >= -EPSILON and c2 - margin >= -EPSILON:
            return m
    d1 = r1x * r1x + r1y * r1y
    d2 = r2x * r2x + r2y * r2y
    r_sq = radius * radius
    ox, oy = pts[v2, 0] - pts[v1, 0], pts[v2, 1] - pts[v1, 1]
    s = -(r1x * ox + r1y * oy) / (ox * ox + oy * oy)  # agent's projection on the edge
    qx, qy = -r1x - s * ox, -r1y - s * oy
    d_line = qx * qx + qy * qy
    # already overlapping: leave along the outward normal, through the origin
    if s < 0.0 and d1 <= r_sq:
        if convex[v1]:
            n = math.sqrt(d1)
            m = _push(P, D, m, 0.0, 0.0, -r1y / n, r1x / n)
        return m
    if s > 1.0 and d2 <= r_sq:
        if convex[v2] and det(r2x, r2y, dirs[v2, 0], dirs[v2, 1]) >= 0.0:
            n = math.sqrt(d2)
            m = _push(P, D, m, 0.0, 0.0, -r2y / n, r2x / n)
        return m
    if 0.0 <= s <= 1.0 and d_line <= r_sq:
        return _push(P, D, m, 0.0, 0.0, -dirs[v1, 0], -dirs[v1, 1])
    # legs of the truncated cone
    if s < 0.0 and d_line <= r_sq:  # seen end-on: vertex v1 alone
        if not convex[v1]:
            return m
        v2 = v1
        lx, ly = _leg(r1x, r1y, d1, radius, 1.0)
        rx, ry = _leg(r1x, r1y, d1, radius, -1.0)
    elif s > 1.0 and d_line <= r_sq:  # seen end-on: vertex v2 alone
        if not convex[v2]:
            return m
        v1 = v2
        lx, ly = _leg(r2x, r2y, d2, radius, 1.0)
        rx, ry = _leg(r2x, r2y, d2, radius, -1.0)
    else:
        if convex[v1]:
            lx, ly = _leg(r1x, r1y, d1, radius, 1.0)
        else:  # concave corner: the leg continues the cut-off line
            lx, ly = -dirs[v1, 0], -dirs[v1, 1]
        if convex[v2]:
            rx, ry = _leg(r2x, r2y, d2, radius, -1.0)
        else:
            rx, ry = dirs[v1, 0], dirs[v1, 1]
    # a leg may not point into the neighbouring edge of a convex vertex
    left_foreign = False
    right_foreign = False
    nb = prv[v1]
    if convex[v1] and det(lx, ly, -dirs[nb, 0], -dirs[nb, 1]) >= 0.0:
        lx, ly = -dirs[nb, 0], -dirs[nb, 1]
        left_foreign = True
    if convex[v2] and det(rx, ry, dirs[v2, 0], dirs[v2, 1]) <= 0.0:
        rx, ry = dirs[v2, 0], dirs[v2, 1]
        right_foreign = True
    # cut-off centres and the projection of the velocity on the cone
    lcx, lcy = inv_tau * (pts[v1, 0] - px), inv_tau * (pts[v1, 1] - py)
    rcx, rcy = inv_tau * (pts[v2, 0] - px), inv_tau * (pts[v2, 1] - py)
    cx, cy = rcx - lcx, rcy - lcy
    single = v1 == v2
    wlx, wly = vx - lcx, vy - lcy
    wrx, wry = vx - rcx, vy - rcy
    t = 0.5 if single else (wlx * cx + wly * cy) / (cx * cx + cy * cy)
    t_left = wlx * lx + wly * ly
    t_right = wrx * rx + wry * ry
    if (t < 0.0 and t_left < 0.0) or (single and t_left < 0.0 and t_right < 0.0):
        n = math.sqrt(wlx * wlx + wly * wly)  # onto the left cut-off circle
        ux, uy = wlx / n, wly / n
        return _push(P, D, m, lcx + margin * ux, lcy + margin * uy, uy, -ux)
    if t > 1.0 and t_right < 0.0:
        n = math.sqrt(wrx * wrx + wry * wry)  # onto the right cut-off circle
        ux, uy = wrx / n, wry / n
        return _push(P, D, m, rcx + margin * ux, rcy + margin * uy, uy, -ux)
    d_cut = math.inf
    if not (t < 0.0 or t > 1.0 or single):
        gx, gy = vx - (lcx + t * cx), vy - (lcy + t * cy)
        d_cut = gx * gx + gy * gy
    d_left = math.inf
    if t_left >= 0.0:
        gx, gy = vx - (lcx + t_left * lx), vy - (lcy + t_left * ly)
        d_left = gx * gx + gy * gy
    d_right = math.inf
    if t_right >= 0.0:
        gx, gy = vx - (rcx + t_right * rx), vy - (rcy + t_right * ry)
        d_right = gx * gx + gy * gy
    if d_cut <= d_left and d_cut <= d_right:  # onto the cut-off segment
        dx, dy = -dirs[v1, 0], -dirs[v1, 1]
        return _push(P, D, m, lcx - margin * dy, lcy + margin * dx, dx, dy)
    if d_left <= d_right:  # onto the left leg
        if left_foreign:
            return m
        return _push(P, D, m, lcx - margin * ly, lcy + margin * lx, lx, ly)
    if right_foreign:  # onto the right leg
        return m
    return _push(P, D, m, rcx + margin * ry, rcy - margin * rx, -rx, -ry)


@numba.njit(cache=True, inline="always", error_model="numpy")
def _box_dist_sq(px, py, box):  # pragma: no cover - numba
    """Squared distance from ``(px, py)`` to the box ``(x_min, y_min, x_max, y_max)``, m^2."""
    dx = max(box[0] - px, 0.0, px - box[2])
    dy = max(box[1] - py, 0.0, py - box[3])
    return dx * dx + dy * dy


@numba.njit(cache=True, parallel=True, error_model="numpy")
def _lines_kernel(pos, vel, radius, range_sq, far_sq, world, inv_tau, pts, nxt, prv, dirs,
                  convex, tree, boxes, roots, depth, bboxes, chunk, P, D, count, need
                  ):  # pragma: no cover - numba
    """Each agent's lines into ``P[i], D[i]`` (``count``), and how many it has (``need``).

    An agent with more lines than ``P`` has columns writes none (``count`` 0):
    the caller calls again with ``P`` as wide as ``need``.
    """
    n = pos.shape[0]
    for c in numba.prange((n + chunk - 1) // chunk):
        stack = np.empty(depth + 2, np.int64)
        nbr = np.empty(pts.shape[0], np.int64)
        nbr_d = np.empty(pts.shape[0])
        lp = np.empty((pts.shape[0], 2))  # this agent's lines, then copied into P, D
        ld = np.empty((pts.shape[0], 2))
        for i in range(c * chunk, min(n, (c + 1) * chunk)):
            count[i] = 0
            need[i] = 0
            px, py = pos[i, 0], pos[i, 1]
            w = world[i]
            if roots[w] < 0 or not _box_dist_sq(px, py, bboxes[w]) < range_sq[i]:
                continue
            k = _neighbours(px, py, range_sq[i], far_sq[i], pts, nxt, tree, boxes, roots[w],
                            stack, nbr, nbr_d)
            m = 0
            for j in range(k):
                m = edge_line(px, py, vel[i, 0], vel[i, 1], radius[i], inv_tau, nbr[j], pts, nxt,
                              prv, dirs, convex, lp, ld, m)
            need[i] = m
            if m <= P.shape[1]:
                P[i, :m] = lp[:m]
                D[i, :m] = ld[:m]
                count[i] = m


#: Columns of the line tables of the first try of :func:`obstacle_lines` (an agent
#: with more lines makes a second, wider one).
FIRST_WIDTH = 32


def obstacle_lines(pos: ArrayLike, vel: ArrayLike, radius: ArrayLike | float,
                   max_speed: ArrayLike | float, time_horizon_obst: float,
                   obstacles: ObstacleSet | Sequence[ArrayLike],
                   world: ArrayLike | None = None) -> tuple[FloatArray, FloatArray, IntArray]:
    """RVO2's obstacle ORCA lines of every agent (hard lines for :mod:`comparisons.orca.lp`).

    Args:
        pos: ``(N, 2)`` agent positions, m.
        vel: ``(N, 2)`` agent velocities, m/s.
        radius: ``(N,)`` or scalar agent radii, m.
        max_speed: ``(N,)`` or scalar speed limits, m/s (they set the search
            range ``time_horizon_obst * max_speed + radius``, m).
        time_horizon_obst: Obstacle time horizon tau_obst, s.
        obstacles: A prepared :class:`ObstacleSet` (possibly several worlds merged
            by :func:`merge_obstacles`) or a list of polygons for :func:`prepare_obstacles`.
        world: ``(N,)`` the world of each agent in a merged set (each agent sees
            only its own world's obstacles, as if it were alone in it); default 0.

    Returns:
        ``(points (N, H, 2) m/s, directions (N, H, 2), count (N,))``: each agent's
        lines (allowed side on the left), nearest edge first, rows padded past
        ``count``; ``H`` is the largest ``count`` (0 when no agent has a line).
    """
    obs = obstacles if isinstance(obstacles, ObstacleSet) else prepare_obstacles(obstacles)
    pos = np.ascontiguousarray(pos, dtype=np.float64).reshape(-1, 2)
    n = len(pos)
    radius = np.ascontiguousarray(np.broadcast_to(radius, (n,)), dtype=np.float64)
    reach = time_horizon_obst * np.broadcast_to(np.asarray(max_speed, np.float64), (n,)) + radius
    range_sq = np.ascontiguousarray(reach * reach)
    count = np.empty(n, np.int64)
    if obs.n_edges == 0 or n == 0:
        count[:] = 0
        return np.zeros((n, 0, 2)), np.zeros((n, 0, 2)), count
    world = (np.zeros(n, np.int64) if world is None
             else np.ascontiguousarray(np.broadcast_to(world, (n,)), dtype=np.int64))
    # far_sq: the range plus 1e-4 of the coordinates' scale, ~1e3 times the float32
    # error of a distance (2^-24 of the coordinates), so a skipped subtree has no edge
    # that _seg_dist_sq could put within range
    scale = 1.0 + reach + np.maximum(np.abs(pos).max(axis=1), np.abs(obs.bbox).max())
    far_sq = np.ascontiguousarray((reach + 1e-4 * scale) ** 2)
    vel = np.ascontiguousarray(vel, dtype=np.float64).reshape(-1, 2)
    need = np.empty(n, np.int64)
    width = min(obs.n_edges, FIRST_WIDTH)
    while True:
        P = np.zeros((n, width, 2))
        D = np.zeros((n, width, 2))
        with kernel_threads(n):
            chunk = max(1, -(-n // (4 * numba.get_num_threads())))
            _lines_kernel(pos, vel, radius, range_sq, far_sq, world, 1.0 / time_horizon_obst,
                          obs.points, obs.next, obs.prev, obs.directions, obs.convex, obs.tree,
                          obs.boxes, obs.roots, obs.depth, obs.bboxes, chunk, P, D, count, need)
        if need.max() <= width:
            break
        width = int(need.max())
    h = int(count.max())
    return P[:, :h], D[:, :h], count
