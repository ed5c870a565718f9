"""Start-up: how long the ``dfcoa`` command takes for the things a new user types first.

Each row times the whole command (a new process, as a shell runs it) in
:data:`~benchmarks.timing.REPS` interleaved repetitions after one warm-up run
(numba's kernel cache warm): ``dfcoa --help``, ``dfcoa list controllers`` and a
whole ``dfcoa run scenarios/example_empty.toml --controller goto_slot``.
Targets: 0.3 s, 1 s and 2 s. There is no peer.

``python -m benchmarks.bench_startup`` prints the rows.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.timing import REPS, print_rows, row

ROOT = Path(__file__).resolve().parents[1]
DFCOA = str(Path(sys.executable).with_name("dfcoa"))


def commands(out: str) -> dict[str, list[str]]:
    """Row title -> the command."""
    return {
        "dfcoa --help": [DFCOA, "--help"],
        "dfcoa list controllers": [DFCOA, "list", "controllers"],
        "dfcoa run example_empty.toml --controller goto_slot (whole process)":
            [DFCOA, "run", str(ROOT / "scenarios" / "example_empty.toml"), "--controller",
             "goto_slot", "--out", out],
    }


def _seconds(cmd: list[str]) -> float:
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True, cwd=ROOT)
    return time.perf_counter() - t0


def run() -> list[dict]:
    """One row per command: wall time of the whole process, us."""
    with tempfile.TemporaryDirectory() as out:
        cmds = commands(out)
        for cmd in cmds.values():  # warm-up: numba's cache, the OS's file cache
            _seconds(cmd)
        times: dict[str, list[np.ndarray]] = {what: [] for what in cmds}
        for rep in range(REPS):
            for what in (list(cmds) if rep % 2 == 0 else list(cmds)[::-1]):
                times[what].append(np.array([_seconds(cmds[what]) * 1e6]))
    return [row(what, reps) for what, reps in times.items()]


if __name__ == "__main__":
    print_rows(run())
