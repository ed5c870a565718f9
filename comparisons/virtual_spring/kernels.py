"""Compiled steps of ``virtual_spring``: the same numbers as the pure functions.

Two pieces of the controller's step, each about forty small numpy operations
as array expressions, run as compiled loops with the operations of the pure
functions of :mod:`comparisons.virtual_spring.equations` and
:mod:`comparisons.virtual_spring.conflict`, in the same order:

- eq 7's sources (:meth:`~comparisons.virtual_spring.controller.VirtualSpring.spring`):
  :func:`spring_sources` gives, for every robot and source (static circles,
  polygons, neighbours, moving obstacles), the vector ``delta`` of
  ``disc_normals``, ``polygon_normals`` and ``spring_force``, and
  :func:`weighted_sum` does eq 7's sum in numpy's order; the inverse cube
  between them stays numpy's (``inverse_cube``: numba's ``pow`` differs from
  numpy's in the last bit);
- eq 15-17 (:meth:`~comparisons.virtual_spring.controller.VirtualSpring.resolve`):
  :func:`conflict_changes` is ``vo_conflict`` followed by ``conflict_resolution``.

``tests/test_virtual_spring_fast.py`` checks both against the pure functions
bit for bit.

Both take the rows of a batch of runs (:class:`~dfcoa_opt.control.base.BatchedController`):
each row reads the static obstacles of its own run's world (``world``, and the
``*_ptr`` ranges of the concatenated tables), and eq 17's shortcut (no
conflict anywhere) is decided per run (``env``), so every row gets the bits
of its run simulated alone.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from comparisons.constraints.geometry_kernels import polygon_walk1
from comparisons.virtual_spring.equations import PolygonEdges, polygon_edge_table
from dfcoa_opt.core.scalar_kernels import clip1

#: Below this norm a vector has no direction (m), as in :mod:`.equations`.
TINY = 1e-12


class StaticSources(NamedTuple):
    """Eq 7's static sources of ``W`` worlds, world after world (:func:`static_sources`).

    ``circles`` ``(C, 2)`` centres and ``circle_r`` ``(C,)`` radii, m: world
    ``w``'s are ``circle_ptr[w] .. circle_ptr[w + 1]``; ``edges`` ``(Q, V, 2)``:
    the polygons (world ``w``'s are ``polygon_ptr[w] ..``), each row from its
    world's own :func:`~comparisons.virtual_spring.equations.polygon_edge_table`,
    of which it has ``edge_count[q]`` edges (the rest is padding of wider worlds).
    """

    circles: NDArray[np.float64]
    circle_r: NDArray[np.float64]
    circle_ptr: NDArray[np.int64]
    edges: PolygonEdges
    edge_count: NDArray[np.int64]
    polygon_ptr: NDArray[np.int64]


def static_sources(worlds: list[tuple[ArrayLike, ArrayLike, list[ArrayLike]]]) -> StaticSources:
    """The static sources of ``W`` worlds, each ``(centres (C_w, 2), radii (C_w,), polygons)`` in m.

    A polygon keeps the edges (and the padding) of its own world's table, so a
    row of a batch walks the edges it walks in the run simulated alone; one
    world's table is used as it is.
    """
    circles = [np.asarray(c, dtype=float).reshape(-1, 2) for c, _, _ in worlds]
    radii = [np.asarray(r, dtype=float).reshape(-1) for _, r, _ in worlds]
    tables = [polygon_edge_table([np.asarray(v, dtype=float) for v in polys])
              for _, _, polys in worlds]
    if len(tables) == 1:
        edges = tables[0]
    else:
        width = max(t.a.shape[1] for t in tables)
        edges = PolygonEdges(*(np.concatenate([_widen(getattr(t, name), width) for t in tables])
                               for name in PolygonEdges._fields))
    return StaticSources(
        np.concatenate(circles), np.concatenate(radii),
        np.cumsum([0] + [len(r) for r in radii]).astype(np.int64), edges,
        np.concatenate([np.full(len(t.a), t.a.shape[1], dtype=np.int64) for t in tables]),
        np.cumsum([0] + [len(t.a) for t in tables]).astype(np.int64))


def _widen(x: NDArray, width: int) -> NDArray:
    """``x`` ``(Q, V, ...)`` padded with zeros to ``V = width`` (columns that are not read)."""
    pad = [(0, 0)] * x.ndim
    pad[1] = (0, width - x.shape[1])
    return np.pad(x, pad)


@numba.njit(cache=True, inline="always")
def _unit(vx, vy):  # pragma: no cover - numba
    """:func:`~comparisons.virtual_spring.equations.unit_vectors` of one vector."""
    norm = math.sqrt(vx * vx + vy * vy)
    if norm > TINY:
        return vx / norm, vy / norm, norm
    return 0.0, 0.0, norm


@numba.njit(cache=True, inline="always")
def _polygon(px, py, a, b):  # pragma: no cover - numba
    """:func:`~comparisons.virtual_spring.equations.polygon_normals` for one polygon.

    The first edge with the smallest distance (not squared: ties as numpy's
    ``argmin`` of the norms) gives the nearest point. Returns ``(ux, uy, s)``.
    """
    qx, qy, _, inside = polygon_walk1(px, py, a, b, True)
    ux, uy, d = _unit(px - qx, py - qy)
    if inside:
        return -ux, -uy, -d
    return ux, uy, d


@numba.njit(cache=True)
def spring_sources(pos, world, circles, circle_r, circle_ptr, ea, eb, edge_count, polygon_ptr,
                   nb_pos, nb_mask, mo_pos, mo_radius, mo_mask, radius, spring_range,
                   min_distance, delta, dist, use, count):  # pragma: no cover - numba
    """Fill eq 7's ``delta`` ``(R, S, 2)``, ``|delta|``, the sources that count and their number.

    Row ``i``'s sources, in this order, are the static circles and polygons of
    its world ``w = world[i]`` -- circles ``circle_ptr[w] .. circle_ptr[w + 1]``
    of the concatenated ``(C, 2)`` centres and ``(C,)`` radii, polygons
    ``polygon_ptr[w] ..`` of the concatenated edge starts ``ea`` and ends ``eb``
    ``(Q, V, 2)`` (the first ``edge_count[q]`` edges of polygon ``q``: its
    world's own :class:`~comparisons.virtual_spring.equations.PolygonEdges`)
    -- then the neighbours ``(R, K, 2)`` (robot radius) and the moving
    obstacles ``(R, M, 2)`` with radii ``(R, M)``; ``count[i]`` of them, the
    rest of the row is padding (0, not used). ``delta`` is the unit vector
    from the source times ``max(clearance, min_distance)``; a source counts
    when it is real (mask), within ``spring_range`` (m) and ``|delta| > TINY``.
    """
    n_k, n_m = nb_pos.shape[1], mo_pos.shape[1]
    for i in range(pos.shape[0]):
        px, py = pos[i, 0], pos[i, 1]
        w = world[i]
        c0, q0 = circle_ptr[w], polygon_ptr[w]
        n_c, n_q = circle_ptr[w + 1] - c0, polygon_ptr[w + 1] - q0
        total = n_c + n_q + n_k + n_m
        count[i] = total
        for s in range(total):
            real = True
            if s < n_c:
                c = c0 + s
                ux, uy, d = _unit(px - circles[c, 0], py - circles[c, 1])
                surface = d - circle_r[c]
            elif s < n_c + n_q:
                q = q0 + s - n_c
                nv = edge_count[q]
                ux, uy, surface = _polygon(px, py, ea[q, :nv], eb[q, :nv])
            elif s < n_c + n_q + n_k:
                k = s - n_c - n_q
                ux, uy, d = _unit(px - nb_pos[i, k, 0], py - nb_pos[i, k, 1])
                surface = d - radius
                real = nb_mask[i, k]
            else:
                m = s - n_c - n_q - n_k
                ux, uy, d = _unit(px - mo_pos[i, m, 0], py - mo_pos[i, m, 1])
                surface = d - mo_radius[i, m]
                real = mo_mask[i, m]
            clear = surface - radius
            # np.maximum: the first argument when >= or NaN
            scale = clear if (clear >= min_distance or math.isnan(clear)) else min_distance
            dx, dy = ux * scale, uy * scale
            delta[i, s, 0], delta[i, s, 1] = dx, dy
            nd = math.sqrt(dx * dx + dy * dy)
            dist[i, s] = nd
            use[i, s] = real and clear <= spring_range and nd > TINY
        for s in range(total, delta.shape[1]):
            delta[i, s, 0] = delta[i, s, 1] = dist[i, s] = 0.0
            use[i, s] = False


@numba.njit(cache=True)
def weighted_sum(w, delta, count, gain, out):  # pragma: no cover - numba
    """Fill ``out`` ``(R, 2)`` with ``gain * sum_s w[i, s] delta[i, s]`` over ``count[i]`` sources.

    In numpy's order: ``np.sum(axis=1)`` of these ``(N, S, 2)`` products adds
    them from 0.0 in source order (checked on this machine for S = 1 .. 300).
    """
    for i in range(delta.shape[0]):
        fx = 0.0
        fy = 0.0
        for s in range(count[i]):
            fx += w[i, s] * delta[i, s, 0]
            fy += w[i, s] * delta[i, s, 1]
        out[i, 0] = gain * fx
        out[i, 1] = gain * fy


@numba.njit(cache=True)
def conflict_changes(pos, v, env, nb_pos, nb_vel, nb_mask, mo_pos, mo_vel, mo_radius, mo_mask,
                     radius, margin, horizon, obstacle_share, dv, count):  # pragma: no cover
    """Eq 15-17 for every row: fill the velocity changes ``dv`` ``(R, 2)`` and ``count``.

    The other robots ``(R, K, 2)`` (Minkowski radius ``2 radius``, share 1) and
    the moving obstacles ``(R, M, 2)`` (``radii + radius``, share
    ``obstacle_share``), with the operations of
    :func:`~comparisons.virtual_spring.conflict.vo_conflict` and
    :func:`~comparisons.virtual_spring.conflict.conflict_resolution` and eq
    17's sum in numpy's order. The rows of one run are consecutive with the
    same ``env`` ``(R,)``; in a run without any conflict and without a ``-0``
    in ``v``, every change is ``+0`` (what the controller's early return gives).
    """
    n, n_k, n_m = pos.shape[0], nb_pos.shape[1], mo_pos.shape[1]
    hit = np.zeros((n, n_k + n_m), dtype=np.bool_)
    busy = np.zeros(n, dtype=np.bool_)  # a conflict or a -0 in v: the run takes eq 17's sums
    for i in range(n):
        count[i] = 0
        for s in range(n_k + n_m):
            if s < n_k:
                real, qx, qy = nb_mask[i, s], nb_pos[i, s, 0], nb_pos[i, s, 1]
                wx, wy = v[i, 0] - nb_vel[i, s, 0], v[i, 1] - nb_vel[i, s, 1]
                reach = 2.0 * radius + margin
            else:
                m = s - n_k
                real, qx, qy = mo_mask[i, m], mo_pos[i, m, 0], mo_pos[i, m, 1]
                wx, wy = v[i, 0] - mo_vel[i, m, 0], v[i, 1] - mo_vel[i, m, 1]
                reach = (mo_radius[i, m] + radius) + margin
            if not real:
                continue
            dx, dy = qx - pos[i, 0], qy - pos[i, 1]
            ww = wx * wx + wy * wy
            tau = 0.0
            if ww > 0.0:  # eq 15: the closest approach along the ray, within the horizon
                tau = clip1((dx * wx + (dy * wy + 0.0)) / ww, 0.0, horizon)
            ex, ey = dx - tau * wx, dy - tau * wy
            if math.sqrt(ex * ex + ey * ey) <= reach:  # eq 16
                hit[i, s] = True
                count[i] += 1
                busy[i] = True
        for c in range(2):
            if v[i, c] == 0.0 and math.copysign(1.0, v[i, c]) < 0.0:
                busy[i] = True
    first = 0
    while first < n:  # run by run
        last = first
        run_busy = False
        while last < n and env[last] == env[first]:
            run_busy = run_busy or busy[last]
            last += 1
        for i in range(first, last):
            dv[i, 0] = 0.0
            dv[i, 1] = 0.0
            if run_busy:
                _changes(i, pos, v, nb_pos, nb_vel, mo_pos, mo_vel, hit, obstacle_share, dv)
        first = last


@numba.njit(cache=True, inline="always")
def _changes(i, pos, v, nb_pos, nb_vel, mo_pos, mo_vel, hit, obstacle_share,
             dv):  # pragma: no cover - numba
    """Eq 17's sum for row ``i`` (its conflicts ``hit[i]``) into ``dv[i]``."""
    n_k, n_m = nb_pos.shape[1], mo_pos.shape[1]
    vx, vy = v[i, 0], v[i, 1]
    ux0, uy0, _ = _unit(vx, vy)
    fx = 0.0
    fy = 0.0
    for s in range(n_k + n_m):
        if s < n_k:
            qx, qy, kx, ky = nb_pos[i, s, 0], nb_pos[i, s, 1], nb_vel[i, s, 0], nb_vel[i, s, 1]
            share = 1.0
        else:
            m = s - n_k
            qx, qy, kx, ky = mo_pos[i, m, 0], mo_pos[i, m, 1], mo_vel[i, m, 0], mo_vel[i, m, 1]
            share = obstacle_share
        ax, ay, _ = _unit(vx + kx, vy + ky)  # eq 17's common direction, then fallbacks
        if ax == 0.0 and ay == 0.0:
            ax, ay = ux0, uy0
        if ax == 0.0 and ay == 0.0:
            ax, ay, _ = _unit(kx, ky)
        rx, ry = pos[i, 0] - qx, pos[i, 1] - qy
        wx, wy = vx - kx, vy - ky
        half = 0.5 * math.sqrt(wx * wx + wy * wy) * share
        step = (half if rx * ax + ry * ay > 0.0 else -half) * (1.0 if hit[i, s] else 0.0)
        fx += step * ax
        fy += step * ay
    dv[i, 0] = fx
    dv[i, 1] = fy
