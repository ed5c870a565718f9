"""`dfcoa bench` as a real process: Ctrl-C, SIGTERM and SIGKILL stop it cleanly."""

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
MESSAGE = re.compile(r"^dfcoa: interrupted: (\d+) of (\d+) runs saved in (.+); run the same "
                     r"command to resume$")


def _sweep(tmp_path: Path, seeds: int = 40) -> Path:
    path = tmp_path / "long.toml"
    corridor = (ROOT / "scenarios" / "bench" / "corridor.toml").as_posix()
    path.write_text(f'scenarios = ["{corridor}"]\ncontrollers = ["orca_nav", "dfcoa"]\n'
                    f"seeds = {seeds}\n")
    return path


def _start(sweep: Path, out: Path) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "dfcoa_opt", "bench", str(sweep), "--out",
                             str(out), "--jobs", "2", "--no-progress"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, cwd=ROOT)


def _wait_for_rows(proc: subprocess.Popen, out: Path, timeout: float = 120.0) -> None:
    """Until the sweep has saved a row (it is then past start-up and mid-sweep)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if list((out / "rows").glob("*.json")):
            return
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.05)
    raise AssertionError("no row was saved")


def _descendants(pid: int) -> set[int]:
    """Every process whose parent chain leads to ``pid`` (from /proc)."""
    parent: dict[int, int] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        parent[int(stat.parent.name)] = int(fields[1])
    out: set[int] = set()
    frontier = {pid}
    while frontier:
        frontier = {p for p, pp in parent.items() if pp in frontier} - out
        out |= frontier
    return out


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


@pytest.mark.parametrize("signum, to_group, code", [
    (signal.SIGINT, True, 130),     # Ctrl-C in a terminal: the whole process group
    (signal.SIGINT, False, 130),    # SIGINT to the main process alone
    (signal.SIGTERM, False, 143),
])
def test_interrupt_saves_finished_runs_prints_one_line_and_resumes(tmp_path, signum, to_group,
                                                                   code):
    sweep, out = _sweep(tmp_path), tmp_path / "res"
    proc = _start(sweep, out)
    _wait_for_rows(proc, out)
    if to_group:
        os.killpg(proc.pid, signum)
    else:
        os.kill(proc.pid, signum)
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == code, stderr
    assert "Traceback" not in stderr and stdout == ""
    lines = stderr.strip().splitlines()
    assert len(lines) == 1, stderr
    saved, total, folder = MESSAGE.match(lines[0]).groups()
    assert int(total) == 80 and 0 < int(saved) < 80
    assert Path(folder).resolve() == out.resolve()
    assert len(list((out / "rows").glob("*.json"))) == int(saved)
    # the same command resumes: only the runs without a row run
    again = subprocess.run([sys.executable, "-m", "dfcoa_opt", "bench", str(sweep), "--out",
                            str(out), "--jobs", "2", "--no-progress"], capture_output=True,
                           text=True, timeout=300, cwd=ROOT)
    assert again.returncode == 0, again.stderr
    assert f"ran {80 - int(saved)} (0 failed), {saved} already done" in again.stdout


def test_sigkill_leaves_no_worker_or_fork_server_behind(tmp_path):
    sweep, out = _sweep(tmp_path), tmp_path / "res"
    proc = _start(sweep, out)
    _wait_for_rows(proc, out)
    children = _descendants(proc.pid)
    assert len(children) >= 3  # fork server, its two workers (and the resource tracker)
    proc.kill()
    proc.communicate(timeout=30)
    deadline = time.monotonic() + 5.0
    while time.monotonic() < deadline and any(_alive(p) for p in children):
        time.sleep(0.1)
    left = [p for p in children if _alive(p)]
    assert not left, [Path(f"/proc/{p}/cmdline").read_bytes() for p in left]
