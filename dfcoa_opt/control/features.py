"""What a learning agent sees: one robot's :class:`Observation` row as a flat vector.

The environments (:mod:`dfcoa_opt.envs`) and the policy controllers
(``policy:PATH``) build the same vector with :func:`flatten`, so a policy
trained in an environment runs unchanged as a controller. Everything is in
the robot's own frame (x forward, y left) and scaled to about [-1, 1]:

==========================  =====  ==================================================
block                       width  content
==========================  =====  ==================================================
``slot``                    2      the slot minus the robot's position / ``range``
``heading``                 2      cos, sin of (leader heading - own heading)
``velocity``                2      own world velocity / ``v_max``
``slot_velocity``           2      the slot's velocity under the leader's motion / ``v_max``
``lidar``                   B      every ``stride``-th beam's range / ``range_max``
                                   (no return: 1; no LiDAR: 1)
``neighbours``              5 K    the K nearest neighbours: position, velocity
                                   (relative, / ``range`` and / ``v_max``), present
``obstacles``               6 M    the M nearest sensed moving obstacles: position,
                                   velocity (relative), radius / ``range``, present
==========================  =====  ==================================================

Absent entries (fewer neighbours or obstacles, or none in range) are zeros
with ``present = 0``. :meth:`ObservationSpec.layout` gives each block's slice.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.control.base import Observation, slot_velocity
from dfcoa_opt.control.features_kernel import flatten_rows
from dfcoa_opt.core.params import param

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class ObservationSpec:
    """How an :class:`Observation` row becomes a vector (module docstring)."""

    beams: int = param(16, doc="LiDAR beams kept (every stride-th of the scan, evenly).",
                       ge=0, le=4096)
    neighbours: int = param(4, doc="Nearest neighbours kept, K.", ge=0, le=64)
    obstacles: int = param(2, doc="Nearest sensed moving obstacles kept, M.", ge=0, le=64)
    range: float = param(5.0, doc="Distance scale of positions.", unit="m", gt=0.0)
    v_max: float = param(0.5, doc="Speed scale of velocities.", unit="m/s", gt=0.0)

    @property
    def size(self) -> int:
        """Length of the vector."""
        return 8 + self.beams + 5 * self.neighbours + 6 * self.obstacles

    def layout(self) -> dict[str, slice]:
        """Each block's slice of the vector, in order (module docstring)."""
        widths = {"slot": 2, "heading": 2, "velocity": 2, "slot_velocity": 2,
                  "lidar": self.beams, "neighbours": 5 * self.neighbours,
                  "obstacles": 6 * self.obstacles}
        out, start = {}, 0
        for name, w in widths.items():
            out[name] = slice(start, start + w)
            start += w
        return out


def _to_body(vec: FloatArray, heading: FloatArray) -> FloatArray:
    """World vectors ``(R, ..., 2)`` in each row's body frame (heading ``(R,)``)."""
    c, s = np.cos(heading), np.sin(heading)
    shape = (len(heading),) + (1,) * (vec.ndim - 2)
    c, s = c.reshape(shape), s.reshape(shape)
    return np.stack((c * vec[..., 0] + s * vec[..., 1], -s * vec[..., 0] + c * vec[..., 1]),
                    axis=-1)


_NO_ENV = np.zeros(0, dtype=np.intp)
_NO_RANGES = np.zeros((0, 0))


def _f64(x: object) -> FloatArray:
    """``x`` as a C-contiguous float64 array (itself when it is one)."""
    return np.ascontiguousarray(x, dtype=np.float64)


def flatten(obs: Observation, spec: ObservationSpec) -> FloatArray:
    """Every row of ``obs`` as the vector of :class:`ObservationSpec` (module docstring).

    One compiled pass (:func:`~dfcoa_opt.control.features_kernel.flatten_rows`) with the
    bits of :func:`flatten_reference`.

    Args:
        obs: The observation of one run, or of a batch (``obs.env`` set).
        spec: What to keep and the scales.

    Returns:
        ``(R, spec.size)`` float64, one row per robot.
    """
    scan, nb, mv = obs.scan, obs.neighbours, obs.obstacles
    r = len(obs.pose)
    ranges = _NO_RANGES if scan is None else _f64(scan.ranges).reshape(r, -1)
    return flatten_rows(
        _f64(obs.pose), _f64(obs.velocity), _f64(obs.leader).reshape(-1, 5),
        _NO_ENV if obs.env is None else np.ascontiguousarray(obs.env, dtype=np.intp),
        _f64(obs.slot), ranges, scan is not None,
        1.0 if scan is None else float(scan.range_max),
        np.ascontiguousarray(nb.index, dtype=np.intp), _f64(nb.position), _f64(nb.velocity),
        _f64(mv.position), _f64(mv.velocity), _f64(mv.radius),
        np.ascontiguousarray(mv.mask, dtype=np.bool_), int(spec.beams), int(spec.neighbours),
        int(spec.obstacles), float(spec.range), float(spec.v_max))


def flatten_reference(obs: Observation, spec: ObservationSpec) -> FloatArray:
    """:func:`flatten` in vectorised numpy: the reference its compiled pass gives bit for bit.

    Args:
        obs: The observation of one run, or of a batch (``obs.env`` set).
        spec: What to keep and the scales.

    Returns:
        ``(R, spec.size)`` float64, one row per robot.
    """
    r = obs.n
    pos, th = obs.pose[:, :2], obs.pose[:, 2]
    lead = obs.row_leader()
    out = np.zeros((r, spec.size))
    lay = spec.layout()
    out[:, lay["slot"]] = _to_body(obs.slot - pos, th) / spec.range
    rel = lead[:, 2] - th
    out[:, lay["heading"]] = np.column_stack((np.cos(rel), np.sin(rel)))
    out[:, lay["velocity"]] = _to_body(obs.velocity, th) / spec.v_max
    out[:, lay["slot_velocity"]] = _to_body(slot_velocity(lead, obs.slot), th) / spec.v_max
    if spec.beams:
        if obs.scan is None:
            out[:, lay["lidar"]] = 1.0
        else:
            ranges = np.asarray(obs.scan.ranges, dtype=float).reshape(r, -1)
            pick = (np.arange(spec.beams) * ranges.shape[1]) // spec.beams
            beams = ranges[:, pick] / obs.scan.range_max
            out[:, lay["lidar"]] = np.where(np.isposinf(beams), 1.0,
                                            np.where(np.isneginf(beams), 0.0, beams))
    if spec.neighbours:
        k = min(spec.neighbours, obs.neighbours.index.shape[1])
        nb = obs.neighbours
        block = np.zeros((r, spec.neighbours, 5))
        present = nb.mask[:, :k]
        block[:, :k, 0:2] = _to_body(nb.position[:, :k] - pos[:, None], th) / spec.range
        block[:, :k, 2:4] = _to_body(nb.velocity[:, :k] - obs.velocity[:, None], th) / spec.v_max
        block[:, :k, 4] = 1.0
        block[:, :k] *= present[..., None]
        out[:, lay["neighbours"]] = block.reshape(r, -1)
    if spec.obstacles:
        mv = obs.obstacles
        m = mv.mask.shape[1]
        block = np.zeros((r, spec.obstacles, 6))
        if m:
            dist = np.where(mv.mask, np.hypot(*(mv.position - pos[:, None]).transpose(2, 0, 1)),
                            np.inf)
            order = np.argsort(dist, axis=1, kind="stable")[:, :spec.obstacles]
            kk = order.shape[1]
            rows = np.arange(r)[:, None]
            present = mv.mask[rows, order]
            block[:, :kk, 0:2] = _to_body(mv.position[rows, order] - pos[:, None], th) / spec.range
            block[:, :kk, 2:4] = (_to_body(mv.velocity[rows, order] - obs.velocity[:, None], th)
                                  / spec.v_max)
            block[:, :kk, 4] = mv.radius[rows, order] / spec.range
            block[:, :kk, 5] = 1.0
            block[:, :kk] *= present[..., None]
        out[:, lay["obstacles"]] = block.reshape(r, -1)
    return out
