"""``nmpc``'s real-time iteration (``controllers.nmpc.rti``): one SQP step per control step."""

import numpy as np
import pytest

from dfcoa_opt.control.base import STATUS_OK, STATUS_SOLVER_FAIL
from dfcoa_opt.core.errors import ScenarioError
from dfcoa_opt.scenario.loader import load_scenario
from dfcoa_opt.sim.simulator import Simulator, run_batch_logs, run_scenario
from tests.nmpc_support import ROOT, break_every_solver, controller, observation, scenario


def recording(ctrl):
    """Record ``(last_rti, last_iterations, status)`` after each ``act`` of ``ctrl``."""
    seen, act = [], ctrl.act

    def wrapped(obs):
        u = act(obs)
        seen.append((ctrl.last_rti.copy(), ctrl.last_iterations.copy(),
                     ctrl.last_result.status.copy()))
        return u

    ctrl.act = wrapped
    return seen


def test_rti_makes_one_iteration_per_step_after_a_full_first_solve():
    """Interpreted (it counts iterations; the compiled solver gives the same numbers)."""
    sc = scenario(n=2, poses=[(2.0, 4.0, 0.5), (1.5, 6.0, -0.5)],
                  offsets=[(0.0, -1.0), (0.0, 1.0)], t_max=4.0)
    ctrl = controller(sc, rti=True, compiled=False)
    assert ctrl.iterate.spec.rti and ctrl.iterate.spec.max_iter == 1
    seen = recording(ctrl)
    Simulator(sc, ctrl).run()
    rti = np.array([s[0] for s in seen])
    its = np.array([s[1] for s in seen])
    assert not rti[0].any() and its[0].min() > 1  # the first step: the full SQP, converged
    assert rti[1:].all()
    assert its[1:].max() == 1 and np.mean(its[1:] == 1) > 0.5  # 0: the warm start was optimal
    assert all(np.all(s[2] == STATUS_OK) for s in seen)


def test_without_rti_the_full_sqp_iterates_to_convergence():
    sc = scenario(n=2, poses=[(2.0, 4.0, 0.5), (1.5, 6.0, -0.5)],
                  offsets=[(0.0, -1.0), (0.0, 1.0)], t_max=4.0)
    ctrl = controller(sc, compiled=False)
    assert ctrl.iterate is None and ctrl.problem.spec.max_iter == 20
    assert not ctrl.problem.spec.rti
    seen = recording(ctrl)
    Simulator(sc, ctrl).run()
    assert not any(s[0].any() for s in seen)
    assert max(int(s[1].max()) for s in seen[1:]) > 1  # it goes on after the first iteration


def test_rti_needs_the_sqp_solver():
    sc = scenario(poses=[(2.0, 4.0, 0.0)])
    with pytest.raises(ScenarioError, match=r"controllers\.nmpc\.rti"):
        controller(sc, rti=True, solver="ipopt")


def test_rti_run_is_finite_and_reaches_the_goal():
    sc = load_scenario(ROOT / "scenarios/example_empty.toml",
                       overrides={"controllers.nmpc.rti": True})
    log = run_scenario(sc, "nmpc")
    assert np.all(np.isfinite(log.command))
    assert log.meta["reached_goal"]
    assert int(log.collision_events.sum()) == 0
    assert np.all(log.filter_status == STATUS_OK)


def test_rti_is_deterministic_and_compiled_equals_interpreted():
    path = ROOT / "scenarios/dfcoa_s1.toml"
    over = {"t_max": 2.0, "controllers.nmpc.rti": True}
    runs = [run_scenario(load_scenario(path, 0, over), "nmpc").digest() for _ in range(2)]
    interpreted = run_scenario(load_scenario(path, 0, {**over, "controllers.nmpc.compiled": False}),
                               "nmpc").digest()
    assert runs[0] == runs[1] == interpreted
    full = run_scenario(load_scenario(path, 0, {"t_max": 2.0}), "nmpc").digest()
    assert full != runs[0]  # rti really changes the iterates


@pytest.mark.parametrize("name", ["dfcoa_s2.toml", "bench/clutter.toml"])
def test_rti_batch_equals_its_single_runs(name):
    path = ROOT / "scenarios" / name
    over = {"t_max": 3.0, "controllers.nmpc.rti": True}
    batch = run_batch_logs(load_scenario(path, 7, over), "nmpc", [0, 1, 2])
    singles = [run_scenario(load_scenario(path, s, over), "nmpc").digest() for s in (0, 1, 2)]
    assert [log.digest() for log in batch] == singles


def test_rti_after_a_fallback_solves_fully_then_iterates_again(monkeypatch):
    sc = scenario(poses=[(2.0, 4.0, 0.0)])
    ctrl = controller(sc, rti=True)
    leader = (2.0, 5.0, 0.0, 0.3, 0.0)

    def act(k):
        ctrl.act(observation([2.0 + 0.01 * k, 4.0, 0.0], [[2.0 + 0.03 * k, 5.0]], t=0.1 * k,
                             leader=leader))
        return bool(ctrl.last_rti[0]), int(ctrl.last_result.status[0])

    assert [act(0), act(1)] == [(False, STATUS_OK), (True, STATUS_OK)]
    break_every_solver(monkeypatch)  # the iteration and its IPOPT rescue fail: shift
    assert act(2) == (True, STATUS_SOLVER_FAIL)
    monkeypatch.undo()
    assert [act(3), act(4)] == [(False, STATUS_OK), (True, STATUS_OK)]
