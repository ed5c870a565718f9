"""``nmpc`` solver set-up: condensed vs multiple shooting, compiled vs interpreted, the cache."""

import warnings
from dataclasses import replace
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

import comparisons.nmpc.compiled as compiled_mod
from comparisons.nmpc.controller import Nmpc
from comparisons.nmpc.problem import NmpcProblem, map_multipliers
from dfcoa_opt.control.registry import build_controller
from dfcoa_opt.scenario.loader import load_scenario
from dfcoa_opt.sim.simulator import Simulator

ROOT = Path(__file__).resolve().parents[1]
S1 = ROOT / "scenarios/dfcoa_s1.toml"
#: Multiple shooting, interpreted: the default before the condensed, compiled solver.
OLD = {"formulation": "multiple-shooting", "compiled": False}


def run_s1(seconds, **params):
    overrides = {f"controllers.nmpc.{k}": v for k, v in params.items()}
    sc = load_scenario(S1, overrides={"t_max": seconds, **overrides})
    ctrl = build_controller("nmpc", sc.spec.controllers, sc.source)
    return Simulator(sc, ctrl).run(), ctrl


def test_condensed_run_matches_multiple_shooting_to_solver_tolerance():
    """3 s of S1: the default (condensed, compiled) against the old default.

    Both solve the same NLP to ``tol = 1e-4`` (primal and dual). The Gauss-Newton Hessian
    is at least ``2 (w_effort + w_rate) = 0.4`` on every control (s^2/m^2, s^2/rad^2),
    so the two solutions of one step differ by at most ``1e-4 / 0.4 = 2.5e-4`` in each
    control, i.e. ``2.5e-5`` m (or rad) per 0.1 s step; 31 steps add up to at most
    ``7.75e-4``. Allowed: ``2e-3`` m and rad. Measured on the whole S1 (848 steps):
    1.1e-4 m.
    """
    new, _ = run_s1(3.0)
    old, _ = run_s1(3.0, **OLD)
    assert new.pose.shape == old.pose.shape == (31, 4, 3)
    d_pos = np.hypot(*(new.pose[..., :2] - old.pose[..., :2]).transpose(2, 0, 1)).max()
    d_th = np.abs(new.pose[..., 2] - old.pose[..., 2]).max()
    assert 0.0 < d_pos < 2e-3 and d_th < 2e-3  # different iterates, same trajectories
    assert np.all(new.filter_status == 0) and np.all(old.filter_status == 0)


def test_condensed_and_multiple_shooting_have_the_same_minimisers(monkeypatch):
    """Problems of the first 0.5 s of S1, solved by both formulations to 1e-10 (IPOPT)."""
    captured = []
    orig = Nmpc._prepare

    def spy(self, obs):
        z, step = orig(self, obs)
        tight = {f: NmpcProblem(replace(self.spec, solver="ipopt", hessian="exact", tol=1e-10,
                                        max_iter=200, formulation=f, compiled=False))
                 for f in ("condensed", "multiple-shooting")}
        captured.extend({f: (pr, self._inputs(i, step, pr)) for f, pr in tight.items()}
                        for i in range(obs.n))
        return z, step

    monkeypatch.setattr(Nmpc, "_prepare", spy)
    run_s1(0.5)
    assert len(captured) == 6 * 4
    for problems in captured[::3]:
        sols = {f: pr.solve(*args) for f, (pr, args) in problems.items()}
        assert all(s.success for s in sols.values())
        cond, ms = sols["condensed"], sols["multiple-shooting"]
        np.testing.assert_allclose(cond.u, ms.u, atol=1e-7)
        np.testing.assert_allclose(cond.x, ms.x, atol=1e-7)
        # the half-plane multipliers are the same constraints' multipliers
        _, lam_g = map_multipliers(ms.lam_x, ms.lam_g, ms_spec := problems["multiple-shooting"][0]
                                   .spec, problems["condensed"][0].spec)
        assert ms_spec.dyn_rows == 3
        np.testing.assert_allclose(cond.lam_g, lam_g, atol=1e-6)


def test_compiled_solver_gives_the_interpreted_numbers_bit_for_bit():
    new, ctrl = run_s1(3.0)
    if ctrl.problem.compiled is None:
        pytest.skip("no C compiler")
    interp, ictrl = run_s1(3.0, compiled=False)
    assert ictrl.problem.compiled is None
    for key in ("pose", "command", "filter_status", "filter_slack"):
        np.testing.assert_array_equal(getattr(new, key), getattr(interp, key))


def test_same_seed_same_run_bit_for_bit():
    a, _ = run_s1(2.0)
    b, _ = run_s1(2.0)
    for key in ("pose", "command", "filter_status", "filter_slack"):
        np.testing.assert_array_equal(getattr(a, key), getattr(b, key))


def captured_inputs(monkeypatch, seconds, **params):
    """Run S1 for ``seconds``; the controller and the packed inputs of its SQP solves."""
    zs = []
    orig = NmpcProblem.solve_rows

    def spy(self, z):
        if self.spec.solver == "sqp":
            zs.extend(z.copy())
        return orig(self, z)

    with monkeypatch.context() as m:
        m.setattr(NmpcProblem, "solve_rows", spy)
        _, ctrl = run_s1(seconds, **params)
    return ctrl, zs


def test_compiled_success_flag_is_the_solvers_own_test(monkeypatch):
    """With 3 SQP iterations most solves stop unconverged: both paths must say so alike."""
    ctrl, zs = captured_inputs(monkeypatch, 0.5)
    spec = replace(ctrl.spec, max_iter=3)
    comp, interp = NmpcProblem(spec), NmpcProblem(replace(spec, compiled=False))
    if comp.compiled is None:
        pytest.skip("no C compiler")
    rng = np.random.default_rng(0)
    flags = []
    for z in zs:  # as captured, or with the controls of the initial guess perturbed
        z = z.copy()
        if rng.random() < 0.5:
            z[:comp.sizes[0]] += rng.normal(0.0, 0.1, comp.sizes[0])
        a, b = comp.solve_packed(z), interp.solve_packed(z)
        for key in ("w", "lam_x", "lam_g", "x"):
            np.testing.assert_array_equal(getattr(a, key), getattr(b, key))
        assert a.success == b.success
        flags.append(a.success)
    assert any(flags) and not all(flags)


def test_solve_rows_gives_each_rows_single_solve_bit_for_bit(monkeypatch):
    """One batched call (compiled: one C loop) = one solve_packed per row, both solvers."""
    ctrl, zs = captured_inputs(monkeypatch, 0.5)
    zs = np.array(zs)
    spec = replace(ctrl.spec, max_iter=3)  # some rows fail: their flags must match too
    for problem in (NmpcProblem(spec), NmpcProblem(replace(spec, compiled=False))):
        batch = problem.solve_rows(zs)
        assert batch.seconds.shape == (len(zs),) and np.all(batch.seconds > 0.0)
        for i, z in enumerate(zs):
            one, row = problem.solve_packed(z), batch.row(i)
            for key in ("w", "lam_x", "lam_g", "x", "u", "slack"):
                np.testing.assert_array_equal(getattr(row, key), getattr(one, key))
            assert (row.success, row.iterations) == (one.success, one.iterations)
        assert batch.success.any() and not batch.success.all()
        # the batch leaves the single call's buffers in place
        np.testing.assert_array_equal(problem.solve_packed(zs[0]).w, batch.w[0])


def test_batch_of_the_compiled_function_matches_single_calls(monkeypatch, tmp_path):
    monkeypatch.setenv("DFCOA_NMPC_CACHE", str(tmp_path))
    if compiled_mod.compiler() is None:
        pytest.skip("no C compiler")
    f = compiled_mod.compile_function(_tiny())
    x = np.random.default_rng(1).normal(size=(5, 3))
    out, flags, seconds = f.batch(x)
    np.testing.assert_array_equal(out, np.array([f(r) for r in x]))
    assert flags.tolist() == [0] * 5 and np.all(seconds >= 0.0)
    assert f.batch(np.zeros((0, 3)))[0].shape == (0, 4)


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


def test_without_a_compiler_the_interpreted_solver_is_used(monkeypatch, tmp_path):
    ctrl, zs = captured_inputs(monkeypatch, 0.1, compiled=False)
    monkeypatch.setenv("DFCOA_NMPC_CACHE", str(tmp_path))
    monkeypatch.setattr(compiled_mod, "compiler", lambda: None)
    with pytest.warns(RuntimeWarning, match="no C compiler"):
        problem = NmpcProblem(replace(ctrl.spec, compiled=True))
    assert problem.compiled is None
    assert problem.solve_packed(zs[0]).success
    assert not list(tmp_path.iterdir())


def test_a_failing_compiler_falls_back_with_a_warning(monkeypatch, tmp_path):
    monkeypatch.setenv("DFCOA_NMPC_CACHE", str(tmp_path))
    monkeypatch.setenv("CC", "false")  # exits 1
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert compiled_mod.compile_function(_tiny()) is None
    assert any("compiling the solver failed" in str(w.message) for w in caught)
    assert not list(tmp_path.glob("*.so"))
