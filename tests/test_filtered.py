import numpy as np

from dfcoa_opt.control.base import (
    STATUS_FALLBACK,
    STATUS_MODIFIED,
    STATUS_OK,
    Filtered,
    FilterResult,
)
from dfcoa_opt.control.goto_slot import GotoSlot
from dfcoa_opt.metrics import summary
from dfcoa_opt.scenario.loader import scenario_from_dict
from dfcoa_opt.sim.simulator import Simulator


class SpeedCap:
    """Toy filter: caps the speed; robot 0 'falls back' to stop at every 10th step."""

    name = "speed_cap"
    command = "velocity"

    def __init__(self, cap):
        self.cap, self.calls, self.kinds = cap, 0, []

    def reset(self, scenario, rng):
        self.calls = 0

    def filter(self, obs, nominal):
        self.kinds.append(nominal.shape)
        speed = np.hypot(*nominal.T)
        scale = np.minimum(1.0, self.cap / np.maximum(speed, 1e-12))
        out = nominal * scale[:, None]
        status = np.where(scale < 1.0, STATUS_MODIFIED, STATUS_OK).astype(np.int8)
        slack = np.zeros(obs.n)
        if self.calls % 10 == 0:
            out[0] = 0.0
            status[0], slack[0] = STATUS_FALLBACK, 0.5
        self.calls += 1
        return FilterResult(out, status, slack, np.full(obs.n, 1e-5))


def test_filtered_is_a_controller_and_its_statistics_are_logged():
    sc = scenario_from_dict({
        "t_max": 5.0, "world": {"size": [10.0, 6.0]}, "team": {"n": 4},
        "formation": {"width": 1.0, "length": 1.0},
        "leader": {"start": [2.0, 3.0], "goal": [9.0, 3.0], "speed": 0.3},
        "sensors": {"lidar": {"enabled": False}}}, "<t>")
    flt = SpeedCap(cap=0.25)
    ctrl = Filtered(GotoSlot(GotoSlot.Params(kp=2.0)), flt)
    assert ctrl.name == "goto_slot+speed_cap" and ctrl.command == "velocity"
    log = Simulator(sc, ctrl).run()
    assert np.all(np.hypot(*log.command.reshape(-1, 2).T) <= 0.25 + 1e-12)
    assert len(log.t) == 51  # instants 0, 0.1, ..., 5.0
    assert (log.filter_status == STATUS_FALLBACK).sum() == 6  # steps 0, 10, ..., 50
    assert log.filter_slack.max() == 0.5 and np.all(log.filter_time == 1e-5)
    m = summary(log, sc.spec.metrics)
    assert m["filter_fallbacks"] == 6
    assert m["filter_interventions"] == int((log.filter_status == STATUS_MODIFIED).sum()) > 0


def test_nominal_is_converted_to_the_filter_kind():
    class UniCtrl:
        name, command = "uni", "unicycle"

        def reset(self, scenario, rng):
            pass

        def act(self, obs):
            return np.column_stack((np.full(obs.n, 0.2), np.zeros(obs.n)))

    sc = scenario_from_dict({
        "t_max": 1.0, "world": {"size": [10.0, 6.0]}, "team": {"n": 4},
        "leader": {"start": [2.0, 3.0], "goal": [9.0, 3.0]},
        "sensors": {"lidar": {"enabled": False}}}, "<t>")
    flt = SpeedCap(cap=1.0)
    Simulator(sc, Filtered(UniCtrl(), flt)).run()
    assert flt.kinds[0] == (4, 3)  # (vx, vy, omega) from the unicycle adapter
