"""The improved velocity obstacle (IVO) of paper 001, section III.B (eq 8-11), for polygons.

Static discs take the closed form of :mod:`comparisons.orca.ivo.discs`, one line
per disc (see "Circular obstacles" below); :func:`ivo_lines` merges both kinds.

Each polygon edge (optionally split into pieces) is a segment ``l``; it is
enclosed by an ellipse ``O'`` (eq 8); the velocity obstacle of ``O'`` for a
horizon ``tau`` (eq 9) gives one half-plane of feasible velocities (eq 10) with
``alpha = 1``; the caller intersects the half-planes with the speed disc
``D(0, v_max)`` (eq 11) and picks the velocity nearest ``v_pref`` (eq 12) with
:func:`comparisons.orca.lp.solve_lines`, the lines being kept hard.

Decisions (the paper's words, then the reading taken here):

* **Eq 8, the ellipse.** "I is extended to an ellipse, denoted as O' ... the
  shortest distance between the expanded convex packet and the original line
  segment should be greater than r_A", ``d = min(|l - O' (+) D(p_A, r_A)|) > r_A``.
  Read literally, the formula is almost vacuous: for a convex ``O'`` holding a
  point ``q`` the distance from ``q`` to the boundary of ``O' (+) D(r)`` is
  ``r + dist(q, boundary of O')``, so ``d > r_A`` only asks ``l`` to lie inside
  ``O'``. The words ask for more: the ellipse's boundary keeps a *clearance*
  ``m`` from the segment, ``min_{q in l} dist(q, boundary of O') >= m``, i.e.
  ``O'`` contains the capsule ``l (+) D(0, m)``. The default ``m = r_A`` is the
  words' reading; ``m -> 0`` is the literal one (``O'`` shrinks to ``l``).
  The ellipse is centred at the segment midpoint with its major axis along the
  segment; with half-length ``c``, ``a = stretch (c + m)`` (``stretch >= 1``,
  default 1: the tips reach exactly ``m`` past the end points) and ``b`` is the
  smallest semi-minor axis for which the capsule fits. The capsule is the
  convex hull of the two end discs ``D(end, m)``, so it is inside the (convex)
  ellipse iff both end discs are; the distance from ``(c, 0)`` to the ellipse
  is ``b sqrt(1 - c^2 / (a^2 - b^2))`` while the nearest point is off the axis,
  and equating it to ``m`` gives ``b^2 = ((a^2 - c^2 + m^2) - sqrt(((a - m)^2 -
  c^2)((a + m)^2 - c^2))) / 2``; for ``stretch = 1`` this is ``b^2 = m (c + m)``
  (the end disc is the osculating circle at the tip, inside the ellipse by
  Blaschke's rolling theorem since ``b^2 / a`` is the ellipse's smallest
  radius of curvature). Long edges give fat ellipses (``b ~ sqrt(m c)``): split
  them with ``max_segment`` (Fig. 2's "set of line segments").
* **Eq 9, the Minkowski sum.** ``IVO = {v | exists t in [0, tau]: t v in
  O' (+) D(p_A, r_A)}``. The sum ``K = O' (+) D(r_A)`` is treated *exactly*,
  through its support function ``h_K(n) = n . c + sqrt(a^2 (n . e1)^2 +
  b^2 (n . e2)^2) + r_A`` (support functions add under Minkowski sums). Inflating
  the semi-axes to ``(a + r_A, b + r_A)`` does **not** enclose ``K`` when
  ``a != b``: its support ``sqrt((a + r)^2 n1^2 + (b + r)^2 n2^2)`` is below
  ``sqrt(a^2 n1^2 + b^2 n2^2) + r`` for every oblique ``n`` (Jensen:
  ``(a n1^2 + b n2^2)^2 < a^2 n1^2 + b^2 n2^2``). The truncated cone
  ``C = union_{s >= 1/tau} s K`` is convex with support ``h_C(n) = h_K(n) / tau``
  where ``h_K(n) <= 0`` (else ``+inf``), so the signed distance from ``v`` to
  ``C`` is ``max_{n: h_K(n) <= 0} (n . v - h_K(n) / tau)``: a 1D maximisation
  over an arc of normals whose ends are the cone's legs (tangent lines from
  ``p_A`` to ``K``, found by bisection on the sign of ``h_K``). It is solved by
  dense sampling and golden-section refinement of the best local optima, so
  ``u`` is the minimal escape to ~1e-7 m/s (the normal to ~1e-8 rad, the
  resolution of comparing values near a smooth optimum). Whatever normal
  the optimiser returns, the half-plane ``n . v >= h_K(n) / tau`` supports the
  convex ``C`` and excludes all of it: safety does not depend on optimality.
* **Eq 9, the horizon.** "tau = dist_{A|O'} / v_A^opt. It means that moving at
  the current velocity, the robot will collide within this time." Read with
  ``dist_{A|O'}`` the distance from the robot's centre ``p_A`` to ``O'``
  (``tau="center"``, default) and ``|v_A^opt|`` the speed: ``tau`` is the time
  the centre needs to reach ``O'``, so a head-on approach is inside the VO and
  the line brakes it to ``s (dist - r_A) / dist``, a speed that shrinks with
  the gap. ``tau="gap"`` uses the gap ``dist - r_A`` (the time to contact):
  then a head-on ``v_opt`` lies exactly on the cut-off and its line only
  forbids approaching faster than now; the braking is left to the floor
  ``tau_min`` and happens in the last step (documented, not the default). A
  float gives a fixed horizon. ``tau`` is clipped to ``[tau_min, tau_max]``
  (defaults 0.1 s and 10 s); a robot at rest (``|v_opt| * tau_max <= dist``)
  gets ``tau_max``. Every velocity allowed by the line stays out of ``K`` for
  ``t <= tau``, so ``tau_min >= dt`` (and a fixed ``tau >= dt``) keeps the
  centre out of ``K`` after a step of length ``dt``.
* **Eq 10, the half-plane.** ``{v | (v - (v_opt + alpha u)) . n >= 0}``, ``u``
  the smallest change of ``v_opt`` leaving the VO, ``n`` its (outward) normal,
  ``alpha = 1`` for static obstacles ("the robot ... needs to pay full
  responsibility"). As in ORCA, the same formula is used when ``v_opt`` is
  already outside the VO (``u`` then points back to the nearest VO point and
  ``v_opt`` satisfies its own line). With ``alpha = 1`` every line contains
  ``v = 0``, so the hard lines are always feasible together with the speed disc.
* **Inside ``K``** (``p_A`` in ``O' (+) D(r_A)``, every ``v`` is in the VO
  through ``t = 0``): push-out half-plane ``n . v >= push_speed`` with ``n``
  the outward normal at the boundary point of ``K`` nearest ``p_A`` (RVO2's
  obstacle-collision line for ``push_speed = 0``, the default, which keeps
  ``v = 0`` feasible; a positive value pushes out but can make opposing hard
  lines infeasible).

* **Circular obstacles** (not in the paper, whose obstacles are polygons). A
  disc ``D(c, R)`` is its own enclosing ellipse: ``O' = D(c, R + m)``, i.e.
  ``a = b = R + m`` with the clearance ``m`` above, so it is treated exactly, as
  one disc, rather than as the 32 edges of its circumscribed polygon. Its VO is
  the truncated cone of a disc and ``u`` has a closed form
  (:func:`comparisons.orca.ivo.discs.disc_pair_line`); the horizon, ``alpha``
  and the push-out line are those above, and the line equals :func:`ivo_line`'s
  for ``a = b`` to ~1e-6 (``tests/test_ivo_disc.py``).

Lines are in the convention of :mod:`comparisons.orca.lp`: a point ``p`` and a
unit direction ``d``, the allowed side on the left, ``det(d, p - v) <= 0``;
here ``d = (n_y, -n_x)`` so that the left normal of ``d`` is ``n``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from comparisons.orca.ivo.discs import IvoLine, as_line, disc_distances, tau_rule
from comparisons.orca.ivo.ellipse import Ellipse, polygon_segments
from comparisons.orca.ivo.kernel import (
    BISECT_ITERS,
    GOLDEN_ITERS,
    N_REFINE,
    N_SAMPLES,
    lines_kernel,
    pair_line,
)
from dfcoa_opt.core.geometry import point_segment_distance
from dfcoa_opt.core.runtime.threads import kernel_threads

FloatArray = NDArray[np.float64]

__all__ = ["BISECT_ITERS", "GOLDEN_ITERS", "N_REFINE", "N_SAMPLES", "IvoObstacles", "ivo_line",
           "ivo_lines"]

#: Coordinate of the padding items of :class:`IvoObstacles`, m: a world with fewer
#: segments or discs than the largest is padded with points this far away, whose
#: distance (~1.4e100 m) exceeds any avoidance range, so they never get a line.
FAR = 1e100


@dataclass(frozen=True)
class IvoObstacles:
    """The segments and static discs of one or more worlds (a batch of runs), prepared once.

    Attributes:
        segments: ``(W, S, 4)`` each world's segments ``(x0, y0, x1, y1)``, m, padded
            past its own with zero-length segments at ``(FAR, FAR)``.
        discs: ``(W, C, 3)`` each world's discs ``(cx, cy, R)``, m, padded past its
            own with ``(FAR, FAR, 0)``.
        flat_segments: ``(sum S_w, 4)`` the real segments of every world, in order, m.
        flat_discs: ``(sum C_w, 3)`` the real discs of every world, in order, m.
        segment_start: ``(W,)`` index of each world's first segment in ``flat_segments``.
        disc_start: ``(W,)`` index of each world's first disc in ``flat_discs``.
    """

    segments: FloatArray
    discs: FloatArray
    flat_segments: FloatArray
    flat_discs: FloatArray
    segment_start: NDArray[np.int64]
    disc_start: NDArray[np.int64]

    @classmethod
    def from_worlds(cls, worlds: list[tuple[ArrayLike, ArrayLike]]) -> IvoObstacles:
        """Pad and stack the worlds' ``(segments (S_w, 4), discs (C_w, 3))``, m."""
        segs = [np.asarray(sg, dtype=float).reshape(-1, 4) for sg, _ in worlds]
        discs = [np.asarray(dc, dtype=float).reshape(-1, 3) for _, dc in worlds]
        n_seg = [len(x) for x in segs]
        n_disc = [len(x) for x in discs]
        seg_pad = np.full((len(worlds), max(n_seg, default=0), 4), FAR)
        disc_pad = np.tile([FAR, FAR, 0.0], (len(worlds), max(n_disc, default=0), 1))
        for w, (sg, dc) in enumerate(zip(segs, discs, strict=True)):
            seg_pad[w, :len(sg)] = sg
            disc_pad[w, :len(dc)] = dc
        return cls(seg_pad, disc_pad, np.concatenate([np.zeros((0, 4)), *segs]),
                   np.concatenate([np.zeros((0, 3)), *discs]),
                   np.cumsum([0, *n_seg[:-1]], dtype=np.int64),
                   np.cumsum([0, *n_disc[:-1]], dtype=np.int64))

    @property
    def n_worlds(self) -> int:
        """Number of worlds ``W``."""
        return len(self.segments)

    def rows(self, world: NDArray[np.intp] | None) -> tuple[FloatArray, FloatArray]:
        """Segments ``(R, S, 4)`` and discs ``(R, C, 3)`` of each row's world, m.

        One world (or ``world`` None) gives its tables as ``(1, S, 4)`` and ``(1, C, 3)``,
        shared by every row.
        """
        if world is None or self.n_worlds == 1:
            return self.segments[:1], self.discs[:1]
        return self.segments[world], self.discs[world]


def ivo_line(pos: ArrayLike, v_opt: ArrayLike, radius: float, ellipse: Ellipse,
             tau: float | str = "center", tau_min: float = 0.1, tau_max: float = 10.0,
             alpha: float = 1.0, push_speed: float = 0.0) -> IvoLine:
    """The IVO half-plane of one robot against one ellipse (eq 9-10).

    Args:
        pos: ``(2,)`` robot position ``p_A``, m.
        v_opt: ``(2,)`` its optimal velocity ``v_A^opt`` (usually the current one), m/s.
        radius: Robot radius ``r_A``, m.
        ellipse: The obstacle ellipse ``O'`` (e.g. from :func:`segment_ellipse`).
        tau: Horizon of eq 9: ``"center"`` (``dist(p_A, O') / |v_opt|``),
            ``"gap"`` (``(dist(p_A, O') - r_A) / |v_opt|``) or a fixed value, s.
        tau_min: Floor of the eq-9 horizon, s.
        tau_max: Cap of the eq-9 horizon (also used when ``v_opt ~ 0``), s.
        alpha: Responsibility ``alpha`` of eq 10 (1: static obstacle).
        push_speed: Outward speed required when ``p_A`` is inside ``O' (+) D(r_A)``, m/s.

    Returns:
        The line and its ingredients.
    """
    p = np.asarray(pos, dtype=float)
    v = np.asarray(v_opt, dtype=float)
    rule, fixed = tau_rule(tau)
    out = np.empty(10)
    c = ellipse.centre - p
    pair_line(c[0], c[1], ellipse.axis[0], ellipse.axis[1], ellipse.a, ellipse.b,
              float(radius), v[0], v[1], rule, fixed, float(tau_min), float(tau_max),
              float(alpha), float(push_speed), np.empty(N_SAMPLES + 1), out)
    return as_line(out)


def ivo_lines(pos: ArrayLike, vel_opt: ArrayLike, radius: ArrayLike,
              polygons: list[ArrayLike] | FloatArray | IvoObstacles | None,
              max_range: float, tau: float | str = "center", tau_min: float = 0.1,
              tau_max: float = 10.0, clearance: float | ArrayLike | None = None,
              stretch: float = 1.0, max_segment: float | None = None,
              max_lines: int | None = None, alpha: float = 1.0, push_speed: float = 0.0,
              discs: ArrayLike | None = None, world: ArrayLike | None = None
              ) -> tuple[FloatArray, FloatArray, NDArray[np.int64]]:
    """IVO half-planes (eq 10) of ``N`` robots against polygons and discs, nearest first.

    One line per segment (polygon edge or piece) and per disc whose distance to
    the robot's centre (to the segment, to the disc's boundary) is at most
    ``max_range`` (eq 11's "obstacles within the obstacle avoidance range"),
    ordered by that distance (segments before discs on ties). Use them as hard lines of
    :func:`comparisons.orca.velocities.orca_velocities` or
    :func:`comparisons.orca.lp.solve_lines` (which adds ``D(0, v_max)``, eq 11).

    Args:
        pos: ``(N, 2)`` robot positions, m.
        vel_opt: ``(N, 2)`` optimal velocities ``v_A^opt`` (usually the current ones), m/s.
        radius: ``(N,)`` or scalar robot radii ``r_A``, m.
        polygons: Obstacle vertex arrays ``(M, 2)``, m (see :func:`polygon_segments`),
            or the ``(S, 4)`` array that function returns (computed once by a
            caller that steps many times; ``max_segment`` is then not used),
            or an :class:`IvoObstacles` of one or more worlds (then ``discs`` is
            None: the table holds them); ``None``: no polygons.
        max_range: Obstacle avoidance range, m.
        tau: Horizon of eq 9: ``"center"``, ``"gap"`` or a fixed value, s (see
            :func:`ivo_line`).
        tau_min: Floor of the eq-9 horizon, s.
        tau_max: Cap of the eq-9 horizon (also used when ``v_opt ~ 0``), s.
        clearance: ``(N,)`` or scalar eq-8 clearance ``m``, m; ``None``: the radii.
        stretch: Ellipse elongation ``a / (c + m) >= 1`` (eq 8).
        max_segment: Split edges longer than this, m (``None``: whole edges).
        max_lines: Most lines per robot (the nearest kept); ``None``: all in range.
        alpha: Responsibility ``alpha`` of eq 10 (1: static obstacles).
        push_speed: Outward speed required inside ``O' (+) D(r_A)``, m/s.
        discs: ``(C, 3)`` static discs ``(cx, cy, R)``, m, each treated exactly as the
            ellipse ``O' = D(c, R + m)`` (:mod:`comparisons.orca.ivo.discs`); ``None``: none.
        world: ``(N,)`` each robot's world in an :class:`IvoObstacles` of several
            worlds (a batch of runs): a robot sees its own world's obstacles only,
            and gets the lines it would get alone in that world, bit for bit.

    Returns:
        ``(points (N, H, 2) m/s, directions (N, H, 2), count (N,))`` in the
        convention of :mod:`comparisons.orca.lp`, rows padded past ``count``
        (``H = max(count)``).

    Raises:
        ValueError: If ``stretch < 1``, a clearance or disc radius is negative, a
            fixed ``tau`` is not positive, or a table of several worlds comes
            without ``world``.
    """
    # fresh writable C arrays: one numba signature whatever the callers pass
    p = np.array(np.asarray(pos, dtype=float).reshape(-1, 2))
    n = len(p)
    v = np.array(np.asarray(vel_opt, dtype=float).reshape(n, 2))
    r = np.array(np.broadcast_to(np.asarray(radius, dtype=float), (n,)))
    m = np.array(np.broadcast_to(r if clearance is None else np.asarray(clearance, float), (n,)))
    if isinstance(polygons, IvoObstacles):
        if discs is not None:
            raise ValueError("an IvoObstacles table holds its discs: give discs=None")
        table = polygons
    else:
        prepared = (isinstance(polygons, np.ndarray) and polygons.ndim == 2
                    and polygons.shape[1] == 4)
        seg = polygons if prepared else polygon_segments([] if polygons is None else polygons,
                                                         max_segment)
        table = IvoObstacles.from_worlds([(seg, [] if discs is None else discs)])
    if world is None and table.n_worlds > 1:
        raise ValueError("an IvoObstacles table of several worlds needs each robot's world")
    if stretch < 1.0 or np.any(m < 0.0) or np.any(table.discs[..., 2] < 0.0):
        raise ValueError("need stretch >= 1, clearance >= 0 and disc radii >= 0")
    rule, fixed = tau_rule(tau)
    seg, disc = table.rows(None if world is None else np.asarray(world, dtype=np.intp))
    n_seg, n_disc = seg.shape[1], disc.shape[1]
    if n_seg + n_disc == 0 or n == 0:
        return np.zeros((n, 0, 2)), np.zeros((n, 0, 2)), np.zeros(n, np.int64)
    dist = point_segment_distance(p[:, None, :], seg[..., 0:2], seg[..., 2:4])
    if n_disc:
        dist = np.hstack([dist.reshape(n, n_seg), disc_distances(p, disc)])
    dist[dist > max_range] = np.inf
    order = np.argsort(dist, axis=1, kind="stable")
    count = np.isfinite(dist).sum(axis=1)
    if max_lines is not None:
        count = np.minimum(count, max_lines)
    h = int(count.max())
    order = order[:, :h]
    if table.n_worlds > 1:  # items of the row's world -> items of the flat tables
        w = np.asarray(world, dtype=np.intp)[:, None]
        order = np.where(order < n_seg, order + table.segment_start[w],
                         len(table.flat_segments) + table.disc_start[w] + (order - n_seg))
    order = np.ascontiguousarray(order, dtype=np.int64)
    count = count.astype(np.int64)
    P = np.zeros((n, h, 2))
    D = np.zeros((n, h, 2))
    with kernel_threads(n):
        lines_kernel(p, v, r, m, np.ascontiguousarray(table.flat_segments),
                     np.ascontiguousarray(table.flat_discs), order, count, float(stretch), rule,
                     fixed, float(tau_min), float(tau_max), float(alpha), float(push_speed), P, D)
    return P, D, count
