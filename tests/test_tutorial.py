"""docs/tutorial.ipynb runs headless without an error, its stored outputs (what the site
shows) are current, and the facade's types check."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import nbformat

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOK = ROOT / "docs" / "tutorial.ipynb"
_spec = importlib.util.spec_from_file_location("run_tutorial", ROOT / "docs" / "run_tutorial.py")
run_tutorial = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(run_tutorial)


def test_the_tutorial_notebook_executes_to_its_stored_outputs():
    stored = nbformat.read(NOTEBOOK, as_version=4)
    nb = run_tutorial.execute(NOTEBOOK, timeout=120)  # raises CellExecutionError, naming the cell
    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs]
    text = "\n".join(str(o.get("text", "")) + str(o.get("data", {}).get("text/plain", ""))
                     for o in outputs)
    assert "'outcome': 'success'" in text  # dfcoa on S1
    assert "capped_goto" in text and "| variant |" in text  # the comparison and its report
    assert "my_policy/learned.json" in text  # the trained policy in the paired comparison
    assert any("image/png" in o.get("data", {}) for o in outputs)  # the plot and the ladder
    # the site shows the stored outputs: every code cell has them, and they are today's
    code = [c for c in stored.cells if c.cell_type == "code"]
    assert all(c.outputs and c.execution_count for c in code), \
        "docs/tutorial.ipynb has cells without outputs: run .venv/bin/python docs/run_tutorial.py"
    fresh, kept = run_tutorial.comparable(nb), run_tutorial.comparable(stored)
    stale = [i for i, (a, b) in enumerate(zip(fresh, kept, strict=True)) if a != b]
    assert not stale, (f"the stored outputs of code cells {stale} differ from a fresh run: "
                       "run .venv/bin/python docs/run_tutorial.py")


def test_the_facade_and_the_controller_interface_type_check():
    proc = subprocess.run(
        [sys.executable, "-m", "mypy", "--follow-imports=silent", "--ignore-missing-imports",
         "--no-incremental", "dfcoa_opt/__init__.py", "dfcoa_opt/api.py",
         "dfcoa_opt/control/base.py"], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-2000:]
