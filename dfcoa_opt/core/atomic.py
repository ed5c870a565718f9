"""Atomic file writes: readers see the old file or the whole new one, never a part.

Also :func:`file_exists`, a file test that never raises (for names read from
input files, which may be too long for the system).

The data goes to a hidden temporary file in the same folder, is flushed to
disk, and is renamed over the target (``os.replace`` is atomic on POSIX and
Windows). A process killed mid-write leaves at most a ``.*.tmp`` file, which
:func:`remove_partials` deletes.
"""

from __future__ import annotations

import os
from pathlib import Path

_TMP_SUFFIX = ".tmp"


def atomic_write(path: str | Path, data: bytes | str) -> Path:
    """Write ``data`` (bytes, or text as UTF-8) to ``path`` atomically; returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}{_TMP_SUFFIX}")
    raw = data.encode("utf-8") if isinstance(data, str) else data
    with open(tmp, "wb") as fh:
        fh.write(raw)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)
    return path


def remove_partials(folder: str | Path) -> int:
    """Delete temporary files left in ``folder`` by killed writers; returns how many."""
    n = 0
    for p in Path(folder).glob(f".*{_TMP_SUFFIX}"):
        p.unlink(missing_ok=True)
        n += 1
    return n


def file_exists(path: str | Path) -> bool:
    """Whether ``path`` is a file; False for a name the system cannot look up (too long)."""
    try:
        return Path(path).is_file()
    except OSError:  # e.g. a name too long
        return False
