"""One MCAP file per run a report's trajectory figures draw (``dfcoa bench --mcap``).

A results folder keeps no LiDAR scans, so each drawn run is simulated again
with :class:`~dfcoa_opt.sim.batch.BatchSimulator` ``record_scans=True`` from
its row (scenario file, seed, overrides, controller) and written with
:func:`~dfcoa_opt.viz.mcap.write_mcap` to ``<results>/mcap/<key>.mcap``.
Recording scans does not change a run, so the new log's digest must be the
row's; a run whose digest differs (the code or the scenario file
changed since it ran) is still written, and named in the returned notes.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from dfcoa_opt.bench.report.trajectories import overlay_rows
from dfcoa_opt.viz.mcap import write_mcap

#: The folder of a results folder that holds the MCAP files.
MCAP_DIR = "mcap"


def drawn_rows(rows: Sequence[Mapping[str, Any]]) -> list[Mapping[str, Any]]:
    """The rows whose runs the report's trajectory figures draw (outside ladders, with a log)."""
    plain = [r for r in rows if r.get("ladder_value") is None]
    return [r for _, chosen in overlay_rows(plain).values() for r in chosen if r.get("log")]


def write_run_mcaps(results_dir: str | Path, rows: Sequence[Mapping[str, Any]]
                    ) -> tuple[list[Path], list[str]]:
    """Write ``<results_dir>/mcap/<key>.mcap`` for every run of :func:`drawn_rows`.

    Args:
        results_dir: The results folder.
        rows: Its rows (:func:`dfcoa_opt.bench.report.document.load_rows`).

    Returns:
        The files written, and one note per run whose digest is not its row's.

    Raises:
        DfcoaError: A scenario cannot be loaded, or ``rosbags`` is missing.
    """
    from dfcoa_opt.scenario.loader import load_scenario
    from dfcoa_opt.sim.batch import BatchSimulator
    from dfcoa_opt.sim.simulator import batch_controllers

    out, notes = [], []
    for row in drawn_rows(rows):
        seed = int(row["seed"])
        sc = load_scenario(row["scenario_file"], seed, row.get("overrides") or None)
        ctrl = batch_controllers(str(row["controller"]), sc, 1)
        sim = BatchSimulator(sc, ctrl, [seed], record_scans=True)
        log = sim.run_all()[0]
        if log.digest() != row.get("digest"):
            notes.append(f"{row['key']}: this run's digest differs from its row's (the code or "
                         "the scenario file changed since it ran)")
        out.append(write_mcap(log, Path(results_dir) / MCAP_DIR / f"{row['key']}.mcap",
                               sim.scenarios[0].world))
    return out, notes
