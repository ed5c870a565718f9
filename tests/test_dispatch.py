"""The SIMD cap: numpy's dispatch pinned at X86_V3 on x86-64, so results match across machines.

Every check runs in a fresh interpreter: numpy reads its dispatch variables once,
when it loads.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from dfcoa_opt.core.runtime import dispatch

ROOT = Path(__file__).resolve().parents[1]
CLUTTER = ROOT / "scenarios" / "bench" / "clutter.toml"
pytestmark = pytest.mark.skipif(not dispatch.is_x86(), reason="the cap applies to x86-64 only")

#: What a fresh interpreter reports after its imports: numpy's level, the variables.
PROBE = ("import json, os; from dfcoa_opt.core.runtime.dispatch import numpy_simd; "
         "print(json.dumps({'level': numpy_simd(), 'disabled': "
         "os.environ.get('NPY_DISABLE_CPU_FEATURES'), 'blas': "
         "os.environ.get('OPENBLAS_CORETYPE')}))")


def clean_env(**extra: str) -> dict[str, str]:
    """This environment without the variables the test process's own cap set."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("NPY_DISABLE_CPU_FEATURES", "NPY_ENABLE_CPU_FEATURES",
                        "OPENBLAS_CORETYPE", dispatch.CAP_VARIABLE)}
    return {**env, **extra}


def python(code: str, **env: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-c", code], env=clean_env(**env), cwd=ROOT,
                          capture_output=True, text=True, check=True, timeout=300)


def probe(first: str = "import dfcoa_opt", **env: str) -> dict[str, str | None]:
    return json.loads(python(f"{first}; {PROBE}", **env).stdout.strip().splitlines()[-1])


def machine_has(level: str) -> bool:
    """Whether this CPU reaches numpy's dispatch ``level`` (uncapped)."""
    from numpy._core import _multiarray_umath as umath

    return bool(umath.__cpu_features__.get(level))


def test_importing_dfcoa_opt_first_caps_numpy_at_x86_v3():
    got = probe()
    assert not dispatch.above_cap(got["level"], "X86_V3")
    assert set(dispatch.targets_above("X86_V3")) <= set(got["disabled"].split())
    if machine_has("X86_V3"):
        assert got["level"] == "X86_V3" and got["blas"] == "Haswell"


def test_the_cap_keeps_the_users_own_disabled_targets():
    got = probe(NPY_DISABLE_CPU_FEATURES="AVX512_SPR", OPENBLAS_CORETYPE="Nehalem")
    disabled = got["disabled"].split()
    assert disabled[0] == "AVX512_SPR" and disabled.count("AVX512_SPR") == 1
    assert set(dispatch.targets_above("X86_V3")) <= set(disabled) and got["blas"] == "Nehalem"


def test_native_leaves_numpy_alone():
    got = probe(DFCOA_SIMD_CAP="native")
    assert got["disabled"] is None and got["blas"] is None
    here = probe("import numpy")  # what numpy picks with no cap at all
    assert got["level"] == here["level"]


def test_numpy_imported_first_warns_once_with_the_fix():
    if not machine_has("X86_V3"):
        pytest.skip("numpy runs at its baseline here: nothing above an X86_V2 cap")
    code = ("import warnings, numpy, dfcoa_opt as d; warnings.simplefilter('always'); "
            "[d.run('scenarios/example_empty.toml', 'goto_slot', seed=s) for s in (0, 1)]")
    err = python(code, DFCOA_SIMD_CAP="X86_V2").stderr
    assert err.count("UserWarning: numpy dispatches to") == 1
    assert "above the X86_V2 cap" in err and "import dfcoa_opt first" in err
    assert "NPY_DISABLE_CPU_FEATURES='X86_V3 " in err or "NPY_DISABLE_CPU_FEATURES='AVX " in err
    assert "numpy dispatches" not in python(code.replace("numpy, ", "")).stderr


def test_a_bad_cap_value_warns_in_one_line_and_keeps_the_default():
    err = python("import dfcoa_opt", DFCOA_SIMD_CAP="X86_V9").stderr
    assert "DFCOA_SIMD_CAP='X86_V9' is not one of X86_V2, X86_V3, native; using X86_V3" in err


def test_sweep_workers_run_capped_and_rows_record_it(tmp_path):
    """``dfcoa bench`` on local processes and on a local Dask cluster, from a clean shell."""
    sweep = tmp_path / "s.toml"
    sweep.write_text(f'scenarios = ["{ROOT / "scenarios" / "example_empty.toml"}"]\n'
                     'controllers = ["goto_slot"]\nseeds = 2\n')
    for i, how in enumerate((["--jobs", "2"], ["--dask-local", "1"])):
        out = tmp_path / f"r{i}"
        subprocess.run([sys.executable, "-m", "dfcoa_opt", "bench", str(sweep), "--out", str(out),
                        "--no-progress", *how], env=clean_env(), cwd=ROOT, check=True,
                       capture_output=True, timeout=300)
        rows = [json.loads(p.read_text()) for p in sorted((out / "rows").glob("*.json"))]
        assert len(rows) == 2
        for row in rows:
            prov = row["provenance"]
            assert prov["simd_cap"] == "X86_V3" and not dispatch.above_cap(prov["simd"], "X86_V3")
            assert prov["pid"] != os.getpid()


VIRTUAL_SPRING_CLUTTER = (
    "import dfcoa_opt as d; from dfcoa_opt.core.runtime.dispatch import numpy_simd; "
    f"p = {str(CLUTTER)!r}; "
    "print(numpy_simd(), *[d.run(d.load(p, seed=s, overrides={"
    "'controllers.virtual_spring.offset_frame': 'leader'}), 'virtual_spring').log.digest() "
    "for s in range(5)])")


def test_x86_v3_and_x86_v2_give_the_same_bits():
    """The comparison's most chaotic cell: virtual_spring in clutter, seeds 0-4."""
    procs = {cap: subprocess.Popen([sys.executable, "-c", VIRTUAL_SPRING_CLUTTER],
                                   env=clean_env(DFCOA_SIMD_CAP=cap), cwd=ROOT, text=True,
                                   stdout=subprocess.PIPE)
             for cap in ("X86_V3", "X86_V2")}
    out = {cap: p.communicate(timeout=600)[0].split() for cap, p in procs.items()}
    assert all(p.returncode == 0 for p in procs.values())
    assert out["X86_V2"][0] == "X86_V2"
    if machine_has("X86_V3"):
        assert out["X86_V3"][0] == "X86_V3"
    assert len(out["X86_V3"]) == 6 and out["X86_V3"][1:] == out["X86_V2"][1:]
