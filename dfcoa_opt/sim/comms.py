"""Imperfect communication and sensing: late and lost messages, pose and command noise.

What the keys do (docs/comms.md):

- ``comms.latency`` / ``comms.dropout``: every message a robot receives about
  another robot (its believed pose and its velocity: the neighbour table, and
  what a controller sends with it) is ``latency`` old; at each step each
  (receiver, sender) message is lost with probability ``dropout``, and the
  receiver keeps the last one it got, with its age. The team's planner at the
  virtual leader (a central planner such as ``reshape``'s) is one more
  receiver of every robot's message (``Observation.team``).
- Range is decided when a message is sent: a receiver's neighbour table holds
  the senders of the proximity table (``sensors.comm_radius``, the
  ``sensors.max_neighbors`` nearest, true positions) of the step whose
  messages arrive now, ``latency`` ago (a radio reaches whoever is in range
  when it transmits), nearest received position first. A lost message of such
  a sender leaves its entry with the last message received. With latency 0
  that step is the current one, the rule of a table gated at reception.
- ``comms.leader_latency`` / ``comms.leader_dropout``: the same for the virtual
  leader's broadcast (its state, hence every slot). A lost broadcast is lost
  for the whole team (``Observation.leader`` is one state per run).
- ``sensors.pose_noise_std`` / ``heading_noise_std``: with ``truth``
  localisation, fresh Gaussian noise on the pose each robot believes (and
  broadcasts) at every step.
- ``robots.command_noise_std``: Gaussian noise on every component of the
  applied command.

At t = 0 every robot knows every other's start (and the leader's): messages
are late and lost from then on (until ``latency`` has passed, the messages
that arrive are the starts, so the step-0 table gates them). Every draw comes
from the run's own generator, run by run in a fixed order each step (pose
noise, then the (N + 1, N) message draws, the planner's row last, then the
leader's, in ``sense``; command noise in ``apply``), so a batch gives its
runs' bits and a seed fixes them; the range gate draws nothing. State is kept
per slot and overwritten from a run's step 0 on, so a run restarted in a slot
holds nothing of the one before. With every key at its default the simulator
makes no :class:`Comms` and draws nothing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.core.geometry import wrap_angle_fast
from dfcoa_opt.scenario.schema import ScenarioSpec

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


def wanted(spec: ScenarioSpec) -> bool:
    """Whether any message is late or lost, or any pose or command is noisy."""
    return bool(spec.comms.on or spec.sensors.pose_noise_std or spec.sensors.heading_noise_std
                or spec.robots.command_noise_std)


@dataclass
class Received:
    """The neighbour table as the receivers have it (rows as the proximity table's).

    Attributes:
        index: ``(R, K)`` senders (robot indices within the run), -1 padded,
            nearest received position first.
        position: ``(R, K, 2)`` received positions, m.
        velocity: ``(R, K, 2)`` received velocities, m/s.
        heading: ``(R, K)`` received headings, rad.
        distance: ``(R, K)`` from the receiver's believed position to the
            received one, m (``inf`` padded).
        age: ``(R, K)`` age of each message, s (0 padded).
        team: ``(R, 5)`` each robot as the planner at the leader last received
            it: x, y (m), theta (rad), vx, vy (m/s).
        team_age: ``(R,)`` the age of that message, s.
    """

    index: NDArray[np.intp]
    position: FloatArray
    velocity: FloatArray
    heading: FloatArray
    distance: FloatArray
    age: FloatArray
    team: FloatArray
    team_age: FloatArray


class Comms:
    """The messages of a batch's runs: what each receiver last got, and when.

    Args:
        spec: The scenario (every run of the batch shares it).
        n: Robots per run.
        slots: Runs of the batch (state is kept per slot, so a restarted slot
            starts again at its step 0).
        rngs: Each slot's generator (the list object the stepper keeps, read
            at every step, so a restart's new generator is used).
    """

    def __init__(self, spec: ScenarioSpec, n: int, slots: int,
                 rngs: list[np.random.Generator]) -> None:
        c, dt = spec.comms, spec.dt
        self.n, self.dt, self.rngs = n, dt, rngs
        self.lag = int(round(c.latency / dt))
        self.drop = float(c.dropout)
        self.leader_lag = int(round(c.leader_latency / dt))
        self.leader_drop = float(c.leader_dropout)
        self.pose_sigma = np.array([spec.sensors.pose_noise_std] * 2
                                   + [spec.sensors.heading_noise_std])
        self.command_sigma = float(spec.robots.command_noise_std)
        self.messages = bool(c.latency or c.dropout)
        self.leader_on = bool(c.leader_latency or c.leader_dropout)
        if self.messages:
            self.history = np.zeros((slots, self.lag + 1, n, 5))  # sent: x, y, theta, vx, vy
            # [receiver, sender]: last message received; receiver N is the planner at the leader
            self.got = np.zeros((slots, n + 1, n, 5))
            self.stamp = np.zeros((slots, n + 1, n), dtype=np.int64)  # its content's step
            # [step % (lag + 1), receiver]: the senders in range when the messages were sent
            k = max(min(int(spec.sensors.max_neighbors), n - 1), 0)
            self.reach = np.full((slots, self.lag + 1, n, k), -1, dtype=np.intp)
        self.leader_stamp = np.zeros(slots, dtype=np.int64)

    def believed(self, pose: FloatArray, active: IntArray) -> FloatArray:
        """``(A*N, 3)`` poses with this step's noise (the true ones without any noise key)."""
        if not self.pose_sigma.any():
            return pose
        n = self.n
        noise = np.concatenate([self.rngs[e].normal(size=(n, 3)) for e in active])
        out = pose + noise * self.pose_sigma
        out[:, 2] = wrap_angle_fast(out[:, 2])
        return out

    def neighbours(self, kk: IntArray, active: IntArray, pose: FloatArray, velocity: FloatArray,
                   index: NDArray[np.intp]) -> Received:
        """Send this step's messages and give the neighbour table as received.

        Args:
            kk: ``(A,)`` each active run's step.
            active: ``(A,)`` their slots.
            pose: ``(A*N, 3)`` believed poses (what robots send, and where receivers are).
            velocity: ``(A*N, 2)`` velocities they send, m/s.
            index: ``(A*N, K)`` neighbours in radio range at this step (robot indices
                within the run, -1 padded), from the true positions. It gates the
                messages sent now; the table given is that of the step whose messages
                arrive now.
        """
        a, n, lag = len(active), self.n, self.lag
        sent = np.concatenate((pose, velocity), axis=1).reshape(a, n, 5)
        self.history[active, kk % (lag + 1)] = sent
        self.reach[active, kk % (lag + 1)] = index.reshape(a, n, -1)
        src = np.maximum(kk - lag, 0)
        content = self.history[active, src % (lag + 1)]  # (A, N, 5): what arrives now
        # the senders in range when that was sent (at lag 0: this step's table)
        index = self.reach[active, src % (lag + 1)].reshape(a * n, -1)
        if self.drop:
            lost = np.stack([self.rngs[e].random((n + 1, n)) < self.drop for e in active])
            lost[kk == 0] = False  # every start is known
        else:
            lost = np.zeros((a, n + 1, n), dtype=bool)
        got = np.where(lost[..., None], self.got[active], content[:, None, :, :])
        stamp = np.where(lost, self.stamp[active], src[:, None, None])
        self.got[active], self.stamp[active] = got, stamp
        rows = np.arange(a * n)
        run, me = rows // n, rows % n
        pad = index < 0
        j = np.where(pad, 0, index)
        msg = got[run[:, None], me[:, None], j]  # (A*N, K, 5)
        msg[pad] = 0.0
        age = (kk[run][:, None] - stamp[run[:, None], me[:, None], j]) * self.dt
        age[pad] = 0.0
        dist = np.hypot(msg[..., 0] - pose[:, None, 0], msg[..., 1] - pose[:, None, 1])
        dist[pad] = np.inf
        order = np.argsort(dist, axis=1, kind="stable")
        take = np.take_along_axis
        msg = take(msg, order[..., None], axis=1)
        team = got[:, n].reshape(a * n, 5)
        team_age = ((kk[:, None] - stamp[:, n]) * self.dt).reshape(a * n)
        return Received(take(index, order, axis=1), msg[..., :2], msg[..., 3:5], msg[..., 2],
                        take(dist, order, axis=1), take(age, order, axis=1), team, team_age)

    def leader(self, kk: IntArray, active: IntArray) -> tuple[IntArray, FloatArray]:
        """The step whose leader broadcast each active run holds, and its age (s)."""
        src = np.maximum(kk - self.leader_lag, 0)
        if self.leader_drop:
            lost = np.array([self.rngs[e].random() < self.leader_drop for e in active])
            lost[kk == 0] = False
            self.leader_stamp[active] = np.where(lost, self.leader_stamp[active], src)
        else:
            self.leader_stamp[active] = src
        stamp = self.leader_stamp[active].copy()
        return stamp, (kk - stamp) * self.dt

    def command(self, native: FloatArray, active: IntArray) -> FloatArray:
        """``(A*N, k)`` commands with this step's actuation noise (as they are without it)."""
        if not self.command_sigma:
            return native
        noise = np.concatenate([self.rngs[e].normal(size=(self.n, native.shape[1]))
                                for e in active])
        return native + noise * self.command_sigma
