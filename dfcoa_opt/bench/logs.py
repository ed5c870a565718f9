"""Reading the runs' logs of a results folder, and compacting the logs no figure reads.

Every renderer reads a run's log through :func:`read_log`, which can record
what it reads (:func:`tracing`). ``make figures`` keeps, after its last render,
the full log of every run a figure drew and replaces each other log by a
*compact log* (:func:`compact_bytes`): the robots' and the leader's poses and
the moving discs at 1 mm and 1 mrad, the contact counts and the run's facts,
about 3 % of the full log. Rows (metrics, outcome, digest) are untouched, so
every table is the same and a cached run stays cached; a figure that later
wants a compacted log gets :class:`LogCompacted`, and ``make figures`` runs
those runs again (the same bits: the digest in the row says so).
"""

from __future__ import annotations

import contextlib
import io
import json
import zipfile
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.atomic import atomic_write
from dfcoa_opt.errors import DfcoaError
from dfcoa_opt.sim.log import COMPACT_FORMAT, RunLog, is_compact

Row = Mapping[str, Any]
#: Quantisation of the compact logs: positions in mm, headings in mrad.
POSITION_STEP, ANGLE_STEP = 1e-3, 1e-3

_TRACE: list[set[str]] = []


class LogCompacted(DfcoaError):
    """A renderer asked for the full log of a run whose log was compacted."""

    def __init__(self, results_dir: Path, key: str) -> None:
        super().__init__(f"{results_dir}: the log of {key} was compacted (only its trajectories "
                         "are kept); run it again for the full log")
        self.results_dir, self.key = results_dir, key


@contextlib.contextmanager
def tracing() -> Iterator[set[str]]:
    """Record the keys of the runs whose logs :func:`read_log` reads inside the block."""
    keys: set[str] = set()
    _TRACE.append(keys)
    try:
        yield keys
    finally:
        _TRACE.remove(keys)


def read_log(results_dir: str | Path, row: Row) -> RunLog:
    """A row's full log (the one way reports and figures read logs).

    Raises:
        LogCompacted: Its log was compacted.
        DfcoaError: No such file, or a damaged one (one line).
    """
    results_dir = Path(results_dir)
    path = results_dir / str(row["log"])
    for keys in _TRACE:
        keys.add(str(row["key"]))
    try:
        if is_compact(path):
            raise LogCompacted(results_dir, str(row["key"]))
        return RunLog.load(path)
    except FileNotFoundError:
        raise DfcoaError(f"{path}: log file not found") from None
    except DfcoaError:
        raise
    except Exception as exc:  # noqa: BLE001 - numpy/zip/json errors of a damaged file
        problem = " ".join(str(exc).split()) or type(exc).__name__
        raise DfcoaError(f"{path}: cannot read the log ({problem})") from None


def _deltas(x: NDArray[np.float64], step: float) -> NDArray[np.int64]:
    """``x`` in steps of ``step``, as differences along the time axis (small integers)."""
    q = np.round(np.nan_to_num(x, nan=0.0) / step).astype(np.int64)
    return np.diff(q, axis=0, prepend=np.zeros_like(q[:1]))


def compact_bytes(log: RunLog) -> bytes:
    """The compact form of a log: poses, leader, moving discs, contacts and facts.

    Poses and the leader's pose at :data:`POSITION_STEP` m and
    :data:`ANGLE_STEP` rad, stored as differences between steps; contact
    counts, offsets, disc radii and ``meta`` as they are. Deflate level 9.
    """
    members = {
        "format": np.array(COMPACT_FORMAT),
        "meta": np.array(json.dumps(log.meta, default=str)),
        "t_steps": np.array([len(log.t), float(log.t[1] - log.t[0]) if len(log.t) > 1 else 0.0]),
        "pose_xy": _deltas(log.pose[..., :2], POSITION_STEP).astype(np.int32),
        "pose_theta": _deltas(log.pose[..., 2], ANGLE_STEP).astype(np.int32),
        "leader_xy": _deltas(log.leader[:, :2], POSITION_STEP).astype(np.int32),
        "leader_theta": _deltas(log.leader[:, 2], ANGLE_STEP).astype(np.int32),
        "dyn_xy": _deltas(log.dyn_pos, POSITION_STEP).astype(np.int32),
        "offsets": log.offsets, "dyn_radius": log.dyn_radius,
        "robot_contacts": log.robot_contacts, "obstacle_contacts": log.obstacle_contacts,
        "dynamic_contacts": log.dynamic_contacts, "collision_events": log.collision_events,
    }
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED, compresslevel=9) as z:
        for name, arr in members.items():
            with z.open(f"{name}.npy", "w", force_zip64=True) as f:
                np.lib.format.write_array(f, np.asanyarray(arr), allow_pickle=False)
    return buf.getvalue()


@dataclass(frozen=True)
class CompactLog:
    """A compact log read back (:func:`load_compact`): the run's trajectories, rounded.

    Attributes:
        t: ``(T,)`` time, s.
        pose: ``(T, N, 3)`` poses, to 1 mm and 1 mrad.
        leader: ``(T, 3)`` the virtual leader's pose, likewise.
        dyn_pos: ``(T, M, 2)`` moving discs, to 1 mm.
        offsets: ``(N, 2)`` slot offsets, m.
        dyn_radius: ``(M,)`` disc radii, m.
        contacts: Contact counts per step: ``robot``, ``obstacle``, ``dynamic``, ``events``.
        meta: The run's facts (as in :class:`~dfcoa_opt.sim.log.RunLog`).
    """

    t: NDArray[np.float64]
    pose: NDArray[np.float64]
    leader: NDArray[np.float64]
    dyn_pos: NDArray[np.float64]
    offsets: NDArray[np.float64]
    dyn_radius: NDArray[np.float64]
    contacts: dict[str, NDArray[np.int32]]
    meta: dict[str, Any]


def load_compact(path: str | Path) -> CompactLog:
    """Read a compact log written by :func:`compact_log`."""
    with np.load(path, allow_pickle=False) as z:
        d = {k: z[k] for k in z.files}
    steps, dt = int(d["t_steps"][0]), float(d["t_steps"][1])

    def undo(name: str, step: float) -> NDArray[np.float64]:
        return np.cumsum(d[name].astype(np.int64), axis=0) * step

    pose = np.concatenate((undo("pose_xy", POSITION_STEP),
                           undo("pose_theta", ANGLE_STEP)[..., None]), axis=-1)
    leader = np.column_stack((undo("leader_xy", POSITION_STEP), undo("leader_theta", ANGLE_STEP)))
    return CompactLog(np.arange(steps) * dt, pose, leader, undo("dyn_xy", POSITION_STEP),
                      d["offsets"], d["dyn_radius"],
                      {"robot": d["robot_contacts"], "obstacle": d["obstacle_contacts"],
                       "dynamic": d["dynamic_contacts"], "events": d["collision_events"]},
                      json.loads(str(d["meta"])))


def compact_log(path: str | Path) -> int:
    """Replace a full log file by its compact form (atomically); the bytes saved (0 if compact)."""
    path = Path(path)
    if is_compact(path):
        return 0
    before = path.stat().st_size
    data = compact_bytes(RunLog.load(path))
    atomic_write(path, data)
    return before - len(data)


def compact_store(root: str | Path, keep: Iterable[str]) -> tuple[int, int]:
    """Compact every log of a results folder but those of the runs ``keep``.

    Returns:
        ``(logs compacted, bytes saved)``.
    """
    root = Path(root)
    keep = set(keep)
    count = saved = 0
    for path in sorted((root / "logs").glob("*.npz")):
        if path.stem in keep:
            continue
        gained = compact_log(path)
        count += gained > 0
        saved += gained
    atomic_write(root / "logs_read.json", json.dumps(sorted(keep), indent=0) + "\n")
    return count, saved
