"""The run log: every array a run produces, saved to one ``.npz``.

Index ``k`` of every time axis is the instant ``t[k] = k * dt``: the state the
robots sensed, and the command they then applied during ``[t[k], t[k] + dt)``.
"""

from __future__ import annotations

import hashlib
import io
import json
import zipfile
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.core.atomic import atomic_write
from dfcoa_opt.core.errors import DfcoaError

FloatArray = NDArray[np.float64]


#: Log fields that are measured wall-clock times (not part of a run's result).
TIMING_FIELDS = ("filter_time",)
#: Log fields that are None unless a run asks for them (not in a log without them).
OPTIONAL_FIELDS = ("scan",)
#: The ``format`` member of a compact log (:mod:`dfcoa_opt.bench.results.logs`): trajectories only.
COMPACT_FORMAT = "dfcoa-compact-log/2"  # /2: meta as UTF-8 bytes (/1: a numpy string)
#: The member of a pruned log (:mod:`dfcoa_opt.bench.results.logs`) naming the fields it keeps.
PRUNED_MEMBER = "pruned"


def npz_bytes(members: dict[str, Any], level: int) -> bytes:
    """An ``.npz`` file's contents (``np.load`` reads it), each member deflated at ``level``."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED, compresslevel=level) as z:
        for name, arr in members.items():
            with z.open(f"{name}.npy", "w", force_zip64=True) as f:
                np.lib.format.write_array(f, np.asanyarray(arr), allow_pickle=False)
    return buf.getvalue()


def is_compact(path: str | Path) -> bool:
    """Whether a log file is a compact log (trajectories only), not a :class:`RunLog`."""
    try:
        with zipfile.ZipFile(path) as z:
            return "format.npy" in z.namelist()
    except zipfile.BadZipFile:
        return False


def is_pruned(path: str | Path) -> bool:
    """Whether a log file keeps only some fields, exact (the ones figures read)."""
    try:
        with zipfile.ZipFile(path) as z:
            return f"{PRUNED_MEMBER}.npy" in z.namelist()
    except zipfile.BadZipFile:
        return False


@dataclass
class RunLog:
    """Arrays of one run (T steps, N robots, M moving obstacles).

    Attributes:
        t: ``(T,)`` time, s.
        pose: ``(T, N, 3)`` true pose (m, m, rad).
        pose_est: ``(T, N, 3)`` pose the controller was given (estimate or truth).
        velocity: ``(T, N, 2)`` true world-frame velocity, m/s.
        twist: ``(T, N, 2)`` applied (v, omega) during step k, m/s and rad/s.
        command: ``(T, N, k)`` raw controller output (its own command kind).
        leader: ``(T, 5)`` virtual leader (x, y, theta, v, omega).
        slots: ``(T, N, 2)`` desired positions from the leader and the offsets, m.
        offsets: ``(N, 2)`` formation slot offsets in the leader frame, m.
        clearance: ``(T, N)`` distance from each robot centre to the nearest static
            obstacle (capped at ``metrics.clearance_cap``), m.
        min_inter_robot: ``(T,)`` smallest centre distance between two robots, m
            (``inf`` with one robot).
        robot_contacts: ``(T,)`` robot pairs overlapping at t[k].
        obstacle_contacts: ``(T,)`` robots touching a static obstacle at t[k].
        dynamic_contacts: ``(T,)`` robots overlapping a moving obstacle at t[k].
        collision_events: ``(T,)`` contacts that began at t[k] (a contact that
            lasts several steps counts once).
        dyn_pos: ``(T, M, 2)`` moving obstacle positions, m.
        dyn_radius: ``(M,)`` moving obstacle radii, m.
        filter_status: ``(T, N)`` int8 safety-filter status
            (``dfcoa_opt.control.base.STATUS_*``; 0 when there is no filter).
        filter_slack: ``(T, N)`` constraint violation left by the filter.
        filter_time: ``(T, N)`` filter solve time per robot, s.
        steering: ``(T, N)`` steering direction chosen by the controller's local
            planner, robot frame, rad (NaN when the controller reports none;
            controllers report it as ``last_steering``).
        meta: JSON-serialisable run facts: scenario, controller, seed, dt, n,
            robot_radius, reached_goal, time_to_goal, steps, ...
        scan: ``(T, N, B)`` the LiDAR ranges each robot had at t[k], m (``+inf`` no
            return, ``-inf`` too close); only when the run was asked to record them
            (``BatchSimulator(record_scans=True)``, ``dfcoa run --mcap``) and the
            LiDAR ran; None otherwise. ``meta["scan"]`` then holds the beam layout.
    """

    t: FloatArray
    pose: FloatArray
    pose_est: FloatArray
    velocity: FloatArray
    twist: FloatArray
    command: FloatArray
    leader: FloatArray
    slots: FloatArray
    offsets: FloatArray
    clearance: FloatArray
    min_inter_robot: FloatArray
    robot_contacts: NDArray[np.int32]
    obstacle_contacts: NDArray[np.int32]
    dynamic_contacts: NDArray[np.int32]
    collision_events: NDArray[np.int32]
    dyn_pos: FloatArray
    dyn_radius: FloatArray
    filter_status: NDArray[np.int8]
    filter_slack: FloatArray
    filter_time: FloatArray
    steering: FloatArray
    meta: dict[str, Any] = field(default_factory=dict)
    scan: FloatArray | None = None

    @classmethod
    def allocate(cls, steps: int, n: int, m: int, k: int = 2) -> RunLog:
        """Zero-filled log to be filled by the simulator and trimmed by :meth:`truncated`.

        Args:
            steps: Instants to hold.
            n: Robots.
            m: Moving obstacles.
            k: Command columns.
        """
        z = np.zeros
        return cls(t=z(steps), pose=z((steps, n, 3)), pose_est=z((steps, n, 3)),
                   velocity=z((steps, n, 2)), twist=z((steps, n, 2)),
                   command=z((steps, n, k)), leader=z((steps, 5)), slots=z((steps, n, 2)),
                   offsets=z((n, 2)), clearance=z((steps, n)), min_inter_robot=z(steps),
                   robot_contacts=z(steps, np.int32), obstacle_contacts=z(steps, np.int32),
                   dynamic_contacts=z(steps, np.int32), collision_events=z(steps, np.int32),
                   dyn_pos=z((steps, m, 2)), dyn_radius=z(m),
                   filter_status=z((steps, n), np.int8), filter_slack=z((steps, n)),
                   filter_time=z((steps, n)), steering=np.full((steps, n), np.nan))

    def truncated(self, end: int) -> RunLog:
        """The first ``end`` instants (per-run arrays ``offsets``, ``dyn_radius`` kept)."""
        keep = {"offsets", "dyn_radius"}
        arrays = {k: (v if k in keep else v[:end].copy()) for k, v in self.arrays().items()}
        return RunLog(meta=dict(self.meta), **arrays)

    @property
    def n_steps(self) -> int:
        """Number of logged steps T."""
        return len(self.t)

    @property
    def n_robots(self) -> int:
        """Number of robots N."""
        return self.pose.shape[1]

    #: Fields of :meth:`trajectories`: time (s), robot index, true pose (m, m, rad),
    #: world velocity (m/s), formation slot (m), static-obstacle clearance (m).
    TRAJECTORY_FIELDS = ("t", "robot", "x", "y", "theta", "vx", "vy", "slot_x", "slot_y",
                         "clearance")

    def trajectories(self) -> np.ndarray:
        """The robots' trajectories as one record per (step, robot), with named fields.

        Returns:
            A ``(T * N,)`` numpy structured array with the fields of
            :data:`TRAJECTORY_FIELDS` (``robot`` int, the others float), step by
            step: ``traj[traj["robot"] == 2]["x"]`` is robot 2's x over time, and
            ``pandas.DataFrame(traj)`` is a long table.
        """
        n_steps, n = self.n_steps, self.n_robots
        dtype = [(f, np.int64 if f == "robot" else np.float64) for f in self.TRAJECTORY_FIELDS]
        out = np.empty(n_steps * n, dtype=dtype)
        cols = {"t": np.repeat(self.t, n), "robot": np.tile(np.arange(n), n_steps),
                "x": self.pose[..., 0], "y": self.pose[..., 1], "theta": self.pose[..., 2],
                "vx": self.velocity[..., 0], "vy": self.velocity[..., 1],
                "slot_x": self.slots[..., 0], "slot_y": self.slots[..., 1],
                "clearance": self.clearance}
        for name, values in cols.items():
            out[name] = np.asarray(values).reshape(-1)
        return out

    def arrays(self) -> dict[str, np.ndarray]:
        """All array fields by name (an :data:`OPTIONAL_FIELDS` one only when present)."""
        out = {f.name: getattr(self, f.name) for f in fields(self) if f.name != "meta"}
        return {k: v for k, v in out.items() if v is not None or k not in OPTIONAL_FIELDS}

    def digest(self) -> str:
        """SHA-256 over every array's bytes but the timings: equal digests = bit-identical runs.

        ``filter_time`` is wall-clock time, different in every run, so it is left out
        (:data:`TIMING_FIELDS`); so are the arrays a run records only on request
        (:data:`OPTIONAL_FIELDS`: ``scan``), which do not change the run, so that a
        run has one digest whether or not it recorded them.
        """
        h = hashlib.sha256()
        for name, arr in sorted(self.arrays().items()):
            if name in TIMING_FIELDS or name in OPTIONAL_FIELDS:
                continue
            a = np.ascontiguousarray(arr)
            h.update(name.encode())
            h.update(str(a.dtype).encode() + str(a.shape).encode())
            h.update(a.tobytes())
        return h.hexdigest()

    def to_bytes(self) -> bytes:
        """The compressed ``.npz`` file contents (meta as JSON), readable by ``np.load``.

        Written like ``np.savez_compressed`` but at deflate level 1: on a
        100-robot log that is 2.9x faster (49 ms against 139 ms) for a file
        10 % larger (2.0 MB against 1.8 MB). ``pose_est`` is left out when it
        is ``pose`` bit for bit (``truth`` localisation), and :meth:`load` puts
        it back: on a 100-robot run that spares 39 of 159 ms and 1.5 of 6.5 MB.
        """
        members = {"meta": np.array(json.dumps(self.meta, default=str)), **self.arrays()}
        if _same_bits(self.pose_est, self.pose):
            del members["pose_est"]
        return npz_bytes(members, 1)

    def save(self, path: str | Path) -> Path:
        """Write :meth:`to_bytes` to ``path`` atomically; returns the path."""
        return atomic_write(path, self.to_bytes())

    @classmethod
    def load(cls, path: str | Path) -> RunLog:
        """Read a log written by :meth:`save` (a left-out ``pose_est`` is ``pose``).

        Raises:
            DfcoaError: ``path`` is a compact log (``make figures`` compacts the logs
                no figure reads; :func:`dfcoa_opt.bench.results.logs.load_compact` reads them).
        """
        with np.load(path, allow_pickle=False) as z:
            if "format" in z.files:
                raise DfcoaError(f"{path}: a compact log (trajectories only, "
                                 f"{str(z['format'])}); read it with "
                                 "dfcoa_opt.bench.results.logs.load_compact")
            if PRUNED_MEMBER in z.files:
                raise DfcoaError(f"{path}: a pruned log (only the fields figures read: "
                                 f"{', '.join(map(str, z[PRUNED_MEMBER]))}); read it with "
                                 "dfcoa_opt.bench.results.logs.read_log")
            return cls.from_members({k: z[k] for k in z.files})

    @classmethod
    def from_members(cls, data: dict[str, np.ndarray]) -> RunLog:
        """A log from the members of its ``.npz`` file (see :meth:`to_bytes`); consumes ``data``."""
        meta = json.loads(str(data.pop("meta")))
        if "pose_est" not in data:
            data["pose_est"] = data["pose"].copy()
        return cls(meta=meta, **data)


class BatchLog:
    """The logs of E runs as ``(E, T, ...)`` arrays: one write per field and step for all runs.

    The fields are those of :class:`RunLog` with a leading run axis (``t`` is
    shared); :meth:`run` copies one run out.
    """

    def __init__(self, arrays: dict[str, np.ndarray]) -> None:
        self.__dict__.update(arrays)
        self._names = list(arrays)

    @classmethod
    def allocate(cls, runs: int, steps: int, n: int, m: int, k: int) -> BatchLog:
        """Zero-filled logs of ``runs`` runs (``steering`` NaN), as :meth:`RunLog.allocate`."""
        one = RunLog.allocate(steps, n, m, k)
        arrays = {name: (arr if name == "t" else np.repeat(arr[None], runs, axis=0))
                  for name, arr in one.arrays().items() if name not in ("offsets", "dyn_radius")}
        return cls(arrays)

    def write(self, active: NDArray[np.intp], k: NDArray[np.int64],
              **fields: np.ndarray | int) -> tuple[Any, Any]:
        """Write instant ``k[j]`` of run ``active[j]`` of every given field, one write a field.

        Args:
            active: ``(A,)`` the runs, strictly increasing.
            k: ``(A,)`` their instants.
            **fields: Each field's ``(A, ...)`` rows (or a scalar for all).

        Returns:
            The index written (``(active, k)``, or a slice of runs and one
            instant when the runs are consecutive on one clock: a cheaper write).
        """
        a = len(active)
        one = a and active[-1] - active[0] == a - 1 and (a == 1 or bool((k == k[0]).all()))
        at = (slice(int(active[0]), int(active[-1]) + 1), int(k[0])) if one else (active, k)
        for name, rows in fields.items():
            getattr(self, name)[at] = rows
        return at

    def clear(self, e: int) -> None:
        """Run ``e``'s rows as :meth:`allocate` left them (a new run in that slot)."""
        for name in self._names:
            if name != "t":
                getattr(self, name)[e] = np.nan if name == "steering" else 0

    def run(self, e: int, end: int, offsets: FloatArray, dyn_radius: FloatArray) -> RunLog:
        """Run ``e``'s first ``end`` instants as a :class:`RunLog` (copies)."""
        arrays = {name: (getattr(self, name)[:end] if name == "t" else
                         getattr(self, name)[e, :end]).copy() for name in self._names}
        return RunLog(offsets=np.array(offsets, dtype=float),
                      dyn_radius=np.array(dyn_radius, dtype=float), **arrays)

def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two arrays hold the same bytes (unlike ``==``, tells -0.0 from 0.0)."""
    return a.dtype == b.dtype and a.shape == b.shape and \
        np.ascontiguousarray(a).tobytes() == np.ascontiguousarray(b).tobytes()
