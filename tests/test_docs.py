"""The documentation site builds with --strict: no broken link, page or docstring."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_the_site_builds_strict(tmp_path):
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir",
                           str(tmp_path / "site")], cwd=ROOT, capture_output=True, text=True,
                          timeout=600, env=env)
    assert proc.returncode == 0, proc.stderr[-3000:]
    site = tmp_path / "site"
    # the generated key reference, the rendered tutorial and the API reference are pages
    assert "comms.latency" in (site / "scenario-keys" / "index.html").read_text()
    assert "capped_goto" in (site / "tutorial" / "index.html").read_text()
    api = (site / "api" / "controllers" / "index.html").read_text()
    assert "Nmpc" in api and "VFHParams" in api
    params = (site / "controller-params" / "index.html").read_text()
    assert "controllers.dfcoa.compensate_tracking_offset" in params
    assert "controllers.cbf.solver" in params
