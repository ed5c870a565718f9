"""Batched simulation: a batch of E runs gives the logs of its runs alone, bit for bit."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import dfcoa_opt as d
from dfcoa_opt.core.errors import DfcoaError
from dfcoa_opt.scenario.loader import load_scenario, reseed
from dfcoa_opt.sim.batch import BatchSimulator
from dfcoa_opt.sim.simulator import Simulator, run_batch_logs, run_scenario

ROOT = Path(__file__).resolve().parents[1]
COMMON = [ROOT / "scenarios" / "dfcoa_s1.toml", ROOT / "scenarios" / "dfcoa_s2.toml",
          *sorted((ROOT / "scenarios" / "bench").glob("*.toml"))]
#: As the comparison runs them.
SETTINGS = {"controllers.virtual_spring.offset_frame": "leader",
            "controllers.virtual_spring_basic.offset_frame": "leader",
            "controllers.cbf.solver": "exact"}
SEEDS = (0, 1, 2)
VARIANTS = [*d.controllers(), "goto_slot+cbf", "goto_slot+orca"]


def singles(path: Path, controller: str, overrides: dict, seeds=SEEDS) -> list[str]:
    return [run_scenario(load_scenario(path, s, overrides), controller).digest() for s in seeds]


@pytest.mark.parametrize("controller", VARIANTS)
def test_a_batch_of_three_is_three_single_runs_on_every_common_scenario(controller):
    overrides = {**SETTINGS, "t_max": 3.0}
    for path in COMMON:
        sc = load_scenario(path, 7, overrides)  # drawn for another seed: each run redraws
        batch = run_batch_logs(sc, controller, SEEDS)
        assert [log.digest() for log in batch] == singles(path, controller, overrides), path.stem
        assert [log.meta["seed"] for log in batch] == list(SEEDS)


@pytest.mark.parametrize("controller", ["goto_slot", "virtual_spring", "goto_slot+cbf"])
def test_runs_that_end_early_leave_the_batch_with_their_own_log(controller):
    """Clutter with stops at the first contact and at a deadlock: the runs end apart."""
    overrides = {**SETTINGS, "stop_on_collision": True, "stop_on_deadlock": True}
    path = ROOT / "scenarios" / "bench" / "clutter.toml"
    seeds = (0, 1, 2, 3, 4)
    batch = run_batch_logs(load_scenario(path, 0, overrides), controller, seeds)
    assert [log.digest() for log in batch] == singles(path, controller, overrides, seeds)
    assert len({log.n_steps for log in batch}) > 1  # they did end at different steps


def test_run_iter_yields_each_run_as_it_ends():
    from dfcoa_opt.control.registry import make_controller

    overrides = {"stop_on_collision": True, "stop_on_deadlock": True}
    sc = load_scenario(ROOT / "scenarios" / "bench" / "clutter.toml", 0, overrides)
    order = [(e, log.n_steps) for e, log in
             BatchSimulator(sc, make_controller("goto_slot"), [0, 1, 2, 3]).run_iter()]
    steps = [s for _, s in order]
    assert sorted(e for e, _ in order) == [0, 1, 2, 3] and steps == sorted(steps)
    assert len(set(steps)) > 1


class Hold:
    """An unbatched controller (no ``batched`` attribute): every robot stands still."""

    name = "hold"
    command = "velocity"
    uses_scan = False

    def reset(self, scenario, rng):
        self.scenario = scenario

    def act(self, obs):
        return np.zeros((obs.n, 2))


def test_an_unbatched_controller_needs_one_object_per_seed():
    from dfcoa_opt.control.registry import make_controller

    sc = load_scenario(ROOT / "scenarios" / "example_empty.toml", overrides={"t_max": 1.0})
    with pytest.raises(DfcoaError, match="'hold' is not batched: give one object per seed"):
        BatchSimulator(sc, Hold(), [0, 1])
    with pytest.raises(DfcoaError, match="at least one seed"):
        BatchSimulator(sc, make_controller("goto_slot"), [])
    assert Simulator(sc, Hold(), 3).run().meta["seed"] == 3
    holds = [Hold(), Hold()]
    logs = BatchSimulator(sc, holds, [4, 5]).run_all()
    assert [log.meta["seed"] for log in logs] == [4, 5]


def test_a_batched_controller_sees_every_run_in_one_observation():
    """One act per step for the whole batch: rows run after run, one leader state per run."""
    from dfcoa_opt.control.goto_slot import GotoSlot

    seen = []

    class Spy(GotoSlot):
        def act(self, obs):
            seen.append((obs.env.copy(), obs.leader.shape, obs.robot_ids.copy(),
                         obs.neighbours.index.copy()))
            return super().act(obs)

    sc = load_scenario(ROOT / "scenarios" / "example_empty.toml", overrides={"t_max": 1.0})
    logs = BatchSimulator(sc, Spy(GotoSlot.Params()), [0, 1, 2]).run_all()
    n = sc.n
    env, leader_shape, ids, index = seen[0]
    assert len(seen) == logs[0].n_steps and leader_shape == (3, 5)
    assert env.tolist() == [0] * n + [1] * n + [2] * n and ids.tolist() == list(range(n)) * 3
    rows = np.arange(3 * n)[:, None]
    real = index >= 0
    assert real.any() and np.all((index // n == rows // n)[real])  # neighbours of the same run


def test_run_batch_gives_the_runs_of_run_and_of_the_command_line(tmp_path):
    from dfcoa_opt.cli import main
    from dfcoa_opt.sim.log import RunLog

    path = ROOT / "scenarios" / "bench" / "clutter.toml"
    runs = d.run_batch(path, "goto_slot", [2, 0, 1])
    alone = [d.run(path, "goto_slot", seed=s) for s in (2, 0, 1)]
    assert [r.log.digest() for r in runs] == [r.log.digest() for r in alone]
    assert [r.scenario.spec.seed for r in runs] == [2, 0, 1]
    assert runs[1].metrics["fce_rms"] == alone[1].metrics["fce_rms"]
    assert main(["run", str(path), "--controller", "goto_slot", "--seeds", "0-1,2",
                 "--out", str(tmp_path), "--json"]) == 0
    cli = {s: RunLog.load(tmp_path / f"clutter-goto_slot-s{s}.npz").digest() for s in SEEDS}
    assert cli == {r.log.meta["seed"]: r.log.digest() for r in runs}


@pytest.mark.parametrize(("text", "seeds"), [("0-3", [0, 1, 2, 3]), ("5,1", [5, 1]),
                                             ("0-1, 7", [0, 1, 7]), ("4", [4])])
def test_seed_lists(text, seeds):
    from dfcoa_opt.cli import seed_list

    assert seed_list(text) == seeds


@pytest.mark.parametrize(("text", "error"), [("0-x", "is not a seed list"),
                                             ("3-1", "'3-1' must be a seed >= 0"),
                                             ("1,0-2", "names a seed twice"), ("", "not a seed")])
def test_bad_seed_lists_are_one_line_errors(text, error, capsys):
    from dfcoa_opt.cli import main

    assert main(["run", str(ROOT / "scenarios" / "example_empty.toml"), "--seeds", text]) == 2
    err = capsys.readouterr().err
    assert error in err and err.count("\n") == 1


@pytest.mark.parametrize("path", [COMMON[0], ROOT / "scenarios" / "bench" / "crossing.toml"],
                         ids=lambda p: p.stem)
def test_noisy_lidar_and_mcl_draw_from_each_runs_own_generator(path):
    """Range noise and the particle filter in one batch: each run's draws, in its order."""
    overrides = {"t_max": 2.0, "sensors.lidar.noise_std": 0.05, "localization": "mcl",
                 "team.start_noise": 0.1}
    batch = run_batch_logs(load_scenario(path, 0, overrides), "dfcoa", SEEDS)
    assert [log.digest() for log in batch] == singles(path, "dfcoa", overrides)
    assert len({log.digest() for log in batch}) == len(SEEDS)


def test_a_batched_centralized_cbf_solves_each_run_apart():
    path = ROOT / "scenarios" / "bench" / "large_20.toml"
    overrides = {"t_max": 1.5, "controllers.cbf.mode": "centralized", "team.start_noise": 0.2}
    batch = run_batch_logs(load_scenario(path, 0, overrides), "goto_slot+cbf", SEEDS)
    assert [log.digest() for log in batch] == singles(path, "goto_slot+cbf", overrides)


@pytest.mark.parametrize("path", [COMMON[0], ROOT / "scenarios" / "bench" / "clutter.toml"],
                         ids=lambda p: p.stem)
def test_one_batched_mcl_estimator_gives_each_run_its_single_run_estimates(path):
    """dfcoa with MCL, 3 runs: one estimator for the batch (clutter: a map per run)."""
    from dfcoa_opt.sim.localization import make_estimators

    overrides = {"t_max": 3.0, "localization": "mcl"}
    sc = load_scenario(path, 0, overrides)
    (est,) = make_estimators("mcl", [reseed(sc, s) for s in SEEDS])
    assert est.n_runs == len(SEEDS)
    batch = run_batch_logs(sc, "dfcoa", SEEDS)
    assert [log.digest() for log in batch] == singles(path, "dfcoa", overrides)
    assert len({log.pose_est.tobytes() for log in batch}) == len(SEEDS)
