"""numba's kernel cache follows edits of the modules a kernel imports (core.runtime)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

import dfcoa_opt
from dfcoa_opt.core.runtime import kernel_cache

KERNEL = """import numba
from kcpkg.b import K, g


@numba.njit(cache=True)
def f(x):
    return g(x) * K
"""
HELPER = """import numba

K = {k}


@numba.njit
def g(x):
    return x + {add}
"""
DRIVER = """import json, sys
from pathlib import Path

import pytest
sys.path.insert(0, sys.argv[1])
touched = None
if sys.argv[2] == "refresh":
    from dfcoa_opt.core.runtime.kernel_cache import refresh
    touched = refresh([Path(sys.argv[1]) / "kcpkg"])
import kcpkg.a
print(json.dumps({"touched": touched, "value": kcpkg.a.f(1.0)}))
"""


def _run(root: Path, mode: str) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    proc = subprocess.run([sys.executable, "-c", DRIVER, str(root), mode], capture_output=True,
                          text=True, timeout=300, env=env, check=True)
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_a_kernel_is_compiled_again_when_a_module_it_imports_changes(tmp_path):
    pkg = tmp_path / "kcpkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text(KERNEL)
    (pkg / "b.py").write_text(HELPER.format(k=1.0, add=1.0))
    (pkg / "c.py").write_text("X = 1\n")
    assert _run(tmp_path, "refresh") == {"touched": ["kcpkg.a"], "value": 2.0}  # no state yet
    assert _run(tmp_path, "plain")["value"] == 2.0
    (pkg / "b.py").write_text(HELPER.format(k=2.0, add=100.0))
    # numba alone keeps the old g and K in a's cache entry: the hazard is real here
    assert _run(tmp_path, "plain")["value"] == 2.0
    assert _run(tmp_path, "refresh") == {"touched": ["kcpkg.a"], "value": 202.0}
    (pkg / "c.py").write_text("X = 2\n")  # a does not import c: nothing to compile
    assert _run(tmp_path, "refresh") == {"touched": [], "value": 202.0}


def test_imports_are_read_from_every_statement_and_limited_to_known_modules():
    known = ["p", "p.geo", "p.kern", "p.sub", "p.sub.deep"]
    src = (b"import numpy as np\nimport p.geo\nfrom p.sub import deep, name\n"
           b"def f():\n    from p.kern import k\n    return k\n")
    assert kernel_cache.imported_modules(src, known) == ["p.geo", "p.kern", "p.sub",
                                                         "p.sub.deep"]
    assert kernel_cache.imported_modules(b"def (:", known) == []
    relative = b"from . import geo\nfrom .sub import deep\nfrom ..x import y\n"
    assert kernel_cache.imported_modules(relative, known, package="p") == ["p", "p.geo",
                                                                          "p.sub", "p.sub.deep"]
    assert kernel_cache.imported_modules(b"from .. import kern\n", known,
                                         package="p.sub") == ["p", "p.kern"]


def test_importing_the_toolkit_records_the_stamps_of_its_kernel_modules():
    state = Path(dfcoa_opt.__file__).parent / "__pycache__" / kernel_cache.STATE_NAME
    stamps = json.loads(state.read_text())["stamps"]
    assert {"dfcoa_opt.planning.astar_kernel", "comparisons.orca.lp"} <= set(stamps)
    assert "dfcoa_opt.sim.simulator" not in stamps  # no cached kernel there


def test_a_read_only_install_is_left_alone(tmp_path, monkeypatch):
    pkg = tmp_path / "kcpkg"
    (pkg / "__pycache__").mkdir(parents=True)
    (pkg / "a.py").write_text(KERNEL)
    cached = pkg / "__pycache__" / "a.f-5.py311.nbi"
    cached.write_bytes(b"index")
    monkeypatch.setattr(kernel_cache.os, "access", lambda path, mode: False)
    assert kernel_cache.refresh([pkg]) == []
    assert cached.exists() and not (pkg / "__pycache__" / kernel_cache.STATE_NAME).exists()
    monkeypatch.undo()
    assert kernel_cache.refresh([pkg]) == ["kcpkg.a"]  # writable: no state yet, dropped
    assert not cached.exists()


def test_an_unreadable_source_warns_and_drops_nothing(tmp_path):
    pkg = tmp_path / "kcpkg"
    (pkg / "__pycache__").mkdir(parents=True)
    (pkg / "a.py").write_text(KERNEL)
    (pkg / "b.py").mkdir()  # a folder named like a source: reading it fails
    cached = pkg / "__pycache__" / "a.f-5.py311.nbi"
    cached.write_bytes(b"index")
    with pytest.warns(RuntimeWarning, match="b.py: cannot read it"):
        assert kernel_cache.refresh([pkg]) == []
    assert cached.exists()
