"""Published runs: a recipe's per-run results, committed as a compact CSV beside its tables.

A recipe that ranks methods (``comparison``, ``heldout``) writes ``runs.csv``
into its output folder from the rows of its sweep, then computes its tables
from that file, so the committed file is exactly what the tables say. A row
keeps its identity (variant, controller, scenario, seed, key), its status,
its log digest, the fingerprint of the code that made it, and the metrics
the recipe's tables read. ``dfcoa compare`` reads the file to set a new
controller among the published methods without simulating them again, and
re-simulates a sample to check that the published digests still reproduce
(:mod:`dfcoa_opt.bench.compare`).

Format: a first line ``# dfcoa-runs/1 <key>=<value> ...`` (the recipe and
the git commit of the code that wrote it), then a CSV header and one line a
run. Values that are not plain text (numbers, booleans, null, NaN, tables)
are JSON, so every number reads back to the same bits.
"""

from __future__ import annotations

import csv
import io
import json
import subprocess
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from dfcoa_opt.bench.results.store import display_path
from dfcoa_opt.core.atomic import atomic_write
from dfcoa_opt.core.errors import DfcoaError

#: The file a recipe writes into its output folder.
RUNS_FILE = "runs.csv"
#: The first word of the file's first line (the format and its version).
FORMAT = "dfcoa-runs/1"
#: The fields of a row kept as they are (after ``seed``, JSON-encoded).
FIELDS = ("key", "variant", "controller", "scenario", "scenario_file", "seed", "ladder",
          "ladder_value", "status", "error", "digest", "code", "log", "overrides")
#: What every recipe's tables read of a run's outcome.
OUTCOME_KEYS = ("outcome", "success", "reached", "first_contact_time", "deadlock_time",
                "time_to_goal", "collisions")
_TEXT = ("key", "variant", "controller", "scenario", "scenario_file", "ladder", "status",
         "digest", "code", "log")


#: What a run's numbers depend on in the checkout: a change here marks the commit modified.
CODE_PATHS = ("dfcoa_opt", "comparisons", "scenarios", "pyproject.toml")


def source_commit(root: Path | str = ".") -> str:
    """The checkout's commit (12 hex digits), ``-modified`` when its code differs; else ``unknown``.

    Only :data:`CODE_PATHS` count: the figures a run of ``make figures`` is
    rewriting do not make the code modified.
    """
    def git(*args: str) -> str | None:
        try:
            out = subprocess.run(["git", *args], cwd=root, capture_output=True, text=True,
                                 timeout=30)
        except (OSError, subprocess.SubprocessError):
            return None
        return out.stdout.strip() if out.returncode == 0 else None

    head = git("rev-parse", "--short=12", "HEAD")
    if not head:
        return "unknown"
    changed = git("status", "--porcelain", "--", *CODE_PATHS)
    return head + ("-modified" if changed else "")


def _cell(value: Any) -> str:
    """A value as its CSV cell: JSON, which keeps a float's bits and NaN and inf."""
    return json.dumps(value, sort_keys=True, separators=(",", ":"))


def write_runs(rows: Sequence[Mapping[str, Any]], path: Path, metrics: Sequence[str],
               recipe: str) -> Path:
    """Write the published runs of a recipe.

    Args:
        rows: The sweep's rows (:meth:`dfcoa_opt.bench.results.store.ResultsStore.rows`).
        path: The ``runs.csv`` to write (atomically).
        metrics: The summary keys the recipe's tables read (besides :data:`OUTCOME_KEYS`).
        recipe: The recipe's name, for the first line.

    Returns:
        ``path``.
    """
    keys = list(dict.fromkeys([*OUTCOME_KEYS, *metrics]))
    buf = io.StringIO()
    buf.write(f"# {FORMAT} recipe={recipe} commit={source_commit()}\n")
    w = csv.writer(buf, lineterminator="\n")
    w.writerow([*FIELDS, *(f"m:{k}" for k in keys)])
    for r in rows:  # in the given order: the tables list variants in the order of their rows
        m = r.get("metrics") or {}
        row = dict(r)
        if row.get("scenario_file"):
            row["scenario_file"] = display_path(str(row["scenario_file"]))
        w.writerow([*(row.get(f) if f in _TEXT and row.get(f) is not None else _cell(row.get(f))
                      for f in FIELDS),
                    *(_cell(m.get(k)) if r.get("metrics") is not None else "" for k in keys)])
    return atomic_write(path, buf.getvalue())


def read_runs(path: Path) -> tuple[list[dict[str, Any]], dict[str, str]]:
    """The rows of a published runs file, and its first line's ``key=value`` pairs.

    A row is a dict like the results store's (``metrics`` holds the columns
    ``m:<key>``; a failed run's ``metrics`` is None).

    Raises:
        DfcoaError: A missing file, another format, or a malformed line (naming the
            file and the line).
    """
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise DfcoaError(f"{path}: cannot read the published runs ({exc.strerror or exc})"
                         ) from None
    first, _, body = text.partition("\n")
    words = first.lstrip("# ").split()
    if not words or words[0] != FORMAT:
        raise DfcoaError(f"{path}: line 1: not a published runs file ({FORMAT})")
    meta = dict(w.split("=", 1) for w in words[1:] if "=" in w)
    reader = csv.reader(io.StringIO(body))
    header = next(reader, None)
    if header is None or list(header[:len(FIELDS)]) != list(FIELDS):
        raise DfcoaError(f"{path}: line 2: the header is not {', '.join(FIELDS)}, ...")
    keys = [h[2:] for h in header[len(FIELDS):]]
    rows = []
    for line, cells in enumerate(reader, start=3):
        if len(cells) != len(header):
            raise DfcoaError(f"{path}: line {line}: {len(cells)} cells, expected {len(header)}")
        try:
            row: dict[str, Any] = {f: (c if f in _TEXT and c != "null" else json.loads(c))
                                   for f, c in zip(FIELDS, cells, strict=False)}
            vals = cells[len(FIELDS):]
            row["metrics"] = (None if all(v == "" for v in vals)
                              else {k: json.loads(v) for k, v in zip(keys, vals, strict=True)})
        except json.JSONDecodeError as exc:
            raise DfcoaError(f"{path}: line {line}: not a value ({exc.msg})") from None
        for f in ("error", "log"):
            row[f] = row[f] or None
        rows.append(row)
    return rows, meta


def published_rows(rows: Sequence[Mapping[str, Any]], path: Path, metrics: Sequence[str],
                   recipe: str) -> list[dict[str, Any]]:
    """Write the published runs, then read them back: what the recipe's tables are made from."""
    return read_runs(write_runs(rows, path, metrics, recipe))[0]
