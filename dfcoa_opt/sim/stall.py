"""The stall test: whether a run has stopped making progress (a deadlock).

One test, used wherever a run is judged stalled: instant ``k`` (``k >= lag``)
is stalled when, over ``[k - lag, k]``, the formation's centroid advanced less
than ``metrics.deadlock_advance`` along the leader's path and every robot
farther than the settle tolerance from its slot moved less than
``metrics.deadlock_displacement`` (:func:`stalled`). It is asked

- while a run is simulated, for ``stop_on_deadlock``: :class:`StallMonitor`, one per
  run (the stepper), or :class:`BatchStall`, every run of a batch at once (the
  learning environments, whose compiled pass calls :func:`stalled_at`, the same
  test in numba, bit for bit);
- after a run, for its outcome: :func:`dfcoa_opt.metrics.outcome.deadlock_onset`.

So a run stopped by ``stop_on_deadlock`` is classified ``deadlock`` by
construction. Definitions and defaults: ``docs/metrics.md`` (outcomes).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.planning.pure_pursuit import PurePursuit
from dfcoa_opt.scenario.schema import MetricSpec

FloatArray = NDArray[np.float64]


def formation_progress(positions: FloatArray, path: FloatArray) -> FloatArray:
    """Arc length along ``path`` of the point nearest the formation's centroid, per instant.

    Args:
        positions: ``(T, N, 2)`` robot positions, m.
        path: ``(P, 2)`` the leader's path, m.

    Returns:
        ``(T,)`` arc lengths from the path's start, m.
    """
    centroid = np.asarray(positions, dtype=float).mean(axis=1)
    return PurePursuit(path, 0.0, 0.0, 0.0).arc_length(centroid)


def stalled(positions: FloatArray, slots: FloatArray, progress: FloatArray, lag: int,
            settle_tolerance: float, advance: float, displacement: float) -> NDArray[np.bool_]:
    """Whether the run had made no progress over the ``lag`` steps before each instant.

    Instant ``k`` (``k >= lag``) is stalled when both hold over ``[k - lag, k]``:
    the formation's centroid advanced less than ``advance`` along the leader's
    path (``progress[k] - progress[k - lag] < advance``), and every robot farther
    than ``settle_tolerance`` from its slot at ``k`` moved less than
    ``displacement`` (net, ``|p_i(k) - p_i(k - lag)|``). Robots at their slots
    are left out, so a robot that chatters around its settled slot does not hide
    a stuck one. Instants before ``lag`` are never stalled.

    Args:
        positions: ``(T, N, 2)`` robot positions, m.
        slots: ``(T, N, 2)`` their formation slots, m.
        progress: ``(T,)`` :func:`formation_progress`, m.
        lag: Window in steps (>= 1).
        settle_tolerance: A robot this close to its slot is at its slot, m.
        advance: Least advance of the centroid that counts as progress, m.
        displacement: Least net displacement of a robot that counts as progress, m.

    Returns:
        ``(T,)`` booleans.
    """
    pos = np.asarray(positions, dtype=float)
    out = np.zeros(len(pos), dtype=bool)
    if lag < 1 or len(pos) <= lag:
        return out
    now, before = pos[lag:], pos[:-lag]
    away = np.linalg.norm(now - np.asarray(slots, dtype=float)[lag:], axis=-1) > settle_tolerance
    moved = np.linalg.norm(now - before, axis=-1)
    still = np.all(~away | (moved < displacement), axis=1)
    prog = np.asarray(progress, dtype=float)
    out[lag:] = still & (prog[lag:] - prog[:-lag] < advance)
    return out


class StallMonitor:
    """:func:`stalled` while a run is simulated, for ``stop_on_deadlock``.

    Args:
        path: ``(P, 2)`` the leader's path, m.
        steps: Instants the run can have.
        dt: Step, s.
        settle_tolerance: The leader's ``settle_tolerance``, m.
        cfg: Metric settings (window and thresholds).
    """

    def __init__(self, path: FloatArray, steps: int, dt: float, settle_tolerance: float,
                 cfg: MetricSpec) -> None:
        self._tracker = PurePursuit(path, 0.0, 0.0, 0.0)
        self._progress = np.zeros(steps)
        self._lag = max(1, int(round(cfg.deadlock_window / dt)))
        self._args = (settle_tolerance, cfg.deadlock_advance, cfg.deadlock_displacement)

    def update(self, k: int, positions: FloatArray, slots: FloatArray) -> bool:
        """Record instant ``k`` and say whether it is stalled.

        Args:
            k: The instant just logged.
            positions: ``(>k, N, 2)`` the logged positions so far (at least up to ``k``), m.
            slots: ``(>k, N, 2)`` the logged slots so far, m.
        """
        self._progress[k] = self._tracker.arc_length(positions[k].mean(axis=0)[None])[0]
        if k < self._lag:
            return False
        lo = k - self._lag
        if not self._progress[k] - self._progress[lo] < self._args[1]:
            return False  # the centroid advanced: not stalled, whatever the robots did
        return bool(stalled(positions[lo:k + 1], slots[lo:k + 1], self._progress[lo:k + 1],
                            self._lag, *self._args)[-1])


class BatchStall:
    """:class:`StallMonitor`'s test for every run of a batch at once.

    The Stepper asks each run's monitor ``update(k, positions, slots)`` in a
    Python loop; this object holds the answer of every run (:attr:`flags`,
    the Stepper's ``stall_flags``), set in the compiled pass that scores the
    step (:func:`~dfcoa_opt.envs.kernels.score_runs`, from the arc lengths the
    reward already needs, with :func:`stalled_at`; :meth:`update_reference` is the same
    with :func:`stalled`).
    The rule and its arithmetic are the monitor's, so a run stops at the same
    instant, bit for bit: instant ``k >= lag`` is stalled when the centroid advanced less
    than ``metrics.deadlock_advance`` along the path since ``k - lag`` and every
    robot farther than ``settle_tolerance`` from its slot moved less than
    ``metrics.deadlock_displacement`` (:func:`stalled`).

    Args:
        slots: E, the batch's slots.
        steps: Instants a run can have.
        dt: Step, s.
        settle_tolerance: The leader's ``settle_tolerance``, m.
        cfg: The scenario's ``[metrics]`` (window and thresholds).
    """

    def __init__(self, slots: int, steps: int, dt: float, settle_tolerance: float,
                 cfg: MetricSpec) -> None:
        self.progress = np.zeros((slots, steps))
        self.flags = np.zeros(slots, dtype=bool)
        self.lag = max(1, int(round(cfg.deadlock_window / dt)))
        self.settle = settle_tolerance
        self.advance, self.displacement = cfg.deadlock_advance, cfg.deadlock_displacement

    def update_reference(self, arc: FloatArray, active: NDArray[np.intp], k: NDArray[np.int64],
                         pose: FloatArray, slots: FloatArray) -> None:
        """Record instant ``k`` of the active runs and decide which are stalled, in numpy.

        The reference of the environments' compiled pass
        (:func:`~dfcoa_opt.envs.kernels.score_runs`, which sets :attr:`progress`
        and :attr:`flags` with these bits).

        Args:
            arc: ``(A,)`` each run's centroid arc length at its instant, m.
            active: ``(A,)`` their slots.
            k: ``(A,)`` their instants.
            pose: The log's ``(E, T, N, 3)`` poses (rows up to ``k`` written), m.
            slots: The log's ``(E, T, N, 2)`` slots, m.
        """
        self.progress[active, k] = arc
        for e, kk in zip(active, k, strict=True):
            lo = kk - self.lag
            self.flags[e] = lo >= 0 and bool(stalled(
                pose[e, lo:kk + 1, :, :2], slots[e, lo:kk + 1], self.progress[e, lo:kk + 1],
                self.lag, self.settle, self.advance, self.displacement)[-1])


@numba.njit(cache=True)
def stalled_at(pose: FloatArray, slots: FloatArray, progress: FloatArray, e: int, k: int,
               lag: int, advance: float, settle: float,
               displacement: float) -> bool:  # pragma: no cover - numba
    """:func:`stalled` of run ``e`` at instant ``k``, compiled (the environments' pass).

    Args:
        pose: ``(E, T, N, 3)`` logged poses, m.
        slots: ``(E, T, N, 2)`` logged slots, m.
        progress: ``(E, T)`` :func:`formation_progress` so far, m.
        e: The run.
        k: The instant.
        lag: Window in steps (>= 1).
        advance: Least advance of the centroid that counts as progress, m.
        settle: A robot this close to its slot is at its slot, m.
        displacement: Least net displacement of a robot that counts as progress, m.

    Returns:
        The flag, with the bits of :func:`stalled` (the same sums, in the same order).
    """
    lo = k - lag
    if lo < 0 or not progress[e, k] - progress[e, lo] < advance:
        return False
    for i in range(pose.shape[2]):
        x, y = pose[e, k, i, 0], pose[e, k, i, 1]
        dx, dy = x - slots[e, k, i, 0], y - slots[e, k, i, 1]
        away = math.sqrt(dx * dx + dy * dy) > settle
        dx, dy = x - pose[e, lo, i, 0], y - pose[e, lo, i, 1]
        if away and not math.sqrt(dx * dx + dy * dy) < displacement:
            return False
    return True
