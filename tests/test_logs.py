"""Compact logs: what the result cache keeps of a run no figure draws."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from dfcoa_opt.bench.figures import restore_logs
from dfcoa_opt.bench.results.logs import (
    LogCompacted,
    compact_bytes,
    compact_store,
    load_compact,
    prune_log,
    read_log,
    tracing,
)
from dfcoa_opt.bench.results.store import ResultsStore
from dfcoa_opt.bench.runner import execute
from dfcoa_opt.bench.sweep import RunSpec
from dfcoa_opt.core.errors import DfcoaError
from dfcoa_opt.sim.log import RunLog, is_compact, is_pruned

CROSSING = Path(__file__).resolve().parents[1] / "scenarios" / "bench" / "crossing.toml"


@pytest.fixture(scope="module")
def store(tmp_path_factory) -> ResultsStore:
    s = ResultsStore(tmp_path_factory.mktemp("store"))
    for seed in (0, 1):
        s.write(execute(RunSpec(str(CROSSING), "crossing", "goto_slot+cbf", seed,
                                '{"t_max":12.0}')))
    return s


def test_compact_log_keeps_the_trajectories_to_a_millimetre(store: ResultsStore) -> None:
    row = store.read_row("crossing__goto_slot+cbf__s0")
    full = RunLog.load(store.root / row["log"])
    data = compact_bytes(full)
    assert len(data) < 0.1 * (store.root / row["log"]).stat().st_size
    path = store.root / "c.npz"
    path.write_bytes(data)
    c = load_compact(path)
    assert np.max(np.abs(c.pose[..., :2] - full.pose[..., :2])) <= 0.5e-3 + 1e-12
    assert np.max(np.abs(c.pose[..., 2] - full.pose[..., 2])) <= 0.5e-3 + 1e-12
    assert np.max(np.abs(c.leader - full.leader[:, :3])) <= 0.5e-3 + 1e-12
    assert np.max(np.abs(c.dyn_pos - full.dyn_pos)) <= 0.5e-3 + 1e-12
    assert np.allclose(c.t, full.t) and c.meta == full.meta
    assert np.array_equal(c.contacts["events"], full.collision_events)
    assert is_compact(path) and not is_compact(store.root / row["log"])
    with pytest.raises(DfcoaError, match=r"c\.npz: a compact log") as e:
        RunLog.load(path)
    assert "\n" not in str(e.value)


def test_a_log_read_whole_stays_whole(tmp_path: Path, store: ResultsStore) -> None:
    row = dict(store.read_row("crossing__goto_slot+cbf__s0"))
    src = store.root / row["log"]
    (tmp_path / "logs").mkdir()
    (tmp_path / "logs" / src.name).write_bytes(src.read_bytes())
    with tracing() as reads:
        read_log(tmp_path, row).digest()  # reads every field
    assert compact_store(tmp_path, reads) == (0, 0, 0)
    assert (tmp_path / "logs" / src.name).read_bytes() == src.read_bytes()


def test_the_store_prunes_what_was_read_and_compacts_the_rest(store: ResultsStore) -> None:
    rows = {k: store.read_row(k) for k in ("crossing__goto_slot+cbf__s0",
                                           "crossing__goto_slot+cbf__s1")}
    kept = store.root / rows["crossing__goto_slot+cbf__s0"]["log"]
    full = RunLog.load(kept)
    size = kept.stat().st_size
    with tracing() as reads:
        log = read_log(store.root, rows["crossing__goto_slot+cbf__s0"])
        assert log.n_robots == full.n_robots and log.t[-1] == full.t[-1]
    assert reads == {"crossing__goto_slot+cbf__s0": {"pose", "t"}}
    compacted, pruned, saved = compact_store(store.root, reads)
    assert (compacted, pruned) == (1, 1) and saved > 0
    assert is_pruned(kept) and not is_compact(kept) and kept.stat().st_size < 0.5 * size
    again = read_log(store.root, rows["crossing__goto_slot+cbf__s0"])
    for name in ("pose", "t"):  # the fields read, bit for bit
        assert getattr(again, name).tobytes() == getattr(full, name).tobytes()
    assert again.meta == full.meta
    with pytest.raises(LogCompacted, match=r"the log of crossing__goto_slot\+cbf__s0 was pruned "
                                           r"to the fields figures read \(not 'twist'\)"):
        _ = again.twist
    with pytest.raises(DfcoaError, match=r"a pruned log \(only the fields figures read: pose, t\)"):
        RunLog.load(kept)
    with pytest.raises(LogCompacted, match=r"the log of crossing__goto_slot\+cbf__s1 was "
                                           r"compacted"):
        read_log(store.root, rows["crossing__goto_slot+cbf__s1"])
    assert compact_store(store.root, reads) == (0, 0, 0)  # nothing left to shrink
    assert prune_log(kept, {"pose", "t", "twist"}) == 0  # a pruned log is never pruned again
    assert store.read_row("crossing__goto_slot+cbf__s1") == rows["crossing__goto_slot+cbf__s1"]
    assert restore_logs(store.root) == 2  # both runs are simulated again for a redo
    assert not list((store.root / "rows").glob("*.json"))


def test_a_pruned_log_keeps_pose_est_that_the_full_log_left_out(tmp_path: Path) -> None:
    s = ResultsStore(tmp_path)
    s.write(execute(RunSpec(str(CROSSING), "crossing", "goto_slot", 0, '{"t_max":3.0}')))
    row = s.read_row("crossing__goto_slot__s0")
    full = RunLog.load(tmp_path / row["log"])
    assert prune_log(tmp_path / row["log"], {"pose_est", "t"}) > 0
    log = read_log(tmp_path, row)
    assert log.pose_est.tobytes() == full.pose_est.tobytes() == full.pose.tobytes()
    with pytest.raises(LogCompacted, match=r"not 'pose'"):
        _ = log.pose
    before = (tmp_path / row["log"]).read_bytes()
    assert compact_store(tmp_path, {}) == (0, 0, 0)  # no trajectories to compact: left as is
    assert (tmp_path / row["log"]).read_bytes() == before


def test_worker_processes_shrink_a_store_to_the_same_bytes(tmp_path: Path) -> None:
    from concurrent.futures import ProcessPoolExecutor

    s = ResultsStore(tmp_path / "a")
    for seed in range(4):
        s.write(execute(RunSpec(str(CROSSING), "crossing", "goto_slot", seed, '{"t_max":3.0}')))
    b = tmp_path / "b"
    (b / "logs").mkdir(parents=True)
    for p in (s.root / "logs").glob("*.npz"):
        (b / "logs" / p.name).write_bytes(p.read_bytes())
    reads = {"crossing__goto_slot__s1": {"pose", "t"}, "crossing__goto_slot__s2": {"twist"}}
    with ProcessPoolExecutor(2) as pool:
        assert compact_store(b, reads, pool) == compact_store(s.root, reads)
    names = sorted(p.name for p in (s.root / "logs").glob("*.npz"))
    assert len(names) == 4
    assert [(b / "logs" / n).read_bytes() for n in names] == [
        (s.root / "logs" / n).read_bytes() for n in names]
    assert (b / "logs_read.json").read_bytes() == (s.root / "logs_read.json").read_bytes()


def test_a_compact_log_of_format_1_still_reads(tmp_path: Path) -> None:
    """Format /1 kept meta as a numpy string; /2 as UTF-8 bytes (a quarter of the size)."""
    import zipfile

    import dfcoa_opt

    full = dfcoa_opt.run(dfcoa_opt.load(CROSSING, overrides={"t_max": 2.0}), "goto_slot").log
    new = tmp_path / "new.npz"
    new.write_bytes(compact_bytes(full))
    with np.load(new, allow_pickle=False) as z:
        members = {k: z[k] for k in z.files}
    assert members["meta"].dtype == np.uint8
    members["meta"] = np.array(members["meta"].tobytes().decode())
    members["format"] = np.array("dfcoa-compact-log/1")
    old = tmp_path / "old.npz"
    with zipfile.ZipFile(old, "w") as zf:
        for name, arr in members.items():
            with zf.open(f"{name}.npy", "w") as f:
                np.lib.format.write_array(f, arr, allow_pickle=False)
    text = json.dumps(full.meta, default=str)  # (NaN != NaN: compared as JSON)
    assert json.dumps(load_compact(old).meta) == json.dumps(load_compact(new).meta) == text
