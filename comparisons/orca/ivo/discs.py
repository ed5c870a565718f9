"""The improved VO (paper 001, eq 8-10) of a static disc, in closed form; eq 9's horizon rules.

Paper 001 builds its ellipses ``O'`` (eq 8) around the segments of polygon
obstacles only. A circular obstacle ``D(c, R)`` needs no segments: the smallest
ellipse whose boundary keeps the clearance ``m`` from the disc (the eq-8 reading
of :mod:`comparisons.orca.ivo.polygons`) is the disc ``O' = D(c, R + m)`` itself
(``a = b = R + m``). Then ``K = O' (+) D(r_A) = D(c, R + m + r_A)``, the velocity
obstacle of eq 9 is the classic truncated cone of a disc (paper 001 eq 7), and
the smallest escape ``u`` from ``v_opt`` has the closed form of RVO2's
agent-agent line (:func:`comparisons.orca.lines.disc_vo_escape`), here with the
relative velocity ``v_opt`` (the obstacle is static), responsibility ``alpha``
(1 for static obstacles, eq 10) and eq 9's horizon ``tau``. Inside ``K`` the
line is the push-out line ``n . v >= push_speed``, ``n`` the outward normal
from ``c`` to ``p_A``. This is the same half-plane as the numerical ellipse path
of :mod:`comparisons.orca.ivo.polygons` with ``a = b`` (tested to 1e-6), at one line per
disc instead of one per edge of its 32-gon.

The pieces shared with the ellipse path also live here: eq 9's horizon rules
(:func:`tau_rule`, :func:`eq9_horizon`) and the :class:`IvoLine` record.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from comparisons.orca.lines import disc_vo_escape

FloatArray = NDArray[np.float64]

#: Horizon rules of eq 9 (``TAU_FIXED``: the caller's constant).
TAU_FIXED, TAU_CENTER, TAU_GAP = 0, 1, 2
_TAU_RULES = {"center": TAU_CENTER, "gap": TAU_GAP}


@dataclass(frozen=True)
class IvoLine:
    """One IVO half-plane (eq 10) with its ingredients.

    Attributes:
        point: ``(2,)`` the point ``v_opt + alpha u`` of the line, m/s.
        direction: ``(2,)`` unit direction; the allowed side is the left.
        normal: ``(2,)`` unit normal ``n`` pointing into the allowed side.
        u: ``(2,)`` smallest change of ``v_opt`` onto the VO boundary, m/s.
        tau: Horizon used (eq 9), s; 0 when the robot is inside ``O' (+) D(r_A)``.
        inside: Whether the robot's centre is inside ``O' (+) D(r_A)`` (push-out line).
    """

    point: FloatArray
    direction: FloatArray
    normal: FloatArray
    u: FloatArray
    tau: float
    inside: bool



def tau_rule(tau: float | str) -> tuple[int, float]:
    """Encode the eq-9 ``tau`` argument as ``(rule, fixed value)``.

    Args:
        tau: ``"center"``, ``"gap"`` or a fixed horizon, s.

    Returns:
        ``(TAU_CENTER | TAU_GAP | TAU_FIXED, fixed horizon in s or 0)``.

    Raises:
        ValueError: If ``tau`` is an unknown rule or a fixed value that is not positive.
    """
    if isinstance(tau, str):
        if tau not in _TAU_RULES:
            raise ValueError(f"tau must be a positive float or one of {sorted(_TAU_RULES)}")
        return _TAU_RULES[tau], 0.0
    if not tau > 0.0:
        raise ValueError("a fixed tau must be positive")
    return TAU_FIXED, float(tau)


@numba.njit(cache=True, inline="always")
def eq9_horizon(rule, fixed, dist, vx, vy, tau_min, tau_max):  # pragma: no cover - numba
    """Eq 9's horizon ``tau = dist / |v_opt|``, clipped to ``[tau_min, tau_max]``.

    Args:
        rule: ``TAU_FIXED``, ``TAU_CENTER`` or ``TAU_GAP``.
        fixed: The horizon of ``TAU_FIXED``, s.
        dist: ``dist_{A|O'}`` of the rule, m: from ``p_A`` (``TAU_CENTER``) or from
            the robot's rim (``TAU_GAP``) to ``O'``.
        vx: x of ``v_opt``, m/s.
        vy: y of ``v_opt``, m/s.
        tau_min: Floor, s.
        tau_max: Cap, also used when ``|v_opt| tau_max <= dist`` (at rest), s.

    Returns:
        The horizon, s.
    """
    if rule == TAU_FIXED:
        return fixed
    speed = math.sqrt(vx * vx + vy * vy)
    return tau_max if speed * tau_max <= dist else max(dist / speed, tau_min)


@numba.njit(cache=True)
def disc_pair_line(cx, cy, big, r, vx, vy, tau_rule, tau_fixed, tau_min, tau_max, alpha,
                   push_speed, out):  # pragma: no cover - numba
    """One IVO line (eq 9-10) against the disc ``O' = D(c, big)``, robot at the origin.

    Args:
        cx: x of the disc centre relative to ``p_A``, m.
        cy: y of the disc centre relative to ``p_A``, m.
        big: Radius of ``O'``, ``R + m`` (obstacle radius plus eq-8 clearance), m.
        r: Robot radius ``r_A``, m.
        vx: x of ``v_opt``, m/s.
        vy: y of ``v_opt``, m/s.
        tau_rule: Eq-9 rule code (see :func:`eq9_horizon`).
        tau_fixed: Horizon of ``TAU_FIXED``, s.
        tau_min: Floor of the horizon, s.
        tau_max: Cap of the horizon, s.
        alpha: Responsibility of eq 10.
        push_speed: Outward speed required inside ``K = D(c, big + r_A)``, m/s.
        out: ``(10,)`` output, as :func:`comparisons.orca.ivo.kernel.pair_line`: point (2),
            direction (2), tau, inside flag, u (2), normal (2).
    """
    rad = big + r  # K = O' (+) D(r_A)
    dist = math.sqrt(cx * cx + cy * cy)
    if dist <= rad:  # p_A in K: push out along the normal from c to p_A
        nx, ny = (-cx / dist, -cy / dist) if dist > 0.0 else (1.0, 0.0)
        gap = push_speed - (nx * vx + ny * vy)
        ux, uy = gap * nx, gap * ny
        dx, dy = ny, -nx
        tau = 0.0
        inside = 1.0
    else:
        to_o = dist - big - (r if tau_rule == TAU_GAP else 0.0)  # eq 9's dist_{A|O'}
        tau = eq9_horizon(tau_rule, tau_fixed, to_o, vx, vy, tau_min, tau_max)
        dx, dy, ux, uy = disc_vo_escape(cx, cy, vx, vy, rad, 1.0 / tau)
        nx, ny = -dy, dx
        inside = 0.0
    out[0] = vx + alpha * ux
    out[1] = vy + alpha * uy
    out[2] = dx
    out[3] = dy
    out[4] = tau
    out[5] = inside
    out[6] = ux
    out[7] = uy
    out[8] = nx
    out[9] = ny


def disc_distances(pos: ArrayLike, discs: ArrayLike) -> FloatArray:
    """Distance from robot centres to disc obstacles (0 inside), the ordering key of the lines.

    Args:
        pos: ``(N, 2)`` robot positions, m.
        discs: ``(C, 3)`` discs ``(cx, cy, R)``, m, the same for every robot; or
            ``(N, C, 3)`` (or ``(1, C, 3)``), each robot's own.

    Returns:
        ``(N, C)`` distances from each centre to each disc, m.
    """
    p = np.asarray(pos, dtype=float).reshape(-1, 2)
    d = np.asarray(discs, dtype=float)
    d = d if d.ndim == 3 else d.reshape(1, -1, 3)
    centre = np.linalg.norm(p[:, None, :] - d[..., 0:2], axis=-1)
    return np.maximum(centre - d[..., 2], 0.0)


def disc_line(pos: ArrayLike, v_opt: ArrayLike, radius: float, centre: ArrayLike,
              disc_radius: float, clearance: float | None = None, tau: float | str = "center",
              tau_min: float = 0.1, tau_max: float = 10.0, alpha: float = 1.0,
              push_speed: float = 0.0) -> IvoLine:
    """The IVO half-plane of one robot against a static disc ``D(c, R)``, closed form.

    Eq 8 gives ``O' = D(c, R + m)`` (``a = b = R + m``), eq 9-10 the line of
    :func:`comparisons.orca.ivo.polygons.ivo_line` for that ellipse (module docstring).

    Args:
        pos: ``(2,)`` robot position ``p_A``, m.
        v_opt: ``(2,)`` its optimal velocity ``v_A^opt``, m/s.
        radius: Robot radius ``r_A``, m.
        centre: ``(2,)`` disc centre ``c``, m.
        disc_radius: Disc radius ``R >= 0``, m.
        clearance: Eq-8 clearance ``m >= 0``, m; ``None``: ``radius``.
        tau: Horizon of eq 9: ``"center"``, ``"gap"`` or a fixed value, s.
        tau_min: Floor of the eq-9 horizon, s.
        tau_max: Cap of the eq-9 horizon (also used when ``v_opt ~ 0``), s.
        alpha: Responsibility ``alpha`` of eq 10 (1: static obstacle).
        push_speed: Outward speed required inside ``D(c, R + m + r_A)``, m/s.

    Returns:
        The line and its ingredients.

    Raises:
        ValueError: If ``disc_radius`` or the clearance is negative, or a fixed ``tau``
            is not positive.
    """
    p = np.asarray(pos, dtype=float)
    v = np.asarray(v_opt, dtype=float)
    c = np.asarray(centre, dtype=float) - p
    m = float(radius if clearance is None else clearance)
    if disc_radius < 0.0 or m < 0.0:
        raise ValueError("need disc_radius >= 0 and clearance >= 0")
    rule, fixed = tau_rule(tau)
    out = np.empty(10)
    disc_pair_line(c[0], c[1], float(disc_radius) + m, float(radius), v[0], v[1], rule, fixed,
                   float(tau_min), float(tau_max), float(alpha), float(push_speed), out)
    return as_line(out)


def as_line(out: FloatArray) -> IvoLine:
    """The :class:`IvoLine` of a kernel's ``(10,)`` output row."""
    return IvoLine(out[0:2].copy(), out[2:4].copy(), out[8:10].copy(), out[6:8].copy(),
                   float(out[4]), bool(out[5]))
