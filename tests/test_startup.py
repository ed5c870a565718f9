"""Start-up stays light: listing controllers and importing the planner load no heavy module."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: Modules that cost 0.1-0.5 s each to import and that no listing needs.
HEAVY = ("scipy.signal", "casadi", "matplotlib", "scipy.optimize", "qpsolvers")


def test_listing_controllers_and_importing_the_planner_load_no_heavy_module():
    code = ("import json, sys; from dfcoa_opt.cli import main; main(['list', 'controllers']); "
            "import dfcoa_opt.planning.astar; "
            f"print(json.dumps([m for m in {HEAVY!r} if m in sys.modules]))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT,
                         check=True, timeout=120).stdout.strip().splitlines()
    assert "nmpc" in "\n".join(out[:-1])  # it listed them, nmpc (casadi's user) included
    assert json.loads(out[-1]) == []


def test_the_heavy_modules_are_loaded_where_they_are_used():
    """The lazy imports still happen: S1's improved A* convolves, an nmpc run builds casadi."""
    code = ("import json, sys, dfcoa_opt as d; "
            "d.run(d.load('scenarios/dfcoa_s1.toml', t_max=0.3), 'nmpc'); "
            "print(json.dumps(sorted(m for m in ('casadi', 'scipy.signal') if m in sys.modules)))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT,
                         check=True, timeout=300).stdout.strip().splitlines()
    assert json.loads(out[-1]) == ["casadi", "scipy.signal"]
