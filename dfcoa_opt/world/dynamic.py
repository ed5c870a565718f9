"""Dynamic obstacles: discs moving along waypoint polylines at constant speed.

These are the walking humans of paper 002 and the obstacle robots of paper 004.
Motion is a pure function of time, so every robot senses the same obstacle
state and runs are reproducible.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

EndMode = Literal["stop", "loop", "bounce"]


@dataclass(frozen=True)
class MovingDisc:
    """One moving disc.

    Attributes:
        radius: Disc radius in m, > 0.
        speed: Speed along the polyline in m/s, >= 0.
        waypoints: ``((x, y), ...)`` in m, at least one.
        start_time: Time in s before which the disc waits at the first waypoint.
        end: What happens at the last waypoint: ``stop``, ``loop`` (back to the
            first waypoint and around again) or ``bounce`` (reverse).
    """

    radius: float
    speed: float
    waypoints: tuple[tuple[float, float], ...]
    start_time: float = 0.0
    end: EndMode = "stop"


class DynamicObstacles:
    """A batch of :class:`MovingDisc` evaluated together (vectorised over discs).

    Args:
        discs: The discs; may be empty.
    """

    def __init__(self, discs: tuple[MovingDisc, ...] = ()) -> None:
        self.discs = tuple(discs)
        m = len(self.discs)
        self.radii = np.array([d.radius for d in self.discs], dtype=float)
        kmax = max((len(d.waypoints) + (d.end == "loop") for d in self.discs), default=1)
        self._pts = np.zeros((m, kmax, 2))
        self._cum = np.full((m, kmax), np.inf)
        self._total = np.zeros(m)
        for i, d in enumerate(self.discs):
            pts = np.asarray(d.waypoints, dtype=float).reshape(-1, 2)
            if d.end == "loop" and len(pts) > 1:
                pts = np.vstack((pts, pts[:1]))
            seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
            cum = np.concatenate(([0.0], np.cumsum(seg)))
            self._pts[i, : len(pts)] = pts
            self._pts[i, len(pts):] = pts[-1]
            self._cum[i, : len(pts)] = cum
            self._total[i] = cum[-1]
        self._speed = np.array([d.speed for d in self.discs], dtype=float)
        self._t0 = np.array([d.start_time for d in self.discs], dtype=float)
        self._mode = np.array([{"stop": 0, "loop": 1, "bounce": 2}[d.end] for d in self.discs],
                              dtype=int)

    def __len__(self) -> int:
        return len(self.discs)

    def _arc(self, t: float | NDArray[np.float64]
             ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Arc length along each polyline at time ``t`` and the direction sign.

        ``t`` a float gives ``(M,)`` arrays; ``(K, 1)`` gives ``(K, M)``.
        """
        s = self._speed * np.maximum(t - self._t0, 0.0)
        total = np.where(self._total > 0, self._total, 1.0)
        sign = np.ones_like(s)
        moving = s < self._total
        loop = self._mode == 1
        bounce = self._mode == 2
        s_loop = np.mod(s, total)
        phase = np.mod(s, 2 * total)
        s_bounce = np.where(phase <= total, phase, 2 * total - phase)
        sign = np.where(bounce & (phase > total), -1.0, sign)
        out = np.where(loop, s_loop, np.where(bounce, s_bounce, np.minimum(s, self._total)))
        still = (self._total == 0) | (~loop & ~bounce & ~moving) | (self._speed == 0)
        sign = np.where(still, 0.0, sign)
        return out, sign

    def state(self, t: float | NDArray[np.float64]
              ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Positions and velocities of all discs at time ``t``, or at each of several times.

        The formulas are elementwise, so the state at one entry of an array of
        times is bit for bit the state at that time alone.

        Args:
            t: Time in s, a float or a ``(K,)`` array.

        Returns:
            ``(positions (M, 2) m, velocities (M, 2) m/s)``, or ``(K, M, 2)`` each.
        """
        m = len(self.discs)
        lead = np.shape(t)
        if m == 0:
            return np.zeros((*lead, 0, 2)), np.zeros((*lead, 0, 2))
        s, sign = self._arc(np.asarray(t, dtype=float)[..., None])
        kmax = self._pts.shape[1]
        if kmax == 1:
            return np.broadcast_to(self._pts[:, 0], (*lead, m, 2)).copy(), np.zeros((*lead, m, 2))
        seg = np.clip((self._cum <= s[..., None]).sum(axis=-1) - 1, 0, kmax - 2)
        idx = np.arange(m)
        a, b = self._pts[idx, seg], self._pts[idx, seg + 1]
        length = self._cum[idx, seg + 1] - self._cum[idx, seg]
        length = np.where(np.isfinite(length) & (length > 0), length, 1.0)
        frac = np.clip((s - self._cum[idx, seg]) / length, 0.0, 1.0)
        pos = a + frac[..., None] * (b - a)
        direction = (b - a) / length[..., None]
        vel = direction * (self._speed * sign)[..., None]
        return pos, vel
