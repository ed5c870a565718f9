"""The results store: one folder per sweep, one row file per run.

Layout::

    RESULTS/
      manifest.json     sweep name, file, SHA-256, code fingerprint of each controller,
                        the run keys, variants, baseline and ladders
      sweep.toml        copy of the sweep file
      rows/<key>.json   one row per run (see dfcoa_opt.bench.runner)
      logs/<key>.npz    the run's log
      results.csv       the rows of the current sweep, flattened

Every file is written atomically (:mod:`dfcoa_opt.core.atomic`), the log before its
row, so a row file exists only for a run whose log is complete. A sweep killed
at any moment (even by SIGKILL) therefore resumes without losing or
duplicating a row: the rerun skips every run that has a row.

A row counts as done only if it was produced by the same code, the same
scenario file and the same overrides: each row records ``code`` (the
fingerprint of its controller, :func:`~dfcoa_opt.bench.results.fingerprint.run_fingerprint`:
its code
and, for a policy file ``policy:PATH``, the bytes of its spec and weights),
``scenario_sha256`` and ``overrides``; other rows are run again.

The fingerprint is :mod:`dfcoa_opt.bench.results.fingerprint`'s: the sources
a run executes, by the layers of the code, plus the controller's own package.
"""

from __future__ import annotations

import csv
import datetime as _dt
import hashlib
import io
import json
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from dfcoa_opt.bench.results.fingerprint import run_fingerprint
from dfcoa_opt.bench.runner import Outcome
from dfcoa_opt.bench.sweep.specs import RunSpec, Sweep
from dfcoa_opt.core.atomic import atomic_write, remove_partials
from dfcoa_opt.core.errors import DfcoaError

#: Row fields written as CSV columns before the metrics.
CSV_FIELDS = ("key", "scenario", "variant", "controller", "seed", "ladder", "ladder_value",
              "overrides", "status", "error", "digest")


def file_sha256(path: str) -> str:
    """First 16 hex digits of the SHA-256 of a file's bytes (rows record scenario files so)."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]


def display_path(path: str) -> str:
    """``path`` relative to the working folder when inside it (no machine paths in reports)."""
    p = Path(path).resolve()
    try:
        return p.relative_to(Path.cwd().resolve()).as_posix()
    except ValueError:
        return p.as_posix()


class ResultsStore:
    """A results folder.

    Args:
        root: The folder (created if missing). Temporary files left by a
            killed writer are removed on opening.
    """

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)
        self.rows_dir = self.root / "rows"
        self.logs_dir = self.root / "logs"
        for d in (self.root, self.rows_dir, self.logs_dir):
            if d.exists() and not d.is_dir():
                raise DfcoaError(f"{d}: exists and is not a folder")
            d.mkdir(parents=True, exist_ok=True)
            remove_partials(d)

    def row_path(self, key: str) -> Path:
        """Path of a run's row file."""
        return self.rows_dir / f"{key}.json"

    def read_row(self, key: str) -> dict[str, Any] | None:
        """The stored row of ``key``; None if absent or unreadable (it is then rerun)."""
        try:
            return json.loads(self.row_path(key).read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return None

    def is_done(self, run: RunSpec) -> bool:
        """A row exists for ``run`` from this code, this scenario file and these overrides.

        This code: the row's ``code`` is the fingerprint of ``run``'s controller
        (:func:`run_fingerprint`: its code, and a policy file's bytes).
        """
        row = self.read_row(run.key)
        return (row is not None and row.get("code") == run_fingerprint(run.controller)
                and row.get("scenario_sha256") == file_sha256(run.scenario_file)
                and row.get("overrides") == run.overrides_dict)

    def pending(self, runs: Iterable[RunSpec], rerun: bool = False) -> list[RunSpec]:
        """The runs to execute: all with ``rerun``, else those not done."""
        runs = list(runs)
        return runs if rerun else [r for r in runs if not self.is_done(r)]

    def adopt(self, run: RunSpec, others: Sequence[ResultsStore]) -> bool:
        """Take ``run``'s finished result from another store that has it; True if taken.

        A row there counts when it is done for ``run`` by :meth:`is_done`'s test (same
        code, scenario file and overrides), under the same key, controller and seed,
        with status ``ok``: the simulation is then the same, bit for bit. Its log is
        copied, and the row gets ``run``'s identity (variant, ladder) and
        ``provenance.reused_from`` (the other store's folder name).
        """
        for other in others:
            if other.root.resolve() == self.root.resolve() or not other.is_done(run):
                continue
            row = other.read_row(run.key)
            if (row is None or row.get("status") != "ok" or row.get("controller") != run.controller
                    or row.get("seed") != run.seed or not row.get("log")):
                continue
            try:
                log = (other.root / row["log"]).read_bytes()
            except OSError:
                continue
            row.update(key=run.key, scenario=run.scenario, scenario_file=run.scenario_file,
                       overrides=run.overrides_dict, overrides_hash=run.overrides_hash,
                       variant=run.variant_name, ladder=run.ladder,
                       ladder_value=run.ladder_value, log=f"logs/{run.key}.npz")
            row["provenance"] = {**(row.get("provenance") or {}), "reused_from": other.root.name}
            self.write(Outcome(row, log))
            return True
        return False

    def write(self, outcome: Outcome) -> Path:
        """Store one finished run: its log first, then its row (both atomic).

        The row gets ``code``, the fingerprint of its controller (:func:`run_fingerprint`),
        and ``scenario_sha256``.
        """
        row = dict(outcome.row)
        row["code"] = run_fingerprint(row["controller"])
        row["scenario_sha256"] = file_sha256(row["scenario_file"])
        # a row that is not strict JSON raises here, before its log is written
        text = json.dumps(row, indent=1, sort_keys=True, allow_nan=False) + "\n"
        if outcome.npz is not None:
            atomic_write(self.root / row["log"], outcome.npz)
        return atomic_write(self.row_path(row["key"]), text)

    def write_manifest(self, sweep: Sweep) -> None:
        """Record the sweep (file copy, hash, run keys).

        ``code`` maps each controller id of the sweep to its :func:`run_fingerprint`.
        The manifest is made (strict JSON: no NaN or inf) before either file is
        written, so a manifest that cannot be written leaves both as they were.
        :func:`~dfcoa_opt.bench.harness.run_sweep` calls it once a run has finished.
        """
        code = {c: run_fingerprint(c) for c in sorted({r.controller for r in sweep.runs})}
        manifest = {
            "name": sweep.name, "sweep_file": display_path(sweep.source),
            "sweep_sha256": sweep.sha256, "code": code,
            "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
            "keys": [r.key for r in sweep.runs], **sweep.describe(),
        }
        text = json.dumps(manifest, indent=1, allow_nan=False) + "\n"
        atomic_write(self.root / "sweep.toml", sweep.text)
        atomic_write(self.root / "manifest.json", text)

    def manifest(self) -> dict[str, Any]:
        """The manifest (empty dict if there is none)."""
        try:
            return json.loads((self.root / "manifest.json").read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return {}

    def rows(self, keys: Sequence[str] | None = None) -> list[dict[str, Any]]:
        """Rows of ``keys`` (default: the manifest's), in that order; missing ones skipped."""
        keys = self.manifest().get("keys", []) if keys is None else keys
        return [r for r in (self.read_row(k) for k in keys) if r is not None]

    def simulation_cpu(self) -> float:
        """CPU-s the manifest's runs took when simulated (their ``provenance.wall_time``).

        Each worker runs on one thread, so a run's wall time is its CPU time. Runs
        copied from another store (``provenance.reused_from``) cost this store nothing
        and are left out.
        """
        total = 0.0
        for row in self.rows():
            prov = row.get("provenance") or {}
            if not prov.get("reused_from"):
                total += float(prov.get("wall_time") or 0.0)
        return total

    def write_csv(self) -> Path:
        """Write ``results.csv``: the current sweep's rows, metrics flattened."""
        rows = self.rows()
        metric_keys: list[str] = []
        for r in rows:
            metric_keys += [k for k in (r.get("metrics") or {}) if k not in metric_keys]
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow([*CSV_FIELDS, "wall_time", *metric_keys])
        for r in rows:
            m = r.get("metrics") or {}
            base = [json.dumps(r["overrides"], sort_keys=True) if f == "overrides"
                    else r.get(f) for f in CSV_FIELDS]
            w.writerow(["" if v is None else v for v in
                        [*base, r.get("provenance", {}).get("wall_time"),
                         *(m.get(k) for k in metric_keys)]])
        return atomic_write(self.root / "results.csv", buf.getvalue())
