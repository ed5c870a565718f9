"""Sweeps run in batches: the same rows as one run at a time, each written when its run ends."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from dfcoa_opt.bench import executors
from dfcoa_opt.bench.executors import BATCH_ROWS, BATCH_RUNS, batches
from dfcoa_opt.bench.runner import DETERMINISTIC_KEYS, execute, execute_batch
from dfcoa_opt.bench.sweep import RunSpec, canonical

ROOT = Path(__file__).resolve().parents[1]
CLUTTER = str(ROOT / "scenarios" / "bench" / "clutter.toml")
LARGE = str(ROOT / "scenarios" / "bench" / "large_100.toml")
STOPS = canonical({"stop_on_collision": True, "stop_on_deadlock": True})


def same(a: dict, b: dict) -> bool:
    """Equal rows but for the solve-time metrics (wall-clock, like ``provenance``)."""
    def clean(row):
        metrics = {k: v for k, v in (row["metrics"] or {}).items()
                   if not k.startswith("filter_time")}
        return [metrics if k == "metrics" else row[k] for k in DETERMINISTIC_KEYS]

    return clean(a) == clean(b)


def test_batches_group_runs_that_differ_only_in_their_seed():
    runs = [RunSpec(CLUTTER, "clutter", c, s, o) for s in range(3)
            for c in ("goto_slot", "lf_vo") for o in ("{}", STOPS)]
    out = batches(runs)
    assert [(b[0].controller, b[0].overrides) for b in out] == [
        ("goto_slot", "{}"), ("goto_slot", STOPS), ("lf_vo", "{}"), ("lf_vo", STOPS)]
    assert all([r.seed for r in b] == [0, 1, 2] for b in out)
    assert sorted(r.key for b in out for r in b) == sorted(r.key for r in runs)


def test_batch_sizes_follow_the_runs_rows_and_workers():
    many = [RunSpec(CLUTTER, "clutter", "goto_slot", s) for s in range(45)]
    assert [len(b) for b in batches(many)] == [BATCH_RUNS, BATCH_RUNS, 5]
    assert [len(b) for b in batches(many[:8], jobs=2)] == [2, 2, 2, 2]  # two each for 2 workers
    big = [RunSpec(LARGE, "large_100", "goto_slot", s, canonical({"team.n": 400}))
           for s in range(12)]
    assert [len(b) for b in batches(big)] == [BATCH_ROWS // 400] * 2 + [2]
    wide = [RunSpec(LARGE, "large_100", "goto_slot", s, canonical({"team.n": 1000}))
            for s in range(3)]
    assert [len(b) for b in batches(wide)] == [2, 1]


def test_batches_start_with_the_most_work():
    """Runs x robots x steps, largest first; equal work keeps the runs' order."""
    short, long_ = canonical({"t_max": 10.0}), canonical({"t_max": 1000.0})
    runs = [RunSpec(CLUTTER, "clutter", c, s, o) for o in (short, long_)
            for c in ("goto_slot", "lf_vo") for s in range(3)]
    runs += [RunSpec(LARGE, "large_100", "goto_slot", s, short) for s in range(2)]
    out = [(b[0].scenario, b[0].controller, b[0].overrides, len(b)) for b in batches(runs)]
    assert out == [("clutter", "goto_slot", long_, 3), ("clutter", "lf_vo", long_, 3),
                   ("large_100", "goto_slot", short, 2),  # 2 x 100 robots x 100 steps
                   ("clutter", "goto_slot", short, 3), ("clutter", "lf_vo", short, 3)]


def test_a_batch_gives_each_runs_own_row_and_a_failing_seed_its_own_failure(tmp_path):
    """Two seeds' clutter fields close the goal: those runs fail alone, the others are rows."""
    path = tmp_path / "closing.toml"
    path.write_text('seed = 4\nt_max = 3.0\n[world]\nsize = [20.0, 10.0]\n'
                    '[world.clutter]\ndensity = 0.15\n[team]\nn = 3\n[formation]\n'
                    'shape = "line"\n[leader]\nstart = [2.0, 5.0]\ngoal = [18.0, 5.0]\n')
    runs = [RunSpec(str(path), "closing", "goto_slot+cbf", s) for s in (0, 1, 2, 3)]
    rows = {o.row["seed"]: o.row for o in execute_batch(runs)}
    alone = {r.seed: execute(r).row for r in runs}
    assert all(same(rows[s], alone[s]) for s in rows) and len(rows) == 4
    failed = [s for s, row in rows.items() if row["status"] == "failed"]
    assert failed == [0, 1] and "formation slot at the goal" in rows[0]["error"]


def test_a_worker_sends_each_row_when_its_run_ends():
    """A batch of a short and a long run: the short run's row arrives while the long one runs."""
    runs = [RunSpec(CLUTTER, "clutter", "lf_vo", s, STOPS) for s in (2, 1)]  # 274, 996 steps
    t0 = time.perf_counter()
    got = []
    for outcome in executors._processes([runs], jobs=1):
        got.append((time.perf_counter() - t0, outcome.row))
    assert [row["seed"] for _, row in got] == [2, 1]
    long_run = got[1][1]["provenance"]["wall_time"]
    assert got[1][0] - got[0][0] > 0.3 * long_run  # not both at the batch's end
    assert all(same(row, execute(r).row) for (_, row), r in zip(got, runs, strict=True))


@pytest.mark.parametrize("n", [1, 3])
def test_serial_sweeps_of_any_batch_size_give_the_same_rows(n, monkeypatch, tmp_path):
    from dfcoa_opt.bench.executors import ExecutorConfig, run_all

    monkeypatch.setattr(executors, "BATCH_RUNS", n)
    runs = [RunSpec(CLUTTER, "clutter", "goto_slot", s, canonical({"t_max": 5.0}))
            for s in range(4)]
    rows = {o.row["key"]: o.row for o in run_all(runs, ExecutorConfig("serial"))}
    assert all(same(rows[r.key], execute(r).row) for r in runs)


def test_a_dask_worker_sends_each_row_when_its_run_ends(monkeypatch):
    """The same batch on a local Dask cluster: rows arrive as runs end, equal to serial ones."""
    from distributed import Client, LocalCluster

    runs = [RunSpec(CLUTTER, "clutter", "lf_vo", s, STOPS) for s in (2, 1)]  # 274, 996 steps
    monkeypatch.setattr(executors, "batches", lambda todo, jobs=1: [list(todo)])  # one batch
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster, Client(cluster) as client:
        client.submit(sum, [1]).result()  # the worker is up
        t0 = time.perf_counter()
        got = [(time.perf_counter() - t0, o.row) for o in executors._dask_stream(client, runs)]
    assert [row["seed"] for _, row in got] == [2, 1]
    assert got[1][0] - got[0][0] > 0.3 * got[1][1]["provenance"]["wall_time"]
    assert all(same(row, execute(r).row) for (_, row), r in zip(got, runs, strict=True))
