"""torchrl over the environments: PettingZooWrapper, torchrl_env, GymWrapper; ends, seeds, bits."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import dfcoa_opt  # noqa: F401  (first: caps numpy's SIMD dispatch)

# isort: split
pytest.importorskip("torchrl")
import torch  # noqa: E402
from gymnasium.vector import AutoresetMode  # noqa: E402
from tensordict import TensorDict  # noqa: E402
from torchrl.envs import GymWrapper, PettingZooWrapper  # noqa: E402
from torchrl.envs.utils import check_env_specs  # noqa: E402

from dfcoa_opt.control.features import ObservationSpec  # noqa: E402
from dfcoa_opt.core.errors import DfcoaError  # noqa: E402
from dfcoa_opt.envs import OUTCOME_CODES, parallel_env, torchrl_env, vector_env  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
OPEN = ROOT / "scenarios" / "envs" / "open_4.toml"
OBSTACLES = ROOT / "scenarios" / "example_obstacles.toml"
SCENARIOS = [pytest.param(OPEN, id="open_4"), pytest.param(OBSTACLES, id="example_obstacles")]
T_MAX = 3.0  # s: 31 instants, so an episode that times out takes 30 steps
NEIGHBOURS = ObservationSpec().layout()["neighbours"]
COLLISION, TIMEOUT = OUTCOME_CODES["collision"], OUTCOME_CODES["timeout"]


def chase_or_random(env, seed_of):
    """A policy: in an episode of even seed every robot drives at its nearest neighbour
    (a collision within about a second), in one of odd seed random actions (a timeout).
    ``seed_of(td)`` is the episode seed, shaped to broadcast over ``[..., N, 2]``."""
    spec = env.full_action_spec["robot", "action"]
    low, high = spec.space.low, spec.space.high

    def policy(td):
        nb = td["robot", "observation"][..., NEIGHBOURS]  # nearest first: x, y (robot frame)
        turn = (3.0 * torch.atan2(nb[..., 1], nb[..., 0])).clamp(low[..., 1], high[..., 1])
        chase = torch.stack([high[..., 0], turn], dim=-1)
        td["robot", "action"] = torch.where(seed_of(td) % 2 == 0, chase, spec.rand())
        return td

    return policy


def check_outcomes(outcome, done, terminated, truncated):
    """Outcome codes where episodes end, 0 elsewhere, and the end flags of each code."""
    assert (outcome[~done] == 0).all()
    assert (outcome[done] != 0).all()
    assert (terminated == (done & (outcome != TIMEOUT))).all()
    assert (truncated == (outcome == TIMEOUT)).all()
    assert {COLLISION, TIMEOUT} <= set(outcome[done].tolist())


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_pettingzoo_wrapper_runs_parallel_env_through_episode_ends(scenario):
    def make():
        return PettingZooWrapper(parallel_env(scenario, t_max=T_MAX), use_mask=True,
                                 categorical_actions=False, seed=0)

    check_env_specs(make())
    env = make()
    torch.manual_seed(0)
    steps = 110
    r = env.rollout(steps, chase_or_random(env, lambda td: td["robot", "info", "seed"][0]),
                    break_when_any_done=False)
    assert r.batch_size == (steps,) and r["robot", "observation"].dtype == torch.float64
    done = r["next", "done"][:, 0].numpy()
    ends = np.flatnonzero(done)
    assert len(ends) >= 3
    info, nxt = r["robot", "info"], r["next", "robot", "info"]
    outcome = nxt["outcome"].numpy().astype(int)  # [T, N]: every robot has its team's
    assert (outcome == outcome[:, :1]).all()
    check_outcomes(outcome[:, 0], done, r["next", "terminated"][:, 0].numpy(),
                   r["next", "truncated"][:, 0].numpy())
    for k in ends[ends + 1 < steps]:  # the next row is the next episode's reset
        assert (info["t"][k + 1] == 0).all()
        assert (info["seed"][k + 1] == info["seed"][k] + 1).all()

    # parallel_env driven directly with the rollout's actions gives the same bits
    ref = parallel_env(scenario, t_max=T_MAX)
    obs, _ = ref.reset(seed=int(info["seed"][0, 0]))
    agents = ref.possible_agents
    for k in range(steps):
        assert np.stack([obs[a] for a in agents]).tobytes() == \
            r["robot", "observation"][k].numpy().tobytes()
        act = r["robot", "action"][k].numpy()
        obs, rew, _, _, inf = ref.step({a: act[i] for i, a in enumerate(agents)})
        assert np.stack([obs[a] for a in agents]).tobytes() == \
            r["next", "robot", "observation"][k].numpy().tobytes()
        assert np.float32(rew["robot_0"]) == r["next", "robot", "reward"][k, 0, 0].item()
        assert inf["robot_0"]["outcome"] == outcome[k, 0]
        assert bool(done[k]) == (not ref.agents)
        if done[k]:
            obs, _ = ref.reset()


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_torchrl_env_is_the_vector_env_with_torchrls_partial_resets(scenario):
    e, s, steps = 3, 5, 100
    env = torchrl_env(scenario, num_envs=e, t_max=T_MAX)
    check_env_specs(env)
    env.set_seed(s)  # the next reset: sub-environment i runs seed s + i
    torch.manual_seed(0)
    policy = chase_or_random(env, lambda td: td["info", "seed"][:, None, None])
    r = env.rollout(steps, policy, break_when_any_done=False)
    assert r.batch_size == (e, steps)
    assert r["robot", "observation"].shape == (e, steps, env.venv.core.n, 56)
    assert r["robot", "observation"].dtype == torch.float64
    done = r["next", "done"][..., 0].numpy()
    assert (done.sum(axis=1) >= 3).all()
    partial = done.any(axis=0) & ~done.all(axis=0)
    assert partial.any()  # some steps reset some sub-environments only
    info, nxt = r["info"], r["next", "info"]
    outcome = nxt["outcome"].numpy()
    check_outcomes(outcome, done, r["next", "terminated"][..., 0].numpy(),
                   r["next", "truncated"][..., 0].numpy())
    # sub-environment i, episode j: seed s + i + j E; a new episode's row starts at t = 0
    episode = np.concatenate([np.zeros((e, 1), int), np.cumsum(done, axis=1)[:, :-1]], axis=1)
    want = s + np.arange(e)[:, None] + episode * e
    assert (info["seed"].numpy() == want).all() and (nxt["seed"].numpy() == want).all()
    # a step scores its episode's instant k dt; a new episode's first row is its reset (t 0)
    start = np.concatenate([np.ones((e, 1), bool), done[:, :-1]], axis=1)
    k = np.arange(steps) - np.maximum.accumulate(np.where(start, np.arange(steps), 0), axis=1)
    t, t_next = info["t"].numpy(), nxt["t"].numpy()
    assert (t_next == k * env.scenario.spec.dt).all()
    going = ~start[:, 1:]
    assert (t[start] == 0).all() and (t[:, 1:][going] == t_next[:, :-1][going]).all()

    # the vector environment driven directly with the rollout's actions gives the same bits
    ref = vector_env(scenario, num_envs=e, t_max=T_MAX, autoreset_mode=AutoresetMode.SAME_STEP)
    obs, _ = ref.reset(seed=s)
    for k in range(steps):
        assert obs.tobytes() == r["robot", "observation"][:, k].numpy().tobytes()
        obs, rew, term, trunc, inf = ref.step(r["robot", "action"][:, k].numpy())
        last = obs.copy()
        for i in np.flatnonzero(term | trunc):
            last[i] = inf["final_obs"][i]
        assert last.tobytes() == r["next", "robot", "observation"][:, k].numpy().tobytes()
        reward = r["next", "robot", "reward"][:, k, :, 0].numpy()
        assert (reward == rew[:, None]).all()
        assert ((term | trunc) == done[:, k]).all()

    # a new rollout starts every sub-environment's next episode, also after an end of some
    # at the last step (whose next episode had started in its slot)
    r2 = env.rollout(steps, policy, break_when_any_done=True)  # stops at the first end
    first = s + np.arange(e) + (done.sum(axis=1) + 1) * e
    assert (r2["info", "seed"][:, 0].numpy() == first).all()
    assert r2["next", "done"][:, -1].any() and not r2["next", "done"][:, -1].all()
    assert (env.rollout(2)["info", "seed"][:, 0].numpy() == first + e).all()


def test_torchrl_env_restarts_only_ended_sub_environments_alone():
    env = torchrl_env(OPEN, num_envs=2, seed=3, t_max=T_MAX)
    first = env.reset()
    assert first["info", "seed"].tolist() == [3, 4]
    with pytest.raises(DfcoaError, match="cannot restart while running"):
        env.reset(TensorDict({"_reset": torch.tensor([[True], [False]])}, batch_size=[2]))
    again = env.reset(TensorDict({"_reset": torch.ones(2, 1, dtype=torch.bool)}, batch_size=[2]))
    assert again["info", "seed"].tolist() == [5, 6]  # every sub-environment's next episode


def test_gym_wrapper_takes_the_vector_env_with_same_step_autoreset():
    env = GymWrapper(vector_env(OPEN, num_envs=2, t_max=2.0,
                                autoreset_mode=AutoresetMode.SAME_STEP))
    check_env_specs(env)
    r = env.rollout(45, break_when_any_done=False)  # 21 instants: 2 ends per sub-environment
    assert r["observation"].shape == (2, 45, 4, 56) and r["observation"].dtype == torch.float64
    assert r["next", "done"].sum().item() == 4
    with pytest.raises(RuntimeError, match="SAME_STEP"):  # torchrl takes no NEXT_STEP
        GymWrapper(vector_env(OPEN, num_envs=2, t_max=2.0))


def test_importing_the_environments_does_not_import_torch():
    code = ("import sys, dfcoa_opt.envs as e; e.OUTCOME_CODES; "
            "assert 'torch' not in sys.modules and 'torchrl' not in sys.modules")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT)
