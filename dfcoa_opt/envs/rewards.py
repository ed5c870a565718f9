"""The environments' reward and episode ends, from the toolkit's own metrics and outcomes.

Every weight and unit is one field of :class:`RewardSpec`. The reward of a step
scores the *instant* at which the action is taken, the instant ``t_k`` that the
run logs (``dfcoa_opt.sim.log``: index ``k`` is the state the robots sensed and
the command they then applied), so its terms are the run log's own numbers::

    r_k = - (formation * E_c(t_k) + shape * E_s(t_k)) * dt
          + progress * (s(t_k) - s(t_{k-1}))
          - contact  * [a contact at t_k]
          + success  * [the goal reached with the formation settled at t_k]
          - deadlock * [the run stalled at t_k]

- ``E_c``: the formation centroid error, paper 000 eq 6
  (:func:`dfcoa_opt.metrics.formation_centroid_error`), m;
- ``E_s``: the formation shape error, paper 000 eq 7
  (:func:`dfcoa_opt.metrics.formation_shape_error`), m;
- ``s``: the arc length along the leader's planned path of the point nearest
  the robots' centroid (:func:`dfcoa_opt.sim.stall.formation_progress`), m, with
  ``s(t_{-1}) = s(t_0)``;
- a contact is any of :func:`dfcoa_opt.metrics.outcome.contact_steps` (robot-robot,
  robot-static, robot-moving), the outcome ``collision``.

Summed over an episode, the first term is ``-formation * dt * sum_k E_c(t_k)``:
the run's ``fce_mean`` times its duration. The action of step ``k`` acts on the
instants after ``t_k``, so it is scored from step ``k + 1`` on; with a discount
``gamma`` that is the same objective as scoring ``t_{k+1}`` at step ``k``, up
to the factor ``gamma`` and the constant first term.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, cast

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.core.params import param
from dfcoa_opt.metrics import formation_centroid_error, formation_shape_error

if TYPE_CHECKING:
    from dfcoa_opt.sim.log import RunLog

FloatArray = NDArray[np.float64]

#: How an episode ended: the outcome classes of :mod:`dfcoa_opt.metrics.outcome`.
TERMINAL_OUTCOMES = ("success", "collision", "deadlock")


@dataclass(frozen=True)
class RewardSpec:
    """Weights of the reward (module docstring); every weight is >= 0, its sign fixed there."""

    formation: float = param(1.0, doc="Weight of the formation centroid error E_c (paper 000 "
                                      "eq 6), per metre of error and second.",
                             unit="1/(m s)", ge=0.0)
    shape: float = param(1.0, doc="Weight of the formation shape error E_s (paper 000 eq 7), "
                                  "per metre of error and second.", unit="1/(m s)", ge=0.0)
    progress: float = param(1.0, doc="Reward per metre the robots' centroid advances along the "
                                     "leader's path.", unit="1/m", ge=0.0)
    contact: float = param(10.0, doc="Penalty at a contact (a collision, which ends the "
                                     "episode).", ge=0.0)
    success: float = param(10.0, doc="Bonus when the leader is at its goal with the formation "
                                     "settled (which ends the episode).", ge=0.0)
    deadlock: float = param(0.0, doc="Penalty when the run stalls (deadlock, which ends the "
                                     "episode with stop_on_deadlock).", ge=0.0)

    def __post_init__(self) -> None:
        """Every weight a finite number >= 0.

        Raises:
            ValueError: A weight is negative, NaN or infinite.
        """
        for f in fields(self):
            value = getattr(self, f.name)
            if not isinstance(value, int | float) or not math.isfinite(value) or value < 0:
                raise ValueError(f"RewardSpec.{f.name} must be a finite number >= 0, got "
                                 f"{value!r}")


@dataclass(frozen=True)
class _Instants:
    """Poses and slots of A instants, shaped as a log's, for the metric functions."""

    pose: FloatArray
    slots: FloatArray


def formation_errors(pose: FloatArray, slots: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Paper 000 eq 6 and eq 7 at A instants (of A runs), with the metrics' own functions.

    Args:
        pose: ``(A, N, 3)`` true poses (m, m, rad).
        slots: ``(A, N, 2)`` the formation slots, m.

    Returns:
        ``E_c`` and ``E_s``, each ``(A,)`` in m.
    """
    snap = cast("RunLog", _Instants(pose, slots))
    return formation_centroid_error(snap), formation_shape_error(snap)


def path_segments(path: FloatArray) -> tuple[FloatArray, ...]:
    """The segments of a path as :func:`path_arc_length` measures along them.

    Args:
        path: ``(P, 2)`` the leader's path, m (repeated points are dropped).

    Returns:
        ``(ax, ay, abx, aby, seg_len, cum)``, each ``(P' - 1,)`` but ``cum``
        ``(P',)``: each segment's start, direction (end minus start) and length,
        and the arc length at each kept point, m.
    """
    path = np.asarray(path, dtype=float).reshape(-1, 2)
    keep = np.concatenate(([True], np.linalg.norm(np.diff(path, axis=0), axis=1) > 1e-12))
    path = path[keep]
    seg_len = np.linalg.norm(np.diff(path, axis=0), axis=1)
    cum = np.concatenate(([0.0], np.cumsum(seg_len)))
    ax, ay = path[:-1, 0], path[:-1, 1]
    return ax, ay, path[1:, 0] - ax, path[1:, 1] - ay, seg_len, cum


def path_arc_length(path: FloatArray, points: FloatArray) -> FloatArray:
    """Arc length of the nearest point of ``path`` to each point, vectorised over the points.

    The arithmetic of ``PurePursuit.arc_length`` (the measure of
    :func:`dfcoa_opt.sim.stall.formation_progress`) in numpy, for every point in
    one call: for each segment the clipped projection ``t``, its distance, and
    the first nearest segment wins. (The environments' step computes it in
    :func:`~dfcoa_opt.envs.kernels.score_runs`, with these bits.)

    Args:
        path: ``(P, 2)`` the leader's path, m (repeated points are dropped).
        points: ``(A, 2)`` points, m.

    Returns:
        ``(A,)`` arc lengths from the path's start, m (0 for a one-point path).
    """
    ax, ay, abx, aby, seg_len, cum = path_segments(path)
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    if len(cum) == 1:
        return np.zeros(len(pts))
    px, py = pts[:, 0:1], pts[:, 1:2]
    t = ((px - ax) * abx + (py - ay) * aby) / (seg_len * seg_len)
    t = np.minimum(np.maximum(t, 0.0), 1.0)
    dx, dy = ax + t * abx - px, ay + t * aby - py
    best = np.argmin(np.sqrt(dx * dx + dy * dy), axis=1)
    return cum[best] + t[np.arange(len(pts)), best] * seg_len[best]


def dense_reward(spec: RewardSpec, dt: float, e_c: FloatArray, e_s: FloatArray,
                 advance: FloatArray, contact: NDArray[np.bool_]) -> FloatArray:
    """The terms of every step: formation, shape, progress and contact (module docstring).

    Args:
        spec: The weights.
        dt: Step, s.
        e_c: ``(A,)`` centroid errors, m.
        e_s: ``(A,)`` shape errors, m.
        advance: ``(A,)`` the centroid's advance along the path since the last instant, m.
        contact: ``(A,)`` whether a contact exists at the instant.

    Returns:
        ``(A,)`` rewards.
    """
    return (-(spec.formation * e_c + spec.shape * e_s) * dt + spec.progress * advance
            - spec.contact * contact)


def end_of_episode(contact: bool, reached: bool, last_instant: bool) -> tuple[str, bool]:
    """The outcome of a run that ended at this instant, and whether that is a termination.

    The order of :func:`dfcoa_opt.metrics.outcome.classify`: a contact is a ``collision``
    (the run stops at its first contact), else reaching the goal with the
    formation settled a ``success``; a run that stopped for neither before its
    last instant was stopped by the stall monitor (``stop_on_deadlock``), a
    ``deadlock``. Running out of time (``t_max``) is a ``timeout``: a
    truncation, not a termination.

    Args:
        contact: A contact at the run's last instant.
        reached: The goal condition held at it.
        last_instant: It was the last instant ``t_max`` allows.

    Returns:
        The outcome (one of :data:`dfcoa_opt.metrics.outcome.OUTCOMES`) and True when
        the episode terminated (False: truncated).
    """
    if contact:
        return "collision", True
    if reached:
        return "success", True
    if not last_instant:
        return "deadlock", True
    return "timeout", False


def end_bonus(spec: RewardSpec, outcome: str) -> float:
    """The reward an episode's outcome adds at its last step (contacts are in :func:`dense_reward`).

    Args:
        spec: The weights.
        outcome: One of :data:`dfcoa_opt.metrics.outcome.OUTCOMES`.
    """
    if outcome == "success":
        return spec.success
    if outcome == "deadlock":
        return -spec.deadlock
    return 0.0


class PathTable:
    """Every world's leader path as segments (:func:`path_segments`), for the compiled arc length.

    Group ``g`` (a world of the batch, ``BatchSimulator.group``) has its
    segments in columns ``start[g]:start[g] + count[g]`` of :attr:`data`, whose
    rows are ``ax, ay, abx, aby, seg_len`` and the arc length at each
    segment's start. A group given a new world gets its path appended; the
    table is compacted when it fills.
    """

    def __init__(self) -> None:
        self.data = np.zeros((6, 64))
        self.start = np.zeros(0, dtype=np.int64)
        self.count = np.zeros(0, dtype=np.int64)
        self.paths: list[FloatArray | None] = []
        self.used = 0

    def set(self, g: int, path: FloatArray) -> None:
        """Make ``path`` group ``g``'s (nothing to do when it already is)."""
        if g < len(self.paths) and self.paths[g] is path:
            return
        ax, ay, abx, aby, seg_len, cum = path_segments(path)
        segs = np.stack((ax, ay, abx, aby, seg_len, cum[:-1]))
        while g >= len(self.paths):
            self.paths.append(None)
            self.start, self.count = np.append(self.start, 0), np.append(self.count, 0)
        self.paths[g], self.count[g] = path, 0
        n = segs.shape[1]
        if self.used + n > self.data.shape[1]:  # compact, with room to grow
            live = int(self.count.sum())
            data = np.zeros((6, max(64, 2 * (live + n))))
            at = 0
            for h in np.flatnonzero(self.count):
                c, s0 = int(self.count[h]), int(self.start[h])
                data[:, at:at + c] = self.data[:, s0:s0 + c]
                self.start[h], at = at, at + c
            self.data, self.used = data, at
        self.data[:, self.used:self.used + n] = segs
        self.start[g], self.count[g] = self.used, n
        self.used += n
