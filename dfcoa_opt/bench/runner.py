"""Execute one run of a sweep and turn it into a result row.

:func:`execute` is what every executor ships to its workers: a pure function
of the :class:`~dfcoa_opt.bench.sweep.expand.RunSpec` (plus the code), so serial,
process and Dask executors produce the same row. A run that fails -- the
scenario does not load for this seed, the controller raises or returns
NaN/inf, a solver error escapes the controller's policy -- becomes a row with
``status = "failed"`` and a one-line ``error``; the sweep goes on.

Row fields (JSON):

- ``key``, ``scenario``, ``scenario_file``, ``controller``, ``seed``,
  ``overrides`` (dotted key -> value), ``overrides_hash``;
- ``variant`` (the readable name of the method configuration), ``ladder`` and
  ``ladder_value`` (the difficulty ladder's label and rung; ``""``/null outside
  a ladder);
- ``status`` (``ok`` | ``failed``), ``error`` (one line or null);
- ``metrics``: :func:`dfcoa_opt.metrics.summary` with NaN/inf as null; among
  them ``outcome`` (success, collision, deadlock or timeout,
  :mod:`dfcoa_opt.metrics.outcome`) and ``reached`` (the goal condition, whatever the
  contacts); and the world's difficulty along the leader's path, the
  ``world_*`` keys of :func:`dfcoa_opt.metrics.world.world_difficulty`;
- ``digest``: SHA-256 over the log arrays (bit-identical runs <=> equal);
- ``log``: the ``.npz`` path relative to the results folder, or null;
- ``provenance``: wall time, finish time, host, numpy's SIMD level, pid,
  and a traceback for unexpected exceptions. Only this field may differ
  between two executions of the same run (on another machine the digest can
  differ too: docs/benchmarking.md, "Across machines").
"""

from __future__ import annotations

import datetime as _dt
import math
import os
import socket
import time
import traceback
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from dfcoa_opt.bench.sweep.specs import RunSpec, load_run_scenario
from dfcoa_opt.core.errors import DfcoaError
from dfcoa_opt.core.runtime import dispatch

if TYPE_CHECKING:
    from dfcoa_opt.scenario.scenario import Scenario
    from dfcoa_opt.sim.log import RunLog

#: Keys of a row that must be identical whichever executor ran it.
DETERMINISTIC_KEYS = ("key", "scenario", "scenario_file", "controller", "seed", "overrides",
                      "overrides_hash", "variant", "ladder", "ladder_value", "status", "error",
                      "metrics", "digest", "log")


@dataclass(frozen=True)
class Outcome:
    """What a worker sends back: the row and the log file's bytes (None if failed)."""

    row: dict[str, Any]
    npz: bytes | None


def is_success(row: Mapping[str, Any]) -> bool:
    """Whether a row's run is a success (collision-free arrival); a failed run is not."""
    return row.get("status") == "ok" and (row.get("metrics") or {}).get("outcome") == "success"


def jsonable(x: Any) -> Any:
    """Floats JSON cannot hold (NaN, inf) become ``None``, recursively."""
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {k: jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    return x


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text if isinstance(exc, DfcoaError) else f"{type(exc).__name__}: {text}"


def _row(run: RunSpec) -> dict[str, Any]:
    """A row of ``run`` before it ran: its identity, ``status = "failed"``."""
    return {
        "key": run.key, "scenario": run.scenario, "scenario_file": run.scenario_file,
        "controller": run.controller, "seed": run.seed, "overrides": run.overrides_dict,
        "overrides_hash": run.overrides_hash, "variant": run.variant_name,
        "ladder": run.ladder, "ladder_value": run.ladder_value, "status": "failed", "error": None,
        "metrics": None, "digest": None, "log": None,
    }


def _outcome(run: RunSpec, log: RunLog, scenario: Scenario, wall: float) -> Outcome:
    """The row of a run that ran to its end (metrics, digest, log bytes)."""
    from dfcoa_opt import metrics
    from dfcoa_opt.metrics.world import world_difficulty

    t0 = time.perf_counter()
    row = _row(run)
    row["metrics"] = jsonable({**metrics.summary(log, scenario.spec.metrics),
                               **world_difficulty(scenario)})
    row["digest"] = log.digest()
    row["log"] = f"logs/{run.key}.npz"
    row["status"] = "ok"
    npz = log.to_bytes()
    row["provenance"] = _provenance(wall + time.perf_counter() - t0)
    return Outcome(row, npz)


def _provenance(wall: float) -> dict[str, Any]:
    return dict(wall_time=wall, host=socket.gethostname(), simd=dispatch.numpy_simd(),
                simd_cap=dispatch.describe(), pid=os.getpid(),
                finished=_dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"))


def execute(run: RunSpec) -> Outcome:
    """Simulate one run and summarise it; never raises for a failing run.

    Args:
        run: The run.

    Returns:
        The row (see the module docstring) and the log's ``.npz`` bytes.
    """
    from dfcoa_opt.sim.simulator import run_scenario

    t0 = time.perf_counter()
    try:
        scenario = load_run_scenario(run)
        log = run_scenario(scenario, run.controller)
        return _outcome(run, log, scenario, time.perf_counter() - t0)
    except Exception as exc:  # noqa: BLE001 - a failing run is data, the sweep goes on
        row = _row(run)
        row["error"] = _one_line(exc)
        prov = {} if isinstance(exc, DfcoaError) else {"traceback": traceback.format_exc()}
        row["provenance"] = {**prov, **_provenance(time.perf_counter() - t0)}
        return Outcome(row, None)


def execute_batch(runs: Sequence[RunSpec]) -> Iterator[Outcome]:
    """Simulate runs that differ only in their seed as one batch; yields each row as its run ends.

    Each row is the row :func:`execute` gives for that run (the batch keeps the
    bits, :class:`~dfcoa_opt.sim.batch.BatchSimulator`), and its wall time is
    the run's share of the batch. When the batch fails (a scenario that does
    not load for one seed, a controller that raises), the runs it has not
    finished are executed one by one, so each failure is the row of its own
    run, as :func:`execute` writes it.

    Args:
        runs: Runs with the same scenario file, overrides and controller.
    """
    from dfcoa_opt.sim.batch import BatchSimulator
    from dfcoa_opt.sim.simulator import batch_controllers

    if len(runs) == 1:
        yield execute(runs[0])
        return
    done: set[int] = set()
    try:
        t0 = time.perf_counter()
        scenario = load_run_scenario(runs[0])
        sim = BatchSimulator(scenario, batch_controllers(runs[0].controller, scenario, len(runs)),
                             [r.seed for r in runs])
        setup = (time.perf_counter() - t0) / len(runs)
        for e, log in sim.run_iter():
            done.add(e)
            yield _outcome(runs[e], log, sim.scenarios[e], setup + log.meta["wall_time"])
    except Exception:  # noqa: BLE001 - attributed run by run below
        for e, run in enumerate(runs):
            if e not in done:
                yield execute(run)
