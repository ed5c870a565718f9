"""Reading the runs' logs of a results folder, and shrinking the logs figures do not need.

Every renderer reads a run's log through :func:`read_log`, which can record
which fields of which runs it reads (:func:`tracing`). ``make figures`` then,
after its last render, *prunes* the log of every run a figure drew to the fields
it read, exact (:func:`pruned_bytes`), and replaces each other log by a
*compact log* (:func:`compact_bytes`): the robots' and the leader's poses and
the moving discs at 1 mm and 1 mrad, the contact counts and the run's facts,
about 3 % of the full log. Rows (metrics, outcome, digest) are untouched, so
every table is the same and a cached run stays cached; a figure that later
wants a compacted log, or a field its pruned log lacks, gets
:class:`LogCompacted`, and ``make figures`` runs those runs again (the same
bits: the digest in the row says so).
"""

from __future__ import annotations

import contextlib
import json
from collections.abc import Iterable, Iterator, Mapping
from concurrent.futures import Executor
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.core.atomic import atomic_write
from dfcoa_opt.core.errors import DfcoaError
from dfcoa_opt.sim.log import (
    COMPACT_FORMAT,
    OPTIONAL_FIELDS,
    PRUNED_MEMBER,
    RunLog,
    is_compact,
    is_pruned,
    npz_bytes,
)

Row = Mapping[str, Any]
#: Quantisation of the compact logs: positions in mm, headings in mrad.
POSITION_STEP, ANGLE_STEP = 1e-3, 1e-3

#: Open :func:`tracing` blocks: run key -> the log fields read.
_TRACE: list[dict[str, set[str]]] = []
#: The fields of a log (``meta`` included; not the optional ones, which a log may lack).
FIELDS = frozenset(f.name for f in fields(RunLog)) - set(OPTIONAL_FIELDS)


class LogCompacted(DfcoaError):
    """A renderer asked for a part of a run's log that the cache no longer keeps."""

    def __init__(self, results_dir: Path, key: str, field: str | None = None) -> None:
        what = (f"was pruned to the fields figures read (not {field!r})" if field else
                "was compacted (only its trajectories are kept)")
        super().__init__(f"{results_dir}: the log of {key} {what}; run it again for the full "
                         "log")
        self.results_dir, self.key = results_dir, key


class _ReadLog(RunLog):
    """A log read by :func:`read_log`: notes the fields read; a pruned one lacks some.

    ``_reads``: the sets of the open :func:`tracing` blocks to add each field
    read to; ``_missing``: the fields a pruned log does not keep, whose reading
    raises :class:`LogCompacted` (``_where``: its results folder and run key).
    """

    def __getattribute__(self, name: str) -> Any:
        if name in FIELDS:
            state = object.__getattribute__(self, "__dict__")
            for read in state.get("_reads", ()):
                read.add(name)
            if name in state.get("_missing", ()):
                raise LogCompacted(*state["_where"], name)
        return object.__getattribute__(self, name)


@contextlib.contextmanager
def tracing() -> Iterator[dict[str, set[str]]]:
    """Record, inside the block, the runs whose logs :func:`read_log` reads and the fields read."""
    reads: dict[str, set[str]] = {}
    _TRACE.append(reads)
    try:
        yield reads
    finally:
        _TRACE.remove(reads)


def read_log(results_dir: str | Path, row: Row) -> RunLog:
    """A row's log (the one way reports and figures read logs); every field exact.

    Raises:
        LogCompacted: Its log was compacted, or a field its pruned log lacks is read.
        DfcoaError: No such file, or a damaged one (one line).
    """
    results_dir = Path(results_dir)
    path = results_dir / str(row["log"])
    key = str(row["key"])
    reads = [trace.setdefault(key, set()) for trace in _TRACE]
    try:
        with np.load(path, allow_pickle=False) as z:
            if "format" in z.files:
                raise LogCompacted(results_dir, key)
            data = {k: z[k] for k in z.files}
    except FileNotFoundError:
        raise DfcoaError(f"{path}: log file not found") from None
    except DfcoaError:
        raise
    except Exception as exc:  # noqa: BLE001 - numpy/zip/json errors of a damaged file
        problem = " ".join(str(exc).split()) or type(exc).__name__
        raise DfcoaError(f"{path}: cannot read the log ({problem})") from None
    missing: set[str] = set()
    if PRUNED_MEMBER in data:
        missing = FIELDS - {"meta"} - {str(f) for f in data.pop(PRUNED_MEMBER)}
    return _log(data, missing, (results_dir, key), reads)


def _log(data: dict[str, np.ndarray], missing: Iterable[str], where: tuple[Path, str],
         reads: list[set[str]]) -> RunLog:
    """A :class:`_ReadLog` of a file's members; the fields ``missing`` raise when read."""
    missing = frozenset(missing)
    data.update({name: np.empty(0) for name in missing})
    log = _ReadLog.from_members(data)
    log.__dict__.update(_reads=reads, _missing=missing, _where=where)
    return log


def _fields_of(path: Path, names: Iterable[str]) -> RunLog:
    """Only the fields ``names`` (and ``meta``) of a full or pruned log file, read fast."""
    names = {*names, "meta"}
    with np.load(path, allow_pickle=False) as z:
        data = {k: z[k] for k in names if k in z.files}
        if "pose_est" in names and "pose_est" not in z.files and "pose" in z.files:
            data["pose_est"] = z["pose"]  # a full log leaves out pose_est when it is pose
    return _log(data, FIELDS - {"meta"} - set(data), (path.parent.parent, path.stem), [])


def _deltas(x: NDArray[np.float64], step: float) -> NDArray[np.int64]:
    """``x`` in steps of ``step``, as differences along the time axis (small integers)."""
    q = np.round(np.nan_to_num(x, nan=0.0) / step).astype(np.int64)
    return np.diff(q, axis=0, prepend=np.zeros_like(q[:1]))


#: The fields a compact log is made of.
COMPACT_SOURCES = ("t", "pose", "leader", "dyn_pos", "offsets", "dyn_radius", "robot_contacts",
                   "obstacle_contacts", "dynamic_contacts", "collision_events")


def compact_bytes(log: RunLog) -> bytes:
    """The compact form of a log: poses, leader, moving discs, contacts and facts.

    Poses and the leader's pose at :data:`POSITION_STEP` m and
    :data:`ANGLE_STEP` rad, stored as differences between steps; contact
    counts, offsets, disc radii as they are, ``meta`` as UTF-8 JSON. Deflate level 6
    (level 9: 5x the time for 4 % less).
    """
    members = {
        "format": np.array(COMPACT_FORMAT),
        "meta": np.frombuffer(json.dumps(log.meta, default=str).encode(), dtype=np.uint8),
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
    return npz_bytes(members, 6)


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
                      _meta(d["meta"]))


def _meta(member: np.ndarray) -> dict[str, Any]:
    """A compact log's meta: UTF-8 bytes (format /2), or a numpy string (format /1)."""
    text = member.tobytes().decode() if member.dtype == np.uint8 else str(member)
    return json.loads(text)


def compact_log(path: str | Path) -> int:
    """Replace a full log file by its compact form (atomically); the bytes saved (0 if compact)."""
    path = Path(path)
    if is_compact(path):
        return 0
    before = path.stat().st_size
    try:
        data = compact_bytes(_fields_of(path, COMPACT_SOURCES))
    except LogCompacted:  # a pruned log without the trajectories: left as it is
        return 0
    atomic_write(path, data)
    return before - len(data)


def pruned_bytes(log: RunLog, keep: Iterable[str]) -> bytes:
    """A log file with the fields ``keep`` only (and ``meta``), exact; deflate level 6."""
    keep = sorted(set(keep) - {"meta"})
    members = {PRUNED_MEMBER: np.array(keep), "meta": np.array(json.dumps(log.meta, default=str)),
               **{name: getattr(log, name) for name in keep}}
    return npz_bytes(members, 6)


def prune_log(path: str | Path, keep: Iterable[str]) -> int:
    """Keep only the fields ``keep`` of a full log file (atomically); the bytes saved.

    A log that is already pruned or compact, or of which every field is kept, is left as it is.
    """
    path = Path(path)
    keep = set(keep)
    if is_compact(path) or is_pruned(path) or FIELDS <= keep | {"meta"}:
        return 0
    before = path.stat().st_size
    data = pruned_bytes(_fields_of(path, keep), keep)
    if len(data) >= before:
        return 0
    atomic_write(path, data)
    return before - len(data)


def _shrink(path: Path, keep: frozenset[str] | None) -> tuple[bool, int]:
    """Prune ``path`` to ``keep`` or, with None, compact it: (pruned, bytes saved)."""
    if keep is None:
        return False, compact_log(path)
    return True, prune_log(path, keep)


def compact_store(root: str | Path, keep: Mapping[str, Iterable[str]],
                  pool: Executor | None = None) -> tuple[int, int, int]:
    """Prune the logs of the runs ``keep`` to the fields read and compact every other log.

    Args:
        root: The results folder.
        keep: Run key -> the log fields figures read (:func:`tracing`).
        pool: Worker processes that shrink the logs (each file is written by one
            of them, the same bytes as here); None shrinks them in this process.

    Returns:
        ``(logs compacted, logs pruned, bytes saved)``.
    """
    root = Path(root)
    paths = sorted((root / "logs").glob("*.npz"))
    wanted = [frozenset(keep[p.stem]) if p.stem in keep else None for p in paths]
    done = (pool.map(_shrink, paths, wanted, chunksize=max(1, len(paths) // 64)) if pool
            else map(_shrink, paths, wanted))
    compacted = pruned = saved = 0
    for was_pruned, gained in done:
        pruned += was_pruned and gained > 0
        compacted += not was_pruned and gained > 0
        saved += gained
    listing = {key: sorted(f) for key, f in sorted(keep.items())}
    atomic_write(root / "logs_read.json", json.dumps(listing, indent=0) + "\n")
    return compacted, pruned, saved
