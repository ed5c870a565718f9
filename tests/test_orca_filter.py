"""The ``orca`` safety filter in the simulator, the navigator, and ``controller+filter`` ids."""

import numpy as np
import pytest

from comparisons.orca.filter import OrcaFilter, concat_lines
from dfcoa_opt import metrics
from dfcoa_opt.control.base import STATUS_FALLBACK, Filtered
from dfcoa_opt.control.registry import available_filters, build_controller, check_overrides
from dfcoa_opt.core.errors import ScenarioError, UnknownNameError
from dfcoa_opt.scenario.loader import scenario_from_dict
from dfcoa_opt.sim.simulator import run_scenario

R = 0.3  # robot radius, m


def swap_scenario(n=6, ring=3.0, model="single_integrator", noise=0.05, **extra):
    """``n`` robots on a ring whose slots are the antipodes: all cross at the centre.

    A small start noise (from the run's seed) breaks the perfect symmetry, in
    which reciprocal avoidance deadlocks (RVO2's examples perturb the preferred
    velocities for the same reason).
    """
    ang = np.arange(n) * 2 * np.pi / n
    start = np.column_stack((10 + ring * np.cos(ang), 10 + ring * np.sin(ang)))
    offsets = [(-ring * np.cos(a), -ring * np.sin(a)) for a in ang]
    data = {
        "name": "swap", "dt": 0.1, "t_max": 25.0, "seed": 3,
        "world": {"size": [20.0, 20.0], "resolution": 10},
        "robots": {"model": model, "radius": R, "v_max": 1.0, "w_max": 3.0},
        "team": {"n": n, "placement": "explicit", "start_noise": noise,
                 "poses": [[float(x), float(y), float(a + np.pi)]
                           for (x, y), a in zip(start, ang, strict=True)]},
        "formation": {"shape": "offsets", "offsets": offsets},
        "leader": {"start": [10.0, 10.0], "goal": [10.6, 10.0], "speed": 0.02,
                   "goal_radius": 0.1},
        "sensors": {"lidar": {"enabled": False}},
        **extra,
    }
    return scenario_from_dict(data, "<swap>")


def test_composed_ids_build_a_filtered_controller_and_validate_both_parts():
    assert "orca" in available_filters()
    ctrl = build_controller("goto_slot+orca", {"goto_slot": {"kp": 2.0},
                                               "orca": {"time_horizon": 3.0}})
    assert isinstance(ctrl, Filtered) and ctrl.name == "goto_slot+orca"
    assert ctrl.controller.p.kp == 2.0 and ctrl.safety.p.time_horizon == 3.0
    with pytest.raises(UnknownNameError, match="did you mean 'orca'"):
        build_controller("goto_slot+orka")
    with pytest.raises(ScenarioError, match="controllers.orca.time_horizon"):
        check_overrides({"orca": {"time_horizon": -1.0}}, "f.toml")


def test_plain_goto_slot_collides_in_the_swap():
    """The baseline the filter must fix: the straight lines cross at the centre."""
    sc = swap_scenario()
    s = metrics.summary(run_scenario(sc, "goto_slot"), sc)
    assert s["collisions"] > 0


@pytest.mark.parametrize("safe_discrete", [False, True])
def test_filter_makes_the_swap_collision_free(safe_discrete):
    sc = swap_scenario(controllers={"orca": {"safe_discrete": safe_discrete}})
    log = run_scenario(sc, "goto_slot+orca")
    s = metrics.summary(log, sc)
    assert s["collisions"] == 0
    assert s["min_inter_robot_distance"] >= 2 * R - 1e-9
    assert np.linalg.norm(log.velocity, axis=-1).max() <= 1.0 + 1e-9
    final = np.linalg.norm(log.pose[-1, :, :2] - log.slots[-1], axis=1)
    assert final.max() < 0.5  # they get through, not just stop


def test_navigator_reaches_the_slots_without_collision():
    sc = swap_scenario(controllers={"orca_nav": {"speed": 1.0}})
    log = run_scenario(sc, "orca_nav")
    s = metrics.summary(log, sc)
    assert s["collisions"] == 0
    assert np.linalg.norm(log.pose[-1, :, :2] - log.slots[-1], axis=1).max() < 0.5


def test_infeasible_policies_are_applied_and_counted():
    """A tight crowd makes some programs infeasible; 'stop' then commands zero."""
    sc = swap_scenario(n=12, ring=2.0, controllers={"orca": {"infeasible": "stop",
                                                             "time_horizon": 8.0}})
    log = run_scenario(sc, "goto_slot+orca")
    fallback = log.filter_status == STATUS_FALLBACK
    assert fallback.any()
    assert metrics.summary(log, sc)["filter_fallbacks"] == int(fallback.sum())


def test_concat_lines_keeps_each_rows_lines_in_order():
    a = (np.arange(12.0).reshape(2, 3, 2), -np.arange(12.0).reshape(2, 3, 2), np.array([1, 3]))
    b = (100 + np.arange(4.0).reshape(2, 1, 2), np.ones((2, 1, 2)), np.array([1, 0]))
    p, d, c = concat_lines([a, b])
    assert list(c) == [2, 3]
    np.testing.assert_array_equal(p[0, :2], [[0, 1], [100, 101]])
    np.testing.assert_array_equal(p[1, :3], a[0][1])
    np.testing.assert_array_equal(d[0, 1], [1, 1])


def test_filter_params_reject_unknown_policy():
    from dfcoa_opt.core.params import build

    with pytest.raises(ScenarioError, match="infeasible"):
        build(OrcaFilter.Params, {"infeasible": "ignore"}, "f.toml", "controllers.orca")


def test_qp_solver_path_gives_the_same_run_as_the_exact_path():
    """The filter's two solving paths agree on a whole swap run (positions to 1e-6 m)."""
    logs = [run_scenario(swap_scenario(n=4, controllers={"orca": {"solver": s}}),
                         "goto_slot+orca") for s in ("exact", "qp")]
    np.testing.assert_allclose(logs[0].pose[..., :2], logs[1].pose[..., :2], atol=1e-6)


@pytest.mark.parametrize("mode", ["orca", "ivo"])
def test_table1_orca_stalls_and_ivo_gets_round(mode):
    """Paper 001 Table I field: RVO2 obstacle lines stop at the first face; IVO gets round.

    Both stay off the obstacles (the lines are hard). This is the behaviour
    Figs 5-6 describe, on our field (docs/reproduction.md).
    """
    from pathlib import Path

    from dfcoa_opt.scenario.loader import load_scenario

    path = Path(__file__).resolve().parents[1] / "scenarios/paper001/table1_crossing.toml"
    sc = load_scenario(path, overrides={"controllers.orca_nav.obstacles": mode})
    log = run_scenario(sc, "orca_nav")
    final = np.linalg.norm(log.pose[-1, :, :2] - log.slots[-1], axis=1)
    assert log.collision_events.sum() == 0
    assert log.clearance.min() >= sc.spec.robots.radius - 1e-9
    if mode == "orca":
        assert np.all(final > 10.0)  # stuck in front of A and B
    else:
        assert np.all(final <= sc.spec.leader.settle_tolerance)
        assert log.meta["reached_goal"]


@pytest.mark.parametrize("cid", ["goto_slot+orca", "orca_nav", "consensus_ivo"])
def test_a_qp_backend_that_is_not_installed_is_a_scenario_error(cid):
    """A misspelt ``qp_solver`` stops the run before its first step, naming the owner's key."""
    owner = cid.split("+")[-1]
    sc = swap_scenario(n=2, controllers={owner: {"solver": "qp", "qp_solver": "osqpp"}})
    with pytest.raises(ScenarioError, match=rf"<swap>: controllers\.{owner}\.qp_solver: "
                                            r"qpsolvers backend 'osqpp' is not installed .*"
                                            r"did you mean 'osqp'"):
        run_scenario(sc, cid)
