"""ORCA half-planes between robots (van den Berg et al. 2011; paper 001 eq 13, ref. [10]).

For robot A and neighbour B with relative position ``p = p_B - p_A``, relative
velocity ``v = v_A - v_B`` and combined radius ``R``, the velocity obstacle for
horizon ``tau`` is the truncated cone ``{v | exists t in [0, tau]: t v in D(p, R)}``
(paper 001 eq 7). ``u`` is the smallest change of ``v`` that leaves it (onto
the cut-off circle ``D(p / tau, R / tau)`` or onto a leg); A takes half of it:
the line passes through ``v_A + u / 2`` with direction perpendicular to ``u``
(reciprocity, responsibility 1/2). When A and B already overlap, the cut-off
circle of one time step (``tau = dt``) is used instead, as RVO2 does, so that
the pair separates within the step.

Lines are written in the convention of :mod:`comparisons.orca.lp` (point,
unit direction, allowed side on the left). The escape from a disc's truncated
cone, :func:`disc_vo_escape`, is shared with the improved VO of a static disc
(:mod:`comparisons.orca.ivo.discs`).
"""

from __future__ import annotations

import math

import numba


@numba.njit(cache=True, inline="always")
def disc_vo_escape(px, py, vx, vy, rad, inv_tau):  # pragma: no cover - numba
    """Smallest change ``u`` of ``v`` onto the boundary of a disc's truncated VO cone (eq 7).

    The velocity obstacle of the disc ``D(p, rad)`` (relative position ``p``,
    outside it: ``|p| > rad``) for horizon ``tau`` is the cone
    ``{v | exists t in [0, tau]: t v in D(p, rad)}``, cut off by ``D(p / tau, rad / tau)``.
    ``u`` goes from ``v`` to the nearest boundary point (onto the cut-off circle
    or onto a leg), whether ``v`` is inside the cone or not; the boundary's
    outward normal there is the left normal of the returned direction.

    Args:
        px: x of the disc centre relative to the robot, m.
        py: y of the disc centre relative to the robot, m.
        vx: x of the (relative) velocity, m/s.
        vy: y of the (relative) velocity, m/s.
        rad: Disc radius (combined radii), m.
        inv_tau: 1 / time horizon, 1/s.

    Returns:
        ``(dx, dy, ux, uy)``: unit direction of the boundary line at the nearest
        point (the VO on its right) and ``u``, m/s.
    """
    dist_sq = px * px + py * py
    rad_sq = rad * rad
    wx = vx - inv_tau * px  # from the cut-off centre to the relative velocity
    wy = vy - inv_tau * py
    w_sq = wx * wx + wy * wy
    dot = wx * px + wy * py
    if dot < 0.0 and dot * dot > rad_sq * w_sq:  # nearest boundary: cut-off circle
        w_len = math.sqrt(w_sq)
        ux_, uy_ = wx / w_len, wy / w_len
        dx, dy = uy_, -ux_
        scale = rad * inv_tau - w_len
        ux, uy = scale * ux_, scale * uy_
    else:  # nearest boundary: a leg of the cone
        leg = math.sqrt(dist_sq - rad_sq)
        if px * wy - py * wx > 0.0:  # left leg
            dx = (px * leg - py * rad) / dist_sq
            dy = (px * rad + py * leg) / dist_sq
        else:  # right leg
            dx = -(px * leg + py * rad) / dist_sq
            dy = -(-px * rad + py * leg) / dist_sq
        along = vx * dx + vy * dy
        ux, uy = along * dx - vx, along * dy - vy
    return dx, dy, ux, uy


@numba.njit(cache=True)
def agent_lines(ax, ay, avx, avy, a_r, nbr_pos, nbr_vel, nbr_r, n_nbr, inv_tau, inv_dt,
                P, D, start):  # pragma: no cover - numba
    """Write the ORCA lines of robot A against its ``n_nbr`` neighbours into ``P, D``.

    Args:
        ax: A's x position, m.
        ay: A's y position, m.
        avx: A's x velocity, m/s.
        avy: A's y velocity, m/s.
        a_r: A's radius, m.
        nbr_pos: ``(K, 2)`` neighbours' positions, m.
        nbr_vel: ``(K, 2)`` neighbours' velocities, m/s.
        nbr_r: ``(K,)`` neighbours' radii, m.
        n_nbr: Neighbours used (the first ``n_nbr`` rows, nearest first).
        inv_tau: 1 / time horizon, 1/s.
        inv_dt: 1 / time step, 1/s (overlapping pairs).
        P: ``(L, 2)`` output line points, m/s.
        D: ``(L, 2)`` output unit directions.
        start: First row of ``P, D`` to write.

    Returns:
        The row after the last one written.
    """
    k = start
    for j in range(n_nbr):
        px = nbr_pos[j, 0] - ax
        py = nbr_pos[j, 1] - ay
        vx = avx - nbr_vel[j, 0]
        vy = avy - nbr_vel[j, 1]
        dist_sq = px * px + py * py
        rad = a_r + nbr_r[j]
        rad_sq = rad * rad
        if dist_sq > rad_sq:
            dx, dy, ux, uy = disc_vo_escape(px, py, vx, vy, rad, inv_tau)
        else:  # overlapping: cut-off circle of one time step
            wx = vx - inv_dt * px
            wy = vy - inv_dt * py
            w_len = math.sqrt(wx * wx + wy * wy)
            ux_, uy_ = wx / w_len, wy / w_len
            dx, dy = uy_, -ux_
            scale = rad * inv_dt - w_len
            ux, uy = scale * ux_, scale * uy_
        P[k, 0] = avx + 0.5 * ux
        P[k, 1] = avy + 0.5 * uy
        D[k, 0] = dx
        D[k, 1] = dy
        k += 1
    return k
