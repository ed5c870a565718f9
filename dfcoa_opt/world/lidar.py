"""2-D LiDAR simulation (interface; the implementation is being written).

Contract used by the rest of the toolkit:

``LaserScan`` (ROS ``sensor_msgs/LaserScan`` fields, REP-117 values):
    angle_min, angle_increment (rad, robot frame, counter-clockwise, 0 = heading),
    range_min, range_max (m), ranges ``(N, B)`` (or ``(B,)``) with ``+inf`` = no
    return and ``-inf`` = closer than range_min. Method ``take(rows)`` and
    property ``angles`` ``(B,)``.

``Lidar(spec: LidarSpec, grid: OccupancyGrid)``:
    ``scan(poses (N,3), discs_xy (M,2), discs_r (M,), owner (M,) int, rng=None) -> LaserScan``
    casts ``spec.beams`` beams from every pose against the grid (exact cell
    traversal) and the discs (exact ray-circle); disc ``m`` is invisible to
    robot ``owner[m]`` (its own body), ``owner = -1`` for moving obstacles.
    Noise ``N(0, noise_std)`` is drawn from ``rng`` only when noise_std > 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True)
class LaserScan:
    """A batch of LaserScan-like records sharing one beam layout.

    Attributes:
        angle_min: Angle of the first beam in the robot frame, rad.
        angle_increment: Angle between beams, rad.
        range_min: Smallest valid range, m.
        range_max: Largest valid range, m.
        ranges: ``(N, B)`` ranges in m; ``+inf`` = no return, ``-inf`` = too close.
    """

    angle_min: float
    angle_increment: float
    range_min: float
    range_max: float
    ranges: NDArray[np.float64]

    @property
    def angles(self) -> NDArray[np.float64]:
        """Beam angles in the robot frame, ``(B,)`` rad."""
        return self.angle_min + self.angle_increment * np.arange(self.ranges.shape[-1])

    def take(self, rows: NDArray[np.intp]) -> LaserScan:
        """The scans of the given rows."""
        return LaserScan(self.angle_min, self.angle_increment, self.range_min, self.range_max,
                         self.ranges[rows])
