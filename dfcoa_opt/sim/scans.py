"""The scans a batch's robots hold between LiDAR frames, and the ones a run records.

With ``sensors.lidar.rate`` a robot gets a new scan only when one is due and
keeps its last one in between (:meth:`ScanBook.held`); with ``record_scans``
every step's scans go to the run's log (:meth:`ScanBook.record`,
:attr:`RunLog.scan <dfcoa_opt.sim.log.RunLog>`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.world.lidar import LaserScan

FloatArray = NDArray[np.float64]


class ScanBook:
    """The held and recorded scans of a batch's ``slots`` slots of ``n`` robots.

    Args:
        slots: Slots of the batch.
        steps: Instants of a run.
        n: Robots per run.
        dt: Time step, s.
        rate: LiDAR frames per second (``inf``: a new scan every step).
    """

    def __init__(self, slots: int, steps: int, n: int, dt: float, rate: float) -> None:
        self.slots, self.steps, self.n, self.dt, self.rate = slots, steps, n, dt, rate
        self._last: FloatArray | None = None  # each slot's robots' last scans
        #: ``(S, K, N, B)`` the scans the robots had (None until :meth:`record`)
        self.log: FloatArray | None = None
        self._layout: dict[str, float] = {}

    def held(self, scan: LaserScan, active: NDArray[np.intp], kk: NDArray[np.int64]
             ) -> LaserScan:
        """The scans the robots have with ``sensors.lidar.rate``: new ones only when due.

        Run ``e`` takes a new scan at step ``k`` when ``floor(k dt rate)`` grew
        since step ``k - 1`` (and at ``k = 0``); otherwise each robot keeps its
        last scan. The LiDAR is cast every step (its noise drawn every step),
        so the runs' draws do not depend on the rate.
        """
        n, rate = self.n, self.rate
        ranges = scan.ranges.reshape(len(active), n, -1)
        if self._last is None:
            self._last = np.zeros((self.slots, n, ranges.shape[2]))
        ticks = np.floor(kk * self.dt * rate + 1e-9)
        due = (kk == 0) | (ticks > np.floor((kk - 1) * self.dt * rate + 1e-9))
        self._last[active[due]] = ranges[due]
        return LaserScan(scan.angle_min, scan.angle_increment, scan.range_min, scan.range_max,
                         self._last[active].reshape(len(active) * n, -1))

    def record(self, scan: LaserScan, active: NDArray[np.intp], kk: NDArray[np.int64]) -> None:
        """Keep the active runs' scans of this step (their instants ``kk``)."""
        ranges = scan.ranges.reshape(len(active), self.n, -1)
        if self.log is None:
            self.log = np.zeros((self.slots, self.steps, self.n, ranges.shape[2]))
            period = 1.0 / self.rate if np.isfinite(self.rate) else self.dt
            self._layout = {"angle_min": scan.angle_min, "angle_increment": scan.angle_increment,
                            "range_min": scan.range_min, "range_max": scan.range_max,
                            "scan_time": period}
        self.log[active, kk] = ranges

    def recorded(self, slot: int, steps: int) -> tuple[FloatArray, dict[str, float]] | None:
        """Slot ``slot``'s first ``steps`` recorded scans (a copy, m) and their beam layout.

        The layout gives ``angle_min`` and ``angle_increment`` in rad,
        ``range_min`` and ``range_max`` in m and ``scan_time`` (the time between
        two frames) in s; None when nothing was recorded.
        """
        if self.log is None:
            return None
        return self.log[slot, :steps].copy(), dict(self._layout)
