"""Formation geometry: slot offsets in the virtual leader's body frame.

A formation is an ``(N, 2)`` array of offsets ``(x forward, y left)`` in m. The
world position of robot i's slot is ``body_to_world(leader_pose, offsets[i])``
(paper 000 eq 4 and eq 30).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.core.geometry import body_to_world
from dfcoa_opt.scenario.schema import FormationSpec


def rectangle_polar(width: float, length: float) -> tuple[float, float]:
    """Paper 000 eq 3: angle and distance of a rectangle corner from its centre.

    Args:
        width: Rectangle width w across the heading, m.
        length: Rectangle length l along the heading, m.

    Returns:
        ``(theta_i, d_i)`` with ``theta_i = atan(w / l)`` (rad) and
        ``d_i = w / (2 sin theta_i)`` (m), i.e. half the diagonal.
    """
    theta = math.atan(width / length)
    return theta, width / (2.0 * math.sin(theta))


def rectangle_offsets(width: float, length: float) -> NDArray[np.float64]:
    """Paper 000 eq 3-5: the four corner slots of a w x l rectangle.

    The paper gives one angle ``theta_i``; the four robots sit at
    ``theta_i``, ``pi - theta_i``, ``pi + theta_i`` and ``-theta_i`` (front-left,
    rear-left, rear-right, front-right; docs/reproduction.md).

    Returns:
        ``(4, 2)`` offsets in m.
    """
    theta, d = rectangle_polar(width, length)
    angles = np.array([theta, math.pi - theta, math.pi + theta, -theta])
    return polar_offsets(np.full(4, d), angles)


def polar_offsets(d: NDArray[np.float64], phi: NDArray[np.float64]) -> NDArray[np.float64]:
    """Offsets from radial distances ``d_a`` (m) and angles ``phi_a`` (rad), paper 000 eq 30."""
    d, phi = np.asarray(d, dtype=float), np.asarray(phi, dtype=float)
    return np.stack((d * np.cos(phi), d * np.sin(phi)), axis=1)


def v_offsets(n: int, spacing: float, angle: float) -> NDArray[np.float64]:
    """V formation (paper 002 eq 5-6): robot 0 at the apex, the others on two wings.

    Follower k (1-based) sits ``ceil(k/2) * spacing`` behind the apex along a
    wing at half-angle ``angle`` from the backward axis, odd k on the left.

    Returns:
        ``(n, 2)`` offsets in m.
    """
    k = np.arange(n)
    rank = np.ceil(k / 2.0)
    side = np.where(k % 2 == 1, 1.0, -1.0)
    return np.stack((-rank * spacing * math.cos(angle), side * rank * spacing * math.sin(angle)),
                    axis=1)


def line_offsets(n: int, spacing: float) -> NDArray[np.float64]:
    """Robots abreast on a line across the heading, centred on the leader."""
    y = (np.arange(n) - (n - 1) / 2.0) * spacing
    return np.stack((np.zeros(n), y[::-1]), axis=1)


def grid_offsets(n: int, spacing: float, columns: int = 0) -> NDArray[np.float64]:
    """Robots on a grid (row-major, front row first), centred on the leader."""
    cols = columns or math.ceil(math.sqrt(n))
    rows = math.ceil(n / cols)
    k = np.arange(n)
    r, c = k // cols, k % cols
    x = ((rows - 1) / 2.0 - r) * spacing
    y = ((cols - 1) / 2.0 - c) * spacing
    return np.stack((x, y), axis=1)


def formation_offsets(spec: FormationSpec, n: int) -> NDArray[np.float64]:
    """The ``(n, 2)`` slot offsets (m) described by a formation section."""
    if spec.shape == "rectangle":
        return rectangle_offsets(spec.width, spec.length)
    if spec.shape == "offsets":
        return np.asarray(spec.offsets, dtype=float).reshape(n, 2)
    if spec.shape == "polar":
        dp = np.asarray(spec.offsets, dtype=float).reshape(n, 2)
        return polar_offsets(dp[:, 0], dp[:, 1])
    if spec.shape == "v":
        return v_offsets(n, spec.spacing, spec.angle)
    if spec.shape == "line":
        return line_offsets(n, spec.spacing)
    return grid_offsets(n, spec.spacing, spec.columns)


def slot_positions(leader_pose: NDArray[np.float64],
                   offsets: NDArray[np.float64]) -> NDArray[np.float64]:
    """World positions of the slots, paper 000 eq 30.

    Args:
        leader_pose: ``(3,)`` or ``(T, 3)`` leader pose(s) (m, m, rad).
        offsets: ``(N, 2)`` slot offsets in m.

    Returns:
        ``(N, 2)`` or ``(T, N, 2)`` positions in m.
    """
    lp = np.asarray(leader_pose, dtype=float)
    if lp.shape == (3,):  # one pose (every simulation step): scalar trig, same numbers
        off = np.asarray(offsets, dtype=float)
        c, s = math.cos(lp[2]), math.sin(lp[2])
        out = np.empty(off.shape)
        out[..., 0] = lp[0] + (c * off[..., 0] - s * off[..., 1])
        out[..., 1] = lp[1] + (s * off[..., 0] + c * off[..., 1])
        return out
    return body_to_world(lp[..., None, :], offsets)


def team_width(offsets: NDArray[np.float64], radius: float) -> float:
    """The formation's width across the leader's heading, bodies included, m.

    The spread of the slots' lateral offsets (the leader frame's y) plus one
    body diameter: the narrowest gap the rigid formation passes head-on.

    Args:
        offsets: ``(N, 2)`` slot offsets in the leader frame, m.
        radius: Robot body radius, m.
    """
    y = np.asarray(offsets, dtype=float).reshape(-1, 2)[:, 1]
    return float(y.max() - y.min() + 2.0 * radius) if len(y) else 2.0 * radius
