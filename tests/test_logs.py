"""Compact logs: what the result cache keeps of a run no figure draws."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dfcoa_opt.bench.logs import (
    LogCompacted,
    compact_bytes,
    compact_store,
    load_compact,
    read_log,
    tracing,
)
from dfcoa_opt.bench.runner import execute
from dfcoa_opt.bench.store import ResultsStore
from dfcoa_opt.bench.sweep import RunSpec
from dfcoa_opt.errors import DfcoaError
from dfcoa_opt.sim.log import RunLog, is_compact

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


def test_the_store_keeps_what_was_read_and_compacts_the_rest(store: ResultsStore) -> None:
    rows = {k: store.read_row(k) for k in ("crossing__goto_slot+cbf__s0",
                                           "crossing__goto_slot+cbf__s1")}
    kept = store.root / rows["crossing__goto_slot+cbf__s0"]["log"]
    before = kept.read_bytes()
    with tracing() as keys:
        read_log(store.root, rows["crossing__goto_slot+cbf__s0"])
    assert keys == {"crossing__goto_slot+cbf__s0"}
    count, saved = compact_store(store.root, keys)
    assert count == 1 and saved > 0
    assert kept.read_bytes() == before  # the drawn log is untouched
    with pytest.raises(LogCompacted, match=r"the log of crossing__goto_slot\+cbf__s1 was "
                                           r"compacted"):
        read_log(store.root, rows["crossing__goto_slot+cbf__s1"])
    assert compact_store(store.root, keys) == (0, 0)  # nothing left to compact
    assert store.read_row("crossing__goto_slot+cbf__s1") == rows["crossing__goto_slot+cbf__s1"]
