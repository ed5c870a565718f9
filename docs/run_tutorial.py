"""Execute docs/tutorial.ipynb and keep its outputs in the file, for the site to show.

The site renders the notebook with its stored outputs (mkdocs-jupyter, ``execute: false``):
executing it in every ``make docs`` would also execute it in every ``make test`` (which
builds the site), a second time beside ``tests/test_tutorial.py``. That test executes the
notebook once and checks both that it runs and that the stored outputs are the current
ones, so the outputs cannot go stale. After changing the notebook, or code whose output it
shows, store the new outputs with::

    .venv/bin/python docs/run_tutorial.py
"""

from __future__ import annotations

import os
import re
import sys
from pathlib import Path
from typing import Any

import nbclient
import nbformat

NOTEBOOK = Path(__file__).resolve().parent / "tutorial.ipynb"
# the notebook's results folder, a new temporary folder in each run
_TEMP_DIR = re.compile(r"\S*dfcoa_tutorial_[A-Za-z0-9_]+")
_ADDRESS = re.compile(r"\b0x[0-9a-f]{6,}\b")  # an object's address in its repr
_SECONDS = re.compile(r"\(\d+ s\)")  # a training round's wall time


def execute(path: Path = NOTEBOOK, timeout: int = 300) -> nbformat.NotebookNode:
    """Run every cell of a notebook in a fresh kernel, as a reader would.

    Args:
        path: The notebook.
        timeout: Seconds allowed for one cell.

    The kernel runs without ``MPLBACKEND`` (``make test`` sets Agg), so that figures show
    inline as they do in Jupyter.

    Returns:
        The notebook with its new outputs, less the standard-error streams (warnings and
        progress bars, which depend on the terminal and the clock).

    Raises:
        nbclient.exceptions.CellExecutionError: A cell raised; the message names it.
    """
    nb = nbformat.read(path, as_version=4)
    client = nbclient.NotebookClient(nb, timeout=timeout, kernel_name="python3",
                                     record_timing=False,
                                     resources={"metadata": {"path": str(path.parent)}})
    client.execute(env={k: v for k, v in os.environ.items() if k != "MPLBACKEND"})
    for cell in nb.cells:
        if cell.cell_type == "code":
            cell.outputs = [o for o in cell.outputs
                            if not (o.output_type == "stream" and o.name == "stderr")]
    return nb


def comparable(nb: nbformat.NotebookNode) -> list[list[dict[str, Any]]]:
    """The outputs of each code cell in a form that two runs can be compared in.

    Text is kept whole (a cell's printed lines as one text, however the kernel split
    them), with the temporary results folder replaced by ``<tmp>``, object addresses by
    ``0x`` and a training round's seconds by ``(s)``; an image counts only by its type (its
    bytes depend on the Matplotlib build).

    Args:
        nb: An executed notebook.

    Returns:
        One list per code cell, one dict per output.
    """
    cells = []
    for cell in nb.cells:
        if cell.cell_type != "code":
            continue
        outs = []
        for out in cell.outputs:
            if out.output_type == "stream" and out.name == "stderr":
                continue
            item: dict[str, Any] = {"type": out.output_type}
            if out.output_type == "stream":
                if outs and outs[-1]["type"] == "stream":
                    outs[-1]["text"] += _plain(out.text)
                    continue
                item["text"] = _plain(out.text)
            elif out.output_type in ("execute_result", "display_data"):
                data = out.get("data", {})
                item["text/plain"] = _plain(data.get("text/plain", ""))
                item["images"] = sorted(k for k in data if k.startswith("image/"))
            outs.append(item)
        cells.append(outs)
    return cells


def _plain(text: str) -> str:
    return _SECONDS.sub("(s)", _ADDRESS.sub("0x", _TEMP_DIR.sub("<tmp>", text)))


def main() -> int:
    """Execute the tutorial and write it back with its outputs."""
    nb = execute()
    nbformat.write(nb, NOTEBOOK)
    print(f"wrote {NOTEBOOK} with the outputs of {len(comparable(nb))} code cells")
    return 0


if __name__ == "__main__":
    sys.exit(main())
