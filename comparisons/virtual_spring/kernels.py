"""Compiled eq 7 sources of ``virtual_spring``: the same numbers as the pure functions.

:meth:`~comparisons.virtual_spring.controller.VirtualSpring.spring` needs, for
every robot and source (static circles, polygons, neighbours, moving
obstacles), the unit vector from the source to the robot and the clearance;
as numpy expressions that is about forty small array operations per step.
:func:`spring_sources` does it in one compiled pass with the operations of
:func:`~comparisons.virtual_spring.equations.disc_normals`,
:func:`~comparisons.virtual_spring.equations.polygon_normals` and the first
half of :func:`~comparisons.virtual_spring.equations.spring_force`, and
:func:`weighted_sum` does eq 7's sum in numpy's order; the inverse cube
between them stays numpy's (``inverse_cube``: numba's ``pow`` differs from
numpy's in the last bit). ``tests/test_virtual_spring_fast.py`` checks the
controller's force against the pure functions bit for bit.
"""

from __future__ import annotations

import math

import numba

from comparisons.constraints.geometry_kernels import polygon_walk1

#: Below this norm a vector has no direction (m), as in :mod:`.equations`.
TINY = 1e-12


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
def spring_sources(pos, circles, circle_r, ea, eb, nb_pos, nb_mask, mo_pos,
                   mo_radius, mo_mask, radius, spring_range, min_distance, delta, dist,
                   use):  # pragma: no cover - numba
    """Fill eq 7's ``delta`` ``(N, S, 2)``, ``|delta|`` and the sources that count.

    Sources ``S = C + Q + K + M`` in this order: static circles ``(C, 2)`` with
    radii ``(C,)``, polygons (edge starts ``ea`` and ends ``eb`` ``(Q, V, 2)``,
    :class:`~comparisons.virtual_spring.equations.PolygonEdges`), neighbours
    ``(N, K, 2)`` (robot radius) and moving obstacles ``(N, M, 2)`` with radii
    ``(N, M)``. ``delta`` is the unit vector from the source times
    ``max(clearance, min_distance)``; a source counts when it is real (mask),
    within ``spring_range`` (m) and ``|delta| > TINY``.
    """
    n_c, n_q, n_k = circles.shape[0], ea.shape[0], nb_pos.shape[1]
    for i in range(pos.shape[0]):
        px, py = pos[i, 0], pos[i, 1]
        for s in range(delta.shape[1]):
            real = True
            if s < n_c:
                ux, uy, d = _unit(px - circles[s, 0], py - circles[s, 1])
                surface = d - circle_r[s]
            elif s < n_c + n_q:
                q = s - n_c
                ux, uy, surface = _polygon(px, py, ea[q], eb[q])
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


@numba.njit(cache=True)
def weighted_sum(w, delta, gain, out):  # pragma: no cover - numba
    """Fill ``out`` ``(N, 2)`` with ``gain * sum_s w[i, s] delta[i, s]``, in numpy's order.

    ``np.sum(axis=1)`` of these ``(N, S, 2)`` products adds them from 0.0 in
    source order (checked on this machine for S = 1 .. 300).
    """
    for i in range(delta.shape[0]):
        fx = 0.0
        fy = 0.0
        for s in range(delta.shape[1]):
            fx += w[i, s] * delta[i, s, 0]
            fy += w[i, s] * delta[i, s, 1]
        out[i, 0] = gain * fx
        out[i, 1] = gain * fy
