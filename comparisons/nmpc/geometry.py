"""Slot references, neighbour predictions and distance half-planes of the ``nmpc`` controller.

Everything here is batched over robots and row-wise: row ``i`` of every output
depends on row ``i`` of its inputs only (plus the neighbours' broadcast plans
passed in explicitly), so the controller stays distributed.

The half-planes come from the shared builders of
:mod:`comparisons.constraints.distance`: for a linearisation point ``xbar`` and a
thing to keep away from, the builder gives the nearest point ``q`` and the unit
normal ``n`` from ``q`` towards ``xbar``; the constraint on the predicted position
``p`` is ``n . (p - q) >= D``, i.e. ``n . p >= c`` with ``c = n . q + D``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from comparisons.constraints.distance import StaticObstacles, disc_nearest, pair_geometry
from comparisons.constraints.world_shapes import WorldShapes
from dfcoa_opt.control.base import MovingObstacles, Neighbours
from dfcoa_opt.core.geometry import take_rows

FloatArray = NDArray[np.float64]
#: Below this slot speed (m/s) the heading reference is the leader's heading.
_STILL = 1e-6


def slot_reference(leader: FloatArray, offsets: FloatArray, times: FloatArray
                   ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Slots over the horizon, with the leader at constant (v, omega) (exact arc).

    Elementwise over the rows: row ``i`` of a batch gives the numbers of its
    leader state alone, bit for bit (the same IEEE operations in the same order).

    Args:
        leader: ``(5,)`` broadcast leader state (x m, y m, theta rad, v m/s, omega rad/s),
            or ``(N, 5)`` one per row (:meth:`~dfcoa_opt.control.base.Observation.row_leader`).
        offsets: ``(N, 2)`` slot offsets in the leader frame, m.
        times: ``(H,)`` prediction times from now, s.

    Returns:
        ``(ref (N, H, 2) m, heading (N, H) rad, twist (N, H, 2))``: the slot
        positions, the direction of the slot's velocity (the leader's heading when
        the slot is still) and the slot's feed-forward twist ``(|d/dt slot| m/s,
        omega rad/s)``, which a unicycle on the slot's path would apply.
    """
    lead = np.asarray(leader, dtype=float)
    if lead.ndim == 1:
        x, y, th, v, w = (float(c) for c in lead)
    else:  # (N, 1) columns: broadcast against times (H,) like the scalars above
        x, y, th, v, w = (lead[:, j:j + 1] for j in range(5))
    half = 0.5 * w * times
    small = np.abs(half) < 1e-9
    sinc = np.where(small, 1.0, np.sin(half) / np.where(small, 1.0, half))
    chord = v * times * sinc
    lx, ly = x + chord * np.cos(th + half), y + chord * np.sin(th + half)
    lth = th + w * times
    c, s = np.cos(lth), np.sin(lth)
    ox, oy = offsets[:, 0:1], offsets[:, 1:2]
    rx, ry = c * ox - s * oy, s * ox + c * oy  # slot minus leader, world frame
    ref = np.stack((lx + rx, ly + ry), axis=-1)
    vx, vy = v * c - w * ry, v * s + w * rx
    speed = np.hypot(vx, vy)
    heading = np.where(speed > _STILL, np.arctan2(vy, vx), np.broadcast_to(lth, speed.shape))
    twist = np.stack((speed, np.broadcast_to(w, speed.shape)), axis=-1)
    return ref, heading, twist


def plan_positions(plans: FloatArray, age: FloatArray, horizon: int) -> FloatArray:
    """Positions of stored plans at ``age + k`` stages, ``k = 0 .. horizon``.

    Linear interpolation between the plan's stages; past its end, linear
    extrapolation along its last segment.

    Args:
        plans: ``(..., H + 1, 2)`` planned positions at the plan's stages, m.
        age: ``(...)`` time since the plan was made, in stages (>= 0).
        horizon: Stages ``H`` wanted.

    Returns:
        ``(..., horizon + 1, 2)`` positions, m.
    """
    last = plans.shape[-2] - 2
    f = age[..., None] + np.arange(horizon + 1)
    i0 = np.clip(np.floor(f + 1e-9).astype(np.intp), 0, last)
    frac = (f - i0)[..., None]
    lead = plans.shape[:-2]
    flat = plans.reshape(-1, *plans.shape[-2:])
    i0 = i0.reshape(len(flat), -1)
    a = take_rows(flat, i0).reshape(*lead, -1, 2)
    b = take_rows(flat, i0 + 1).reshape(*lead, -1, 2)
    return a + frac * (b - a)


def _entries(nb: Neighbours, count: int, index: NDArray[np.intp]
             ) -> tuple[NDArray[np.intp], FloatArray, FloatArray, int]:
    """The first ``count`` entries of each row, padded: ids, positions (m), velocities (m/s).

    Returns ``(idx (N, K), pos (N, K, 2), vel (N, K, 2), take)`` with ``take`` the
    entries taken from the table (the others are padding, ``idx = -1``).
    """
    n = len(index)
    idx = np.full((n, count), -1, dtype=np.intp)
    take = min(count, index.shape[1])
    idx[:, :take] = index[:, :take]
    pos = np.zeros((n, count, 2))
    vel = np.zeros((n, count, 2))
    pos[:, :take], vel[:, :take] = nb.position[:, :take], nb.velocity[:, :take]
    return idx, pos, vel, take


def neighbour_predictions(nb: Neighbours, count: int, plans: FloatArray, plan_age: FloatArray,
                          tau: float, horizon: int, index: NDArray[np.intp] | None = None
                          ) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Predicted centres of each robot's ``count`` nearest neighbours at stages 1 .. H.

    A neighbour with a plan of the previous steps (``plan_age`` finite, in
    stages, less than ``horizon``) follows that plan, translated so that it starts
    at the neighbour's broadcast position; one without moves at its broadcast
    velocity. Every message is fresh here (``nb.age`` None): with late or lost
    messages each entry carries its own plan, :func:`entry_predictions`.

    Args:
        nb: The observation's neighbour table.
        count: Neighbour slots ``K`` (extra ones are dropped, missing ones padded).
        plans: ``(R, H + 1, 2)`` every robot's last plan, by global id, m.
        plan_age: ``(R,)`` age of each plan in stages (``inf`` = none).
        tau: Stage length, s.
        horizon: Stages ``H``.
        index: ``(N, K')`` the neighbours' global ids (rows of ``plans``, -1 padded);
            default ``nb.index`` (a table whose indices are global ids).

    Returns:
        ``(pred (N, K, H, 2) m, mask (N, K))``.
    """
    idx, pos, vel, _ = _entries(nb, count, nb.index if index is None else index)
    mask = idx >= 0
    safe = np.where(mask, idx, 0)
    steps = tau * np.arange(1, horizon + 1)
    pred = pos[:, :, None, :] + vel[:, :, None, :] * steps[:, None]
    age = plan_age[safe]
    planned = mask & (age < horizon)
    if planned.any():
        # each plan is sampled once (a robot is the neighbour of several), then gathered
        used, slot = np.unique(safe[planned], return_inverse=True)
        traj = plan_positions(plans[used], plan_age[used], horizon)[slot]
        pred[planned] = traj[:, 1:] + (pos[planned] - traj[:, 0])[:, None, :]
    return pred, mask


def entry_predictions(nb: Neighbours, count: int, plans: FloatArray, plan_age: FloatArray,
                      tau: float, horizon: int, index: NDArray[np.intp] | None = None
                      ) -> tuple[FloatArray, NDArray[np.bool_]]:
    """:func:`neighbour_predictions` when each entry carries its own plan.

    With late or lost messages (``nb.age``) entry ``(i, k)`` carries the plan its
    sender had when it sent the message, so two receivers of one sender may
    hold different plans. Each is used as :func:`neighbour_predictions` uses a
    plan: less than ``horizon`` stages old (its age counted from now), it is
    sampled at ``t + k tau`` and translated so that it starts at the entry's
    position; without one the neighbour moves at the entry's velocity. Given
    each entry the plan of its id, the numbers are :func:`neighbour_predictions`',
    bit for bit.

    Args:
        nb: The observation's neighbour table.
        count: Neighbour slots ``K`` (extra ones are dropped, missing ones padded).
        plans: ``(N, K', H + 1, 2)`` each entry's plan, m (columns as ``nb``'s, or
            its first ``K'`` ones).
        plan_age: ``(N, K')`` their ages now, in stages (``inf`` = none).
        tau: Stage length, s.
        horizon: Stages ``H``.
        index: ``(N, K'')`` the neighbours' global ids (-1 padded); default ``nb.index``.

    Returns:
        ``(pred (N, K, H, 2) m, mask (N, K))``.
    """
    idx, pos, vel, take = _entries(nb, count, nb.index if index is None else index)
    n, take = len(idx), min(take, plans.shape[1])
    mask = idx >= 0
    age = np.full((n, count), np.inf)
    age[:, :take] = plan_age[:, :take]
    own = np.zeros((n, count, *plans.shape[2:]))
    own[:, :take] = plans[:, :take]
    steps = tau * np.arange(1, horizon + 1)
    pred = pos[:, :, None, :] + vel[:, :, None, :] * steps[:, None]
    planned = mask & (age < horizon)
    if planned.any():
        traj = plan_positions(own[planned], age[planned], horizon)
        pred[planned] = traj[:, 1:] + (pos[planned] - traj[:, 0])[:, None, :]
    return pred, mask


def robot_halfplanes(lin: FloatArray, pred: FloatArray, mask: NDArray[np.bool_],
                     distance: float, reach: float) -> tuple[FloatArray, FloatArray]:
    """Half-planes keeping each predicted position ``distance`` from the neighbours' centres.

    Args:
        lin: ``(N, H, 2)`` linearisation points (own predicted positions), m.
        pred: ``(N, K, H, 2)`` predicted neighbour centres, m.
        mask: ``(N, K)`` existing neighbours.
        distance: ``D`` = 2 radius + margin, m.
        reach: Neighbours farther than this from the linearisation point are left out, m.

    Returns:
        ``(normal (N, H, K, 2), offset (N, H, K) m)``; inactive rows have offset ``-inf``.
    """
    n, h = lin.shape[:2]
    k = pred.shape[1]
    other = pred.transpose(0, 2, 1, 3).reshape(n * h, k, 2)
    delta, normal = pair_geometry(lin.reshape(n * h, 2), other)
    delta, normal = delta.reshape(n, h, k), normal.reshape(n, h, k, 2)
    other = other.reshape(n, h, k, 2)
    active = mask[:, None, :] & (delta <= reach)
    offset = np.einsum("nhkd,nhkd->nhk", normal, other) + distance
    return normal, np.where(active, offset, -np.inf)


def moving_nearest(lin: FloatArray, moving: MovingObstacles, tau: float
                   ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Nearest points of the moving discs each row senses, predicted to each stage.

    The discs a row senses are packed first, in their order (padding after):
    ``q = 0``, ``delta = inf``, ``n = (1, 0)``. Each (stage, disc) pair is one
    :func:`~comparisons.constraints.distance.disc_nearest` evaluation of the disc
    centred at ``position + velocity (k + 1) tau``.

    Args:
        lin: ``(N, H, 2)`` linearisation points, m.
        moving: The observation's moving obstacles (``M`` slots).
        tau: Stage length, s.

    Returns:
        ``(q (N, H, M, 2) m, delta (N, H, M) m, normal (N, H, M, 2))``.
    """
    n, h = lin.shape[:2]
    m = moving.mask.shape[1]
    order = np.argsort(~moving.mask, axis=1, kind="stable")  # sensed discs first, in order
    sensed = np.take_along_axis(moving.mask, order, axis=1)
    pos = take_rows(moving.position, order)
    vel = take_rows(moving.velocity, order)
    rad = np.take_along_axis(moving.radius, order, axis=1)
    times = tau * np.arange(1, h + 1)
    centre = pos[:, None] + vel[:, None] * times[None, :, None, None]  # (N, H, M, 2)
    discs = np.concatenate((centre, np.broadcast_to(rad[:, None, :, None], (n, h, m, 1))),
                           axis=-1)
    q, delta, normal = disc_nearest(lin.reshape(n * h, 2), discs.reshape(n * h, m, 3))
    q, delta, normal = q.reshape(n, h, m, 2), delta.reshape(n, h, m), normal.reshape(n, h, m, 2)
    off = ~np.broadcast_to(sensed[:, None, :], (n, h, m))
    q[off], delta[off], normal[off] = 0.0, np.inf, (1.0, 0.0)
    return q, delta, normal


def obstacle_halfplanes(lin: FloatArray, static: StaticObstacles | WorldShapes,
                        moving: MovingObstacles, tau: float, count: int, distance: float,
                        reach: float, world: NDArray[np.intp] | None = None
                        ) -> tuple[FloatArray, FloatArray]:
    """Half-planes of the ``count`` nearest static and moving obstacles at each stage.

    Static shapes (discs and polygons) go through
    :meth:`~comparisons.constraints.distance.StaticObstacles.nearest` (or
    :meth:`~comparisons.constraints.world_shapes.WorldShapes.nearest`, the same numbers with
    each row in its own map); moving discs are predicted at constant
    velocity to each stage's time and go through
    :func:`~comparisons.constraints.distance.disc_nearest` (:func:`moving_nearest`).
    The ``count`` nearest of both (signed distance from the linearisation point)
    within ``reach`` are kept.

    Args:
        lin: ``(N, H, 2)`` linearisation points, m (stage k at ``(k + 1) tau`` s from now).
        static: The map's shapes, or the maps of a batch (with ``world``).
        moving: The observation's moving obstacles.
        tau: Stage length, s.
        count: Slots per stage ``M``.
        distance: ``D`` = robot radius + margin, m.
        reach: Obstacles farther than this (signed distance) are left out, m.
        world: ``(N,)`` each row's map in ``static`` (a :class:`WorldShapes`; None: map 0).

    Returns:
        ``(normal (N, H, M, 2), offset (N, H, M) m)``; inactive rows have offset ``-inf``.
    """
    n, h = lin.shape[:2]
    if isinstance(static, WorldShapes):
        near = static.nearest(lin, count, reach, world)
    else:
        near = static.nearest(lin.reshape(n * h, 2), count, reach)
    q = near.point.reshape(n, h, count, 2)
    delta = near.delta.reshape(n, h, count)
    normal = near.normal.reshape(n, h, count, 2)
    if moving.mask.shape[1] and moving.mask.any():
        # rows that sense nothing keep their static slots: those are sorted already,
        # the moving padding (delta = inf) goes after them
        mq, md, mn = moving_nearest(lin, moving, tau)
        q = np.concatenate((q, mq), axis=2)
        delta = np.concatenate((delta, md), axis=2)
        normal = np.concatenate((normal, mn), axis=2)
        order = np.argsort(delta, axis=2, kind="stable")[..., :count]
        delta = np.take_along_axis(delta, order, axis=2)
        q = np.take_along_axis(q, order[..., None], axis=2)
        normal = np.take_along_axis(normal, order[..., None], axis=2)
    offset = np.einsum("nhkd,nhkd->nhk", normal, q) + distance
    return normal, np.where(delta <= reach, offset, -np.inf)
