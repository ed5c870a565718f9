"""`dfcoa bench` as a real process: Ctrl-C, SIGTERM and SIGKILL stop it cleanly.

Each test starts `python -m dfcoa_opt bench` in a new session (so that the
whole process group can be signalled, as a terminal's Ctrl-C does) on a
48-run sweep of the corridor (about 0.15 s a run on 2 workers), and signals it
once it is mid-sweep: after its first saved row, or while its fork server is
still importing its preload. Timeouts for start-up are generous (a loaded
2-core machine); the 5 s bound after a SIGKILL is not.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SEEDS = 24
RUNS = 2 * SEEDS  # two controllers
MESSAGE = re.compile(r"^dfcoa: interrupted: (\d+) of (\d+) runs saved in (.+); run the same "
                     r"command to resume$")
FORK_SERVER = b"multiprocessing.forkserver"
GONE_WITHIN = 5.0  # s: how long a process of the sweep may outlive its main process


def _sweep(tmp_path: Path) -> Path:
    path = tmp_path / "long.toml"
    corridor = (ROOT / "scenarios" / "bench" / "corridor.toml").as_posix()
    path.write_text(f'scenarios = ["{corridor}"]\ncontrollers = ["orca_nav", "dfcoa"]\n'
                    f"seeds = {SEEDS}\n")
    return path


def _command(sweep: Path, out: Path) -> list[str]:
    return [sys.executable, "-m", "dfcoa_opt", "bench", str(sweep), "--out", str(out), "--jobs",
            "2", "--no-progress"]


def _start(sweep: Path, out: Path) -> subprocess.Popen:
    return subprocess.Popen(_command(sweep, out), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True, cwd=ROOT)


def _rows(out: Path) -> int:
    return len(list((out / "rows").glob("*.json")))


def _wait_until(proc: subprocess.Popen, ready, what: str, timeout: float = 120.0) -> None:
    """Poll ``ready()`` every 10 ms while ``proc`` runs, for at most ``timeout`` s."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if ready():
            return
        assert proc.poll() is None, (what, proc.communicate())
        time.sleep(0.01)
    raise AssertionError(f"timed out waiting for {what}")


def _stat(pid: int) -> list[str] | None:
    """Fields of ``/proc/PID/stat`` after the command name (state first), or None."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None


def _descendants(pid: int) -> dict[int, str]:
    """Every live process whose parent chain leads to ``pid``, with its start time.

    The start time (``/proc/PID/stat`` field 22) tells a reused pid from the original.
    """
    parent, start = {}, {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        fields = _stat(int(stat.parent.name))
        if fields is not None and fields[0] != "Z":
            parent[int(stat.parent.name)] = int(fields[1])
            start[int(stat.parent.name)] = fields[19]
    found: set[int] = set()
    frontier = {pid}
    while frontier:
        frontier = {p for p, pp in parent.items() if pp in frontier} - found
        found |= frontier
    return {p: start[p] for p in found}


def _cmdline(pid: int) -> bytes:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ")
    except OSError:
        return b""


def _left(procs: dict[int, str]) -> list[int]:
    """The processes of ``procs`` still running (zombies count as gone)."""
    return [p for p, start in procs.items()
            if (fields := _stat(p)) is not None and fields[0] != "Z" and fields[19] == start]


def _assert_gone_by(procs: dict[int, str], deadline: float) -> None:
    """Every process of ``procs`` has exited by ``deadline`` (``time.monotonic()``)."""
    while _left(procs) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not _left(procs), [_cmdline(p) for p in _left(procs)]


def _sweep_processes(proc: subprocess.Popen) -> dict[int, str]:
    """The fork server, workers and resource tracker of a running sweep."""
    procs = _descendants(proc.pid)
    assert any(FORK_SERVER in _cmdline(p) for p in procs), [_cmdline(p) for p in procs]
    return procs


def _one_line(proc: subprocess.Popen, code: int, out: Path) -> int:
    """Wait for the interrupted sweep; check its exit code and one stderr line; return K."""
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == code, stderr
    assert "Traceback" not in stderr and stdout == "", stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1, stderr
    match = MESSAGE.match(lines[0])
    assert match, lines[0]
    saved, total, folder = match.groups()
    assert int(total) == RUNS
    assert Path(folder).resolve() == out.resolve()
    assert int(saved) == _rows(out)
    return int(saved)


def test_ctrl_c_saves_finished_runs_prints_one_line_and_the_same_command_resumes(tmp_path):
    sweep, out = _sweep(tmp_path), tmp_path / "res"
    proc = _start(sweep, out)
    _wait_until(proc, lambda: _rows(out) > 0, "a saved row")
    procs = _sweep_processes(proc)
    os.killpg(proc.pid, signal.SIGINT)  # Ctrl-C in a terminal: the whole process group
    saved = _one_line(proc, 130, out)
    assert 0 < saved < RUNS
    _assert_gone_by(procs, time.monotonic() + GONE_WITHIN)
    assert (out / "results.csv").is_file()
    again = subprocess.run(_command(sweep, out), capture_output=True, text=True, timeout=300,
                           cwd=ROOT)
    assert again.returncode == 0, again.stderr
    assert re.search(rf"; ran {RUNS - saved} \(\d+ failed\), {saved} already done ",
                     again.stdout), again.stdout
    assert _rows(out) == RUNS


@pytest.mark.parametrize("signum, code", [(signal.SIGTERM, 143), (signal.SIGINT, 130)],
                         ids=["SIGTERM", "SIGINT"])
def test_signal_to_the_main_process_alone_stops_the_sweep_with_one_line(tmp_path, signum, code):
    sweep, out = _sweep(tmp_path), tmp_path / "res"
    proc = _start(sweep, out)
    _wait_until(proc, lambda: _rows(out) > 0, "a saved row")
    procs = _sweep_processes(proc)
    os.kill(proc.pid, signum)  # e.g. `kill PID`, a batch system; the workers get nothing
    assert 0 < _one_line(proc, code, out) < RUNS
    _assert_gone_by(procs, time.monotonic() + GONE_WITHIN)


def test_ctrl_c_while_the_fork_server_imports_its_preload_prints_no_traceback(tmp_path):
    """The fork server takes a second or more to import its preload, a window in which
    Ctrl-C made it print a KeyboardInterrupt traceback (and, the main process gone, a
    worker it forked then a FileNotFoundError one)."""
    sweep, out = _sweep(tmp_path), tmp_path / "res"
    proc = _start(sweep, out)
    _wait_until(proc, lambda: any(FORK_SERVER in _cmdline(p) for p in _descendants(proc.pid)),
                "the fork server")
    procs = _descendants(proc.pid)
    os.killpg(proc.pid, signal.SIGINT)
    _one_line(proc, 130, out)
    _assert_gone_by(procs, time.monotonic() + GONE_WITHIN)


def test_sigkill_leaves_no_worker_or_fork_server_behind(tmp_path):
    sweep, out = _sweep(tmp_path), tmp_path / "res"
    proc = _start(sweep, out)
    _wait_until(proc, lambda: _rows(out) > 0, "a saved row")
    procs = _sweep_processes(proc)
    assert len(procs) >= 3  # the fork server, its two workers (and the resource tracker)
    proc.kill()
    deadline = time.monotonic() + GONE_WITHIN
    proc.wait(timeout=30)
    _assert_gone_by(procs, deadline)
    proc.communicate(timeout=30)
