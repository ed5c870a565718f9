"""Failure injection through the benchmark harness: solver errors and infeasible QPs.

A run whose safety filter meets a solver error or an infeasible program must
apply the filter's policy, count every use, complete, and record the counts in
its result row. (Controllers that return NaN or raise are covered by
``tests/test_bench.py::test_failed_runs_are_rows_and_the_sweep_goes_on``.)
"""

from __future__ import annotations

import math

import numpy as np
import qpsolvers

from dfcoa_opt.bench.executors import ExecutorConfig
from dfcoa_opt.bench.harness import run_sweep
from dfcoa_opt.control.base import STATUS_FALLBACK, STATUS_SOLVER_FAIL
from dfcoa_opt.sim.log import RunLog


def ring_swap(path, n: int, ring: float, t_max: float) -> None:
    """Write a scenario: ``n`` single integrators on a ring, each bound for its antipode."""
    poses = ", ".join(f"[{10 + ring * math.cos(a):.6f}, {10 + ring * math.sin(a):.6f}, "
                      f"{a + math.pi:.6f}]" for a in np.arange(n) * 2 * math.pi / n)
    offsets = ", ".join(f"[{-ring * math.cos(a):.6f}, {-ring * math.sin(a):.6f}]"
                        for a in np.arange(n) * 2 * math.pi / n)
    path.write_text(f"""dt = 0.1
t_max = {t_max}
[world]
size = [20.0, 20.0]
resolution = 10
[robots]
model = "single_integrator"
radius = 0.3
v_max = 1.0
[team]
n = {n}
placement = "explicit"
start_noise = 0.05
poses = [{poses}]
[formation]
shape = "offsets"
offsets = [{offsets}]
[leader]
start = [10.0, 10.0]
goal = [10.6, 10.0]
speed = 0.02
goal_radius = 0.1
[sensors.lidar]
enabled = false
""")


def sweep_file(tmp_path, scenario, controllers_table: str):
    """A one-run sweep of ``goto_slot+orca`` on ``scenario`` with the given filter table."""
    path = tmp_path / "sweep.toml"
    path.write_text(f'name = "inject"\nscenarios = ["{scenario}"]\n'
                    f'controllers = ["goto_slot+orca"]\nseeds = 1\n[[variants]]\n'
                    f"{controllers_table}\n")
    return path


def the_row_and_log(res):
    """The only row of a sweep result, and its log."""
    (row,) = res.store.rows()
    assert row["status"] == "ok", row["error"]
    return row, RunLog.load(res.store.root / row["log"])


def test_forced_solver_errors_apply_the_policy_are_counted_and_recorded(tmp_path, monkeypatch):
    """Every 7th call into the QP solver raises: each one fails exactly that robot's solve,
    the 'stop' policy commands zero for it, the run completes, and the row counts them."""
    scen = tmp_path / "swap.toml"
    ring_swap(scen, n=6, ring=3.0, t_max=6.0)
    real, calls, raised = qpsolvers.solve_qp, [0], [0]

    def flaky(*args, **kwargs):
        calls[0] += 1
        if calls[0] % 7 == 0:
            raised[0] += 1
            raise RuntimeError("injected solver crash")
        return real(*args, **kwargs)

    monkeypatch.setattr(qpsolvers, "solve_qp", flaky)
    sweep = sweep_file(tmp_path, scen, '"controllers.orca.solver" = "qp"\n'
                                       '"controllers.orca.infeasible" = "stop"')
    res = run_sweep(sweep, tmp_path / "out", ExecutorConfig("serial"), progress=False)
    assert (res.ran, res.failed) == (1, 0)
    row, log = the_row_and_log(res)
    failed = log.filter_status == STATUS_SOLVER_FAIL
    assert raised[0] > 5
    assert row["metrics"]["filter_solver_failures"] == int(failed.sum()) == raised[0]
    assert row["metrics"]["filter_fallbacks"] >= raised[0]
    np.testing.assert_array_equal(log.command[failed], 0.0)  # the policy was applied
    assert log.t[-1] >= 6.0 - 1e-9 or row["metrics"]["goal_reached"]  # the run went on


def test_infeasible_programs_apply_the_policy_are_counted_and_recorded(tmp_path):
    """A tight ring of 12 with an 8 s horizon makes the ORCA programs infeasible: through
    osqp each gets the 'stop' policy, and the row's count equals the log's."""
    scen = tmp_path / "tight.toml"
    ring_swap(scen, n=12, ring=2.0, t_max=4.0)
    sweep = sweep_file(tmp_path, scen, '"controllers.orca.solver" = "qp"\n'
                                       '"controllers.orca.infeasible" = "stop"\n'
                                       '"controllers.orca.time_horizon" = 8.0')
    res = run_sweep(sweep, tmp_path / "out", ExecutorConfig("serial"), progress=False)
    assert (res.ran, res.failed) == (1, 0)
    row, log = the_row_and_log(res)
    fallback = log.filter_status == STATUS_FALLBACK
    assert fallback.sum() > 0
    assert row["metrics"]["filter_fallbacks"] == int(fallback.sum())
    assert row["metrics"]["filter_solver_failures"] == 0
    np.testing.assert_array_equal(log.command[fallback], 0.0)
    assert (log.filter_slack[fallback] > 0).all()  # the violation left is recorded too
