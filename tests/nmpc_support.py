"""Shared by the ``nmpc`` tests: a small open-field scenario, a reset controller, a
hand-made observation and a monkeypatch that makes every solve fail."""

import math
from pathlib import Path

import numpy as np

import comparisons.nmpc.compiled as nmpc_compiled
import comparisons.nmpc.problem as nmpc_problem
from dfcoa_opt.control.base import MovingObstacles, Observation
from dfcoa_opt.control.registry import make_controller
from dfcoa_opt.scenario.loader import scenario_from_dict
from tests.helpers import neighbours_from_lists

ROOT = Path(__file__).resolve().parents[1]
R = 0.2  # robot radius, m


def scenario(n=1, poses=None, offsets=((0.0, 0.0),), obstacles=(), humans=(), t_max=10.0,
             leader=None, **extra):
    """A small open field; the leader goes +x at 0.3 m/s from (2, 5)."""
    team = {"n": n} if poses is None else {"n": n, "placement": "explicit", "poses": poses}
    data = {
        "name": "nmpc_test", "dt": 0.1, "t_max": t_max, "seed": 1,
        "world": {"size": [20.0, 10.0], "resolution": 10, "obstacles": list(obstacles),
                  "dynamic_obstacles": list(humans)},
        "robots": {"radius": R, "v_max": 0.6, "w_max": 2.0, **extra.pop("robots", {})},
        "team": team,
        "formation": {"shape": "offsets", "offsets": [list(o) for o in offsets]},
        "leader": leader or {"start": [2.0, 5.0], "goal": [18.0, 5.0], "speed": 0.3,
                             "wait_for_formation": False},
        "sensors": {"lidar": {"enabled": False}, "obstacle_range": 5.0},
        **extra,
    }
    return scenario_from_dict(data, "<nmpc>")


def controller(sc, **params):
    c = make_controller("nmpc", params)
    c.reset(sc, np.random.default_rng(0))
    return c


def observation(pose, slot, t=0.0, leader=(0.0, 0.0, 0.0, 0.0, 0.0), lists=None, offsets=None,
                humans=()):
    """A hand-made observation; ``lists[i]`` = robot i's neighbours."""
    pose = np.asarray(pose, dtype=float).reshape(-1, 3)
    n = len(pose)
    nb = neighbours_from_lists(pose[:, :2], np.zeros((n, 2)), lists or [[] for _ in range(n)])
    m = max(len(humans), 1)
    hp, hv, hr = np.zeros((n, m, 2)), np.zeros((n, m, 2)), np.zeros((n, m))
    hm = np.zeros((n, m), dtype=bool)
    for j, (p, v, r) in enumerate(humans):
        hp[:, j], hv[:, j], hr[:, j], hm[:, j] = p, v, r, True
    slot = np.asarray(slot, dtype=float).reshape(n, 2)
    leader = np.asarray(leader, dtype=float)
    if offsets is None:  # offsets consistent with the slots and the leader
        c, s = math.cos(leader[2]), math.sin(leader[2])
        rel = slot - leader[:2]
        offsets = np.column_stack((c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1]))
    return Observation(t, 0.1, np.arange(n), pose, np.zeros((n, 2)), np.zeros((n, 2)), None,
                       nb, MovingObstacles(hp, hv, hr, hm), leader, np.zeros(2),
                       np.asarray(offsets, float), slot)


def break_every_solver(monkeypatch):
    """Every solve fails: the interpreted solvers raise, the compiled ones flag an error."""
    def broken(self, *args, **kwargs):
        raise RuntimeError("forced")

    def flagged(self, z):
        return np.full((len(z), self.n_out), np.nan), np.ones(len(z), np.intc), np.zeros(len(z))

    monkeypatch.setattr(nmpc_problem.NmpcProblem, "_interpreted", broken)
    monkeypatch.setattr(nmpc_compiled.CompiledFunction, "__call__", broken)
    monkeypatch.setattr(nmpc_compiled.CompiledFunction, "batch", flagged)
