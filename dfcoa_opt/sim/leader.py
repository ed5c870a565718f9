"""The virtual leader: a unicycle that follows the planned path by pure pursuit.

Its state ``(x, y, theta, v, omega)`` is broadcast to every robot. ``v`` and
``omega`` are the commands it applies during the current step, so followers
know the reference motion of the step they are planning.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.planning.pure_pursuit import PurePursuit
from dfcoa_opt.scenario.formation import slot_positions
from dfcoa_opt.scenario.scenario import Scenario
from dfcoa_opt.world.robots.unicycle_kernel import unicycle_arc

FloatArray = NDArray[np.float64]
#: Bytes of leader tracks kept per process (:func:`leader_track`); the least recently
#: used go first (a 100-robot track of 800 steps takes 1.3 MB).
TRACKS_BYTES = 64 * 2**20


class VirtualLeader:
    """Tracks the path planned when the scenario was loaded.

    Args:
        scenario: The scenario (uses ``spec.leader`` and the grid).
    """

    def __init__(self, scenario: Scenario) -> None:
        spec = scenario.spec.leader
        self.spec = spec
        self.goal = np.asarray(spec.goal, dtype=float)
        start = np.asarray(spec.start, dtype=float)
        self.path = scenario.leader_path
        self.tracker = PurePursuit(self.path, spec.speed, spec.lookahead, spec.w_max)
        self.pose = np.array([start[0], start[1], scenario.leader_heading])
        self.v = 0.0
        self.w = 0.0
        #: Whether the leader is within ``goal_radius`` of the goal (updated as it moves).
        self.at_goal = self._within_goal()

    def _within_goal(self) -> bool:
        return bool(np.hypot(*(self.pose[:2] - self.goal)) <= self.spec.goal_radius)

    def state(self, dt: float) -> FloatArray:
        """Broadcast state ``(x, y, theta, v, omega)``; computes this step's command.

        A leader whose step of ``dt`` s at ``leader.speed`` would be longer than its
        distance to the goal slows for that step (``v`` and ``omega`` scaled alike:
        the same arc, shorter), so a fast leader or a long step lands on its goal
        instead of passing it and circling back. A leader that reaches its goal
        region at a step of at most ``goal_radius`` never slows.
        """
        if self.at_goal:
            self.v, self.w = 0.0, 0.0
        else:
            self.v, self.w, _ = self.tracker.command(self.pose)
            left = float(np.hypot(*(self.pose[:2] - self.goal)))
            if self.v * dt > left:
                scale = left / (self.v * dt)
                self.v, self.w = self.v * scale, self.w * scale
        return np.array([*self.pose, self.v, self.w])

    def advance(self, dt: float) -> None:
        """Move for ``dt`` seconds with the command of :meth:`state`."""
        self.pose = unicycle_arc(self.pose, float(self.v), float(self.w), float(dt))
        self.at_goal = self._within_goal()


@dataclass(frozen=True)
class LeaderTrack:
    """The leader's broadcast states and slots at every step ``t_k = k dt`` of a run.

    The leader follows its path whatever the robots do, so these are a function of
    the scenario's path, leader settings, slot offsets and ``dt`` alone. The arrays
    are read-only (every run of the scenario shares them).

    Attributes:
        state: ``(K, 5)`` :meth:`VirtualLeader.state` at each step.
        at_goal: ``(K,)`` :attr:`VirtualLeader.at_goal` at each step (before it moves).
        slots: ``(K, N, 2)`` the slots of that state (paper 000 eq 30), m.
    """

    state: FloatArray
    at_goal: NDArray[np.bool_]
    slots: FloatArray

    @property
    def nbytes(self) -> int:
        """Memory held by the arrays, bytes."""
        return self.state.nbytes + self.at_goal.nbytes + self.slots.nbytes


_TRACKS: OrderedDict[tuple, LeaderTrack] = OrderedDict()
_TRACKS_LOCK = threading.Lock()


def leader_track(scenario: Scenario, dt: float, steps: int) -> LeaderTrack:
    """The :class:`LeaderTrack` of ``steps`` steps of ``dt`` s.

    Computed by stepping a :class:`VirtualLeader` exactly as a run does (the
    same numbers, bit for bit) until it has stopped at its goal (a step that
    leaves its pose unchanged; the later steps repeat it), once per process for
    each distinct path, leader settings, offsets, ``dt`` and ``steps``: the runs
    of one scenario (every seed and controller) share it. Up to
    :data:`TRACKS_BYTES` of tracks are kept.
    """
    spec = scenario.spec.leader
    path, offsets = scenario.leader_path, scenario.offsets
    key = (path.tobytes(), path.shape, offsets.tobytes(), offsets.shape,
           float(scenario.leader_heading), tuple(spec.start), tuple(spec.goal), spec.speed,
           spec.w_max, spec.lookahead, spec.goal_radius, float(dt), int(steps))
    with _TRACKS_LOCK:
        track = _TRACKS.get(key)
        if track is not None:
            _TRACKS.move_to_end(key)
            return track
    leader = VirtualLeader(scenario)
    state = np.empty((steps, 5))
    at_goal = np.empty(steps, dtype=bool)
    slots = np.empty((steps, *offsets.shape))
    for k in range(steps):
        at_goal[k] = leader.at_goal
        state[k] = leader.state(dt)
        slots[k] = slot_positions(state[k, :3], offsets)
        before = leader.pose
        leader.advance(dt)
        if at_goal[k] and leader.pose.tobytes() == before.tobytes():
            # stopped for good: every later step is this one again, bit for bit
            at_goal[k + 1:], state[k + 1:], slots[k + 1:] = True, state[k], slots[k]
            break
    for a in (state, at_goal, slots):
        a.flags.writeable = False
    track = LeaderTrack(state, at_goal, slots)
    with _TRACKS_LOCK:
        _TRACKS[key] = track
        while sum(t.nbytes for t in _TRACKS.values()) > TRACKS_BYTES:
            _TRACKS.popitem(last=False)
    return track
