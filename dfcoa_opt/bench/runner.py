"""Execute one run of a sweep and turn it into a result row.

:func:`execute` is what every executor ships to its workers: a pure function
of the :class:`~dfcoa_opt.bench.sweep.RunSpec` (plus the code), so serial,
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
  :mod:`dfcoa_opt.outcome`) and ``reached`` (the goal condition, whatever the
  contacts);
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
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from dfcoa_opt import dispatch, environment
from dfcoa_opt.bench.sweep import RunSpec, load_run_scenario
from dfcoa_opt.errors import DfcoaError

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


def execute(run: RunSpec) -> Outcome:
    """Simulate one run and summarise it; never raises for a failing run.

    Args:
        run: The run.

    Returns:
        The row (see the module docstring) and the log's ``.npz`` bytes.
    """
    from dfcoa_opt import metrics
    from dfcoa_opt.sim.simulator import run_scenario

    t0 = time.perf_counter()
    row: dict[str, Any] = {
        "key": run.key, "scenario": run.scenario, "scenario_file": run.scenario_file,
        "controller": run.controller, "seed": run.seed, "overrides": run.overrides_dict,
        "overrides_hash": run.overrides_hash, "variant": run.variant_name,
        "ladder": run.ladder, "ladder_value": run.ladder_value, "status": "failed", "error": None,
        "metrics": None, "digest": None, "log": None,
    }
    prov: dict[str, Any] = {}
    npz = None
    try:
        scenario = load_run_scenario(run)
        log = run_scenario(scenario, run.controller)
        row["metrics"] = jsonable(metrics.summary(log, scenario.spec.metrics))
        row["digest"] = log.digest()
        row["log"] = f"logs/{run.key}.npz"
        row["status"] = "ok"
        npz = log.to_bytes()
    except Exception as exc:  # noqa: BLE001 - a failing run is data, the sweep goes on
        row["error"] = _one_line(exc)
        if not isinstance(exc, DfcoaError):
            prov["traceback"] = traceback.format_exc()
    prov.update(wall_time=time.perf_counter() - t0, host=socket.gethostname(),
                simd=environment.numpy_simd(), simd_cap=dispatch.describe(), pid=os.getpid(),
                finished=_dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"))
    row["provenance"] = prov
    return Outcome(row, npz)
