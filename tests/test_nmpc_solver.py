"""``nmpc`` solver set-up: the compiled-function cache."""

import warnings

import casadi as ca
import numpy as np
import pytest

import comparisons.nmpc.compiled as compiled_mod


# ----------------------------------------------------------------- the compiled-function cache
def _tiny():
    x = ca.MX.sym("x", 3)
    return ca.Function("tiny", [x], [ca.vertcat(ca.sin(x) * 2.0, ca.sumsqr(x))])


def test_compile_once_then_load_from_the_cache(monkeypatch, tmp_path):
    monkeypatch.setenv("DFCOA_NMPC_CACHE", str(tmp_path))
    if compiled_mod.compiler() is None:
        pytest.skip("no C compiler")
    f = compiled_mod.compile_function(_tiny())
    assert f is not None and len(list(tmp_path.glob("*.so"))) == 1
    x = np.array([0.1, -2.0, 3.0])
    np.testing.assert_array_equal(f(x), np.asarray(_tiny()(x)).ravel())

    def no_build(*args):
        raise AssertionError("compiled again")

    monkeypatch.setattr(compiled_mod, "_build", no_build)
    g = compiled_mod.compile_function(_tiny())  # same source: loaded from the cache
    np.testing.assert_array_equal(g(x), f(x))


def test_a_failing_compiler_falls_back_with_a_warning(monkeypatch, tmp_path):
    monkeypatch.setenv("DFCOA_NMPC_CACHE", str(tmp_path))
    monkeypatch.setenv("CC", "false")  # exits 1
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert compiled_mod.compile_function(_tiny()) is None
    assert any("compiling the solver failed" in str(w.message) for w in caught)
    assert not list(tmp_path.glob("*.so"))
