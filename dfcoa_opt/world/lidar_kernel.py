"""The LiDAR's compiled kernels: grid walk with free-space jumps, ray-disc hits, whole scans.

The method is described in :mod:`dfcoa_opt.world.lidar`, which wraps these
kernels (:class:`~dfcoa_opt.world.lidar.Lidar`).
"""

from __future__ import annotations

import math

import numba
import numpy as np

#: Free-space jumps are taken only when they advance more than this many cells.
SKIP_MIN_CELLS = 2.0
_ANGLE_MARGIN = 1e-9  # rad added to a disc's half-angle; the exact test decides


@numba.njit(cache=True)
def _candidates(points, xy, reach, lo, width, n_keys, start, order):  # pragma: no cover
    """Both passes of :func:`disc_candidates`."""
    n = points.shape[0]
    r2 = reach * reach
    ptr = np.zeros(n + 1, dtype=np.int64)
    for fill in range(2):
        idx = np.empty(ptr[n] if fill else 0, dtype=np.int64)
        for i in range(n):
            cx = int(math.floor((points[i, 0] - lo[0]) / reach)) + 1
            cy = int(math.floor((points[i, 1] - lo[1]) / reach)) + 1
            k = ptr[i]
            for dy in range(-1, 2):
                for dx in range(-1, 2):
                    x, y = cx + dx, cy + dy
                    if x < 0 or x >= width or y < 0:
                        continue
                    cell = y * width + x
                    if cell >= n_keys:
                        continue
                    for q in range(start[cell], start[cell + 1]):
                        j = order[q]
                        ddx, ddy = xy[j, 0] - points[i, 0], xy[j, 1] - points[i, 1]
                        if ddx * ddx + ddy * ddy <= r2:
                            if fill:
                                idx[k] = j
                            k += 1
            if not fill:
                ptr[i + 1] = ptr[i] + (k - ptr[i])
        if fill:
            for i in range(n):  # each list in increasing disc index
                idx[ptr[i]:ptr[i + 1]].sort()
            return ptr, idx
    return ptr, np.empty(0, dtype=np.int64)


@numba.njit(cache=True)
def _walk(px, py, ux, uy, t, c, r, tlim, dist, ox, oy, h, skip):  # pragma: no cover - numba
    """Continue the ray ``p + t u`` from cell ``(r, c)`` (which holds the point at ``t``).

    Returns the parameter (m) where the ray enters the first occupied cell, or
    ``inf`` when that is beyond ``tlim`` or the ray leaves the grid first.
    """
    n_rows, n_cols = dist.shape
    res = 1.0 / h
    sx, fx = (1, 1) if ux > 0.0 else (-1, 0)  # step and far-side offset
    sy, fy = (1, 1) if uy > 0.0 else (-1, 0)
    iux = 1.0 / ux if ux != 0.0 else 0.0
    iuy = 1.0 / uy if uy != 0.0 else 0.0
    tx = (ox + (c + fx) * h - px) * iux if ux != 0.0 else np.inf
    ty = (oy + (r + fy) * h - py) * iuy if uy != 0.0 else np.inf
    half_diag = h * math.sqrt(0.5)
    min_jump = SKIP_MIN_CELLS * h
    check = min_jump + half_diag
    margin = 1e-7 * h
    while True:
        d = dist[r, c]
        if d == 0.0:
            return t
        if skip and d > check:
            dcx = px + t * ux - (ox + (c + 0.5) * h)
            dcy = py + t * uy - (oy + (r + 0.5) * h)
            free = d - math.sqrt(dcx * dcx + dcy * dcy) - half_diag
            if free > min_jump:
                t += free - margin  # lands >= margin away from every occupied square
                if t > tlim:
                    return np.inf
                gc = math.floor((px + t * ux - ox) * res)
                gr = math.floor((py + t * uy - oy) * res)
                if gc < 0 or gc >= n_cols or gr < 0 or gr >= n_rows:
                    return np.inf  # left the (convex) grid: never returns
                c = int(gc)
                r = int(gr)
                tx = (ox + (c + fx) * h - px) * iux if ux != 0.0 else np.inf
                ty = (oy + (r + fy) * h - py) * iuy if uy != 0.0 else np.inf
                continue
        if tx < ty:
            t = tx
            c += sx
            if c < 0 or c >= n_cols:
                return np.inf
            tx = (ox + (c + fx) * h - px) * iux
        else:
            t = ty
            r += sy
            if r < 0 or r >= n_rows:
                return np.inf
            ty = (oy + (r + fy) * h - py) * iuy
        if t > tlim:
            return np.inf


@numba.njit(cache=True)
def cast_grid(px, py, ux, uy, tlim, dist, ox, oy, h, skip):  # pragma: no cover - numba
    """Distance (m) along the unit ray ``(px, py) + t (ux, uy)`` to the first occupied cell.

    Args:
        px: Ray start x in m (inside or outside the grid).
        py: Ray start y in m.
        ux: Unit direction, x component.
        uy: Unit direction, y component.
        tlim: Largest distance of interest in m.
        dist: ``(H, W)`` 0 on occupied cells, else a lower bound of the distance (m)
            from the cell centre to the nearest occupied cell centre (``inf`` = none).
        ox: Grid origin x in m.
        oy: Grid origin y in m.
        h: Cell size in m.
        skip: Use distance-field jumps (``False`` = plain DDA; same result).

    Returns:
        The distance, 0 when the start lies in an occupied cell, ``inf`` when no
        occupied cell is entered at ``t <= tlim``.
    """
    n_rows, n_cols = dist.shape
    t = 0.0
    t_out = np.inf
    if ux != 0.0:  # clip the ray to the grid rectangle
        ta = (ox - px) / ux
        tb = (ox + n_cols * h - px) / ux
        t = max(t, min(ta, tb))
        t_out = min(t_out, max(ta, tb))
    elif px < ox or px > ox + n_cols * h:
        return np.inf
    if uy != 0.0:
        ta = (oy - py) / uy
        tb = (oy + n_rows * h - py) / uy
        t = max(t, min(ta, tb))
        t_out = min(t_out, max(ta, tb))
    elif py < oy or py > oy + n_rows * h:
        return np.inf
    if t > t_out or t > tlim:
        return np.inf
    c = min(max(int(math.floor((px + t * ux - ox) / h)), 0), n_cols - 1)
    r = min(max(int(math.floor((py + t * uy - oy) / h)), 0), n_rows - 1)
    return _walk(px, py, ux, uy, t, c, r, tlim, dist, ox, oy, h, skip)


@numba.njit(cache=True)
def _hit_disc(out_row, k, fx, fy, cc, ux, uy):  # pragma: no cover - numba
    """Nearest hit of beam ``k`` (unit ``u``) with a disc at offset ``f`` from the pose.

    ``cc = |f|^2 - r^2 > 0`` (pose outside the disc); keeps the minimum in ``out_row[k]``.
    """
    proj = fx * ux + fy * uy
    if proj <= 0.0:
        return
    disc = proj * proj - cc
    if disc < 0.0:
        return
    t = cc / (proj + math.sqrt(disc))  # the near root, without cancellation
    if t < out_row[k]:
        out_row[k] = t


@numba.njit(cache=True)
def _scan_kernel(poses, cos_a, sin_a, dists, world, par, disc_xy, disc_r, owner, cand_ptr,
                 cand_idx, skip, out):  # pragma: no cover - numba
    """Fill ``out`` ``(N, B)`` with REP-117 ranges (see :meth:`Lidar.scan`).

    ``dists`` ``(G, rows, cols)``: the distance fields of ``G`` grids of one
    geometry (``par``); row ``i`` casts in grid ``world[i]`` (``world`` empty:
    grid 0 for every row).
    """
    ox, oy, h, rmin, rmax, amin, inc = par[0], par[1], par[2], par[3], par[4], par[5], par[6]
    n_rows, n_cols = dists.shape[1], dists.shape[2]
    n_beams = cos_a.shape[0]
    n_discs = disc_r.shape[0]
    two_pi = 2.0 * math.pi
    half_diag = h * math.sqrt(0.5)
    inv_inc = 1.0 / inc if inc > 0.0 else 0.0
    period = two_pi * inv_inc  # 2 pi in beam-index units
    full = abs(inc * n_beams - two_pi) < 1e-9
    ux = np.empty(n_beams)
    uy = np.empty(n_beams)
    for i in range(poses.shape[0]):
        px, py, th = poses[i, 0], poses[i, 1], poses[i, 2]
        if not (np.isfinite(px) and np.isfinite(py) and np.isfinite(th)):
            raise ValueError("poses must be finite")
        ct, st = math.cos(th), math.sin(th)
        dist = dists[world[i]] if world.shape[0] > 0 else dists[0]
        row = out[i]
        for k in range(n_beams):
            ux[k] = ct * cos_a[k] - st * sin_a[k]
            uy[k] = st * cos_a[k] + ct * sin_a[k]
            row[k] = np.inf
        # ---- discs: analytic, only beams inside the angle each disc subtends
        if cand_ptr.shape[0] > 0:
            j0, j1 = cand_ptr[i], cand_ptr[i + 1]
        else:
            j0, j1 = 0, n_discs
        for jj in range(j0, j1):
            m = cand_idx[jj] if cand_ptr.shape[0] > 0 else jj
            if owner[m] == i:
                continue
            fx = disc_xy[m, 0] - px
            fy = disc_xy[m, 1] - py
            rad = disc_r[m]
            d2 = fx * fx + fy * fy
            cc = d2 - rad * rad
            if cc <= 0.0:  # inside the disc: every beam is blocked at once
                row[:] = 0.0
                break
            reach = rmax + rad
            if d2 > reach * reach:
                continue
            if inc == 0.0 or n_beams < 3:
                for k in range(n_beams):
                    _hit_disc(row, k, fx, fy, cc, ux[k], uy[k])
                continue
            # beams within asin(r / |f|) = atan(r / sqrt(cc)) <= r / sqrt(cc) of the centre
            half = min(rad / math.sqrt(cc), 2.0) + _ANGLE_MARGIN
            phi = math.atan2(ct * fy - st * fx, ct * fx + st * fy)  # robot frame, [-pi, pi]
            lo = (phi - half - amin) * inv_inc  # beam-index interval
            hi = (phi + half - amin) * inv_inc
            if full:  # the beams wrap around: index modulo B (no beam is visited twice)
                for kk in range(int(math.ceil(lo)), int(math.floor(hi)) + 1):
                    k = kk % n_beams
                    _hit_disc(row, k, fx, fy, cc, ux[k], uy[k])
                continue
            for s in (-period, 0.0, period):
                k0 = max(int(math.ceil(lo + s)), 0)
                k1 = min(int(math.floor(hi + s)), n_beams - 1)
                for k in range(k0, k1 + 1):
                    _hit_disc(row, k, fx, fy, cc, ux[k], uy[k])
        # ---- grid: the start cell and the first free-space jump are shared by all beams
        gc = math.floor((px - ox) / h)
        gr = math.floor((py - oy) / h)
        inside = 0 <= gc < n_cols and 0 <= gr < n_rows
        c0 = int(gc) if inside else 0
        r0 = int(gr) if inside else 0
        d0 = dist[r0, c0] if inside else np.inf
        t0 = 0.0
        if inside and skip and d0 > 0.0:
            dcx = px - (ox + (c0 + 0.5) * h)
            dcy = py - (oy + (r0 + 0.5) * h)
            free = d0 - math.sqrt(dcx * dcx + dcy * dcy) - half_diag
            if free > SKIP_MIN_CELLS * h:
                t0 = free - 1e-7 * h
        for k in range(n_beams):
            v = row[k]
            tlim = min(v, rmax)
            if tlim > 0.0:
                if not inside:
                    g = cast_grid(px, py, ux[k], uy[k], tlim, dist, ox, oy, h, skip)
                elif d0 == 0.0:
                    g = 0.0
                elif t0 == 0.0:
                    g = _walk(px, py, ux[k], uy[k], 0.0, c0, r0, tlim, dist, ox, oy, h, skip)
                elif t0 > tlim:
                    g = np.inf
                else:
                    gc = math.floor((px + t0 * ux[k] - ox) / h)
                    gr = math.floor((py + t0 * uy[k] - oy) / h)
                    if 0 <= gc < n_cols and 0 <= gr < n_rows:
                        g = _walk(px, py, ux[k], uy[k], t0, int(gc), int(gr), tlim, dist, ox,
                                  oy, h, skip)
                    else:
                        g = np.inf
                if g < v:
                    v = g
            if v > rmax:
                v = np.inf
            elif v < rmin:
                v = -np.inf
            row[k] = v
