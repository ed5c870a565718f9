"""The batch stepper: a run started in a slot mid-batch is the run simulated alone."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dfcoa_opt.control.registry import make_controller
from dfcoa_opt.core.errors import DfcoaError
from dfcoa_opt.scenario.loader import load_scenario
from dfcoa_opt.sim.batch import BatchSimulator
from dfcoa_opt.sim.simulator import run_scenario
from dfcoa_opt.sim.stepper import Stepper

ROOT = Path(__file__).resolve().parents[1]


def drive(path: Path, overrides: dict, controller: str, seeds: list[int], later: list[int]):
    """Step a batch of ``seeds``; each time a run ends, start the next of ``later`` in its slot.

    Returns:
        ``{seed: digest}`` of every finished run, and the step at which each run started.
    """
    sc = load_scenario(path, seeds[0], overrides)
    sim = BatchSimulator(sc, [make_controller(controller) for _ in seeds], seeds)
    stepper = Stepper(sim, scan_wanted=True)
    ctrls = {e: c for e, c in enumerate(sim.controllers)}
    for e, c in ctrls.items():
        c.reset(sim.scenarios[e], stepper.rngs[e])
    queue, digests, started, step = list(later), {}, {}, 0
    while len(stepper.active):
        stepper.sense()
        cmd = np.concatenate([ctrls[e].act(stepper.run_observation(j))
                              for j, e in enumerate(stepper.active)])
        for end in stepper.apply(cmd, ctrls[0].command):
            e = end.slot
            log = stepper.log.run(e, end.steps, sim.scenarios[e].offsets,
                                  sim.scenarios[e].world.dynamic.radii)
            digests[sim.seeds[e]] = log.digest()
            if queue:
                seed = queue.pop(0)
                stepper.restart(e, seed)
                ctrls[e] = make_controller(controller)
                ctrls[e].reset(sim.scenarios[e], stepper.rngs[e])
                started[seed] = step + 1
        step += 1
    return digests, started


@pytest.mark.parametrize("controller, stacked", [("goto_slot", True), ("lf_vo", True),
                                                  ("goto_slot", False)])
def test_runs_started_in_freed_slots_are_the_runs_alone(controller, stacked, monkeypatch):
    """Clutter (a world per seed), stops at contact or deadlock: runs end apart and restart.

    The leader slots come from the stacked tracks, or (past the size limit) run by run.
    """
    if not stacked:
        monkeypatch.setattr("dfcoa_opt.sim.lookups.TRACKS_STACKED_BYTES", 0)
    path = ROOT / "scenarios" / "bench" / "clutter.toml"
    overrides = {"stop_on_collision": True, "stop_on_deadlock": True, "t_max": 60.0,
                 "team.start_noise": 0.05}
    digests, started = drive(path, overrides, controller, [0, 1], [2, 3, 4])
    assert sorted(digests) == [0, 1, 2, 3, 4]
    assert len(set(started.values())) >= 2 and min(started.values()) > 1  # mid-batch, apart
    for seed, digest in digests.items():
        assert digest == run_scenario(load_scenario(path, seed, overrides), controller).digest()


def test_runs_started_in_freed_slots_with_late_messages_are_the_runs_alone():
    """Late and lost messages gated by the range at sending: a restarted slot keeps none."""
    path = ROOT / "scenarios" / "bench" / "clutter.toml"
    overrides = {"stop_on_collision": True, "stop_on_deadlock": True, "t_max": 60.0,
                 "team.start_noise": 0.05, "comms.latency": 0.3, "comms.dropout": 0.2,
                 "sensors.comm_radius": 2.0}
    digests, started = drive(path, overrides, "lf_vo", [0, 1], [2, 3, 4])
    assert sorted(digests) == [0, 1, 2, 3, 4]
    assert len(set(started.values())) >= 2 and min(started.values()) > 1  # mid-batch, apart
    for seed, digest in digests.items():
        assert digest == run_scenario(load_scenario(path, seed, overrides), "lf_vo").digest()


def test_a_slot_with_a_run_cannot_restart():
    sc = load_scenario(ROOT / "scenarios" / "example_empty.toml", overrides={"t_max": 1.0})
    sim = BatchSimulator(sc, [make_controller("goto_slot") for _ in range(2)], [0, 1])
    stepper = Stepper(sim, scan_wanted=False)
    with pytest.raises(DfcoaError, match="slot 1 still has a run"):
        stepper.restart(1, 5)
