"""Stable-Baselines3 over the batched environments: the VecEnv contract, seeds, PPO."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import dfcoa_opt  # noqa: F401  (first: caps numpy's SIMD dispatch)

# isort: split
pytest.importorskip("stable_baselines3")
import torch  # noqa: E402
from gymnasium.vector import AutoresetMode  # noqa: E402
from stable_baselines3 import PPO  # noqa: E402
from stable_baselines3.common.vec_env import VecEnv, VecMonitor  # noqa: E402

from dfcoa_opt.envs import OUTCOME_CODES, sb3_vec_env, vector_env  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
OPEN = ROOT / "scenarios" / "envs" / "open_4.toml"
OBSTACLES = ROOT / "scenarios" / "example_obstacles.toml"


def actions(k: int, shape: tuple[int, ...]) -> np.ndarray:
    """Deterministic actions that vary per step and robot (v m/s, omega rad/s)."""
    rows = np.arange(int(np.prod(shape[:-1]))).reshape(shape[:-1])
    return np.stack([0.2 + 0.1 * np.sin(0.3 * k + rows), 0.5 * np.cos(0.2 * k + rows)], axis=-1)


def test_it_is_the_vector_env_robot_by_robot_with_sb3s_done_contract():
    e, steps = 3, 45  # t_max 2 s: 21 instants, every team ends twice
    env = sb3_vec_env(OPEN, num_envs=e, seed=4, t_max=2.0)
    ref = vector_env(OPEN, num_envs=e, seed=4, t_max=2.0, autoreset_mode=AutoresetMode.SAME_STEP)
    n = env.robots
    assert isinstance(env, VecEnv) and env.num_envs == e * n
    assert env.observation_space.shape == (56,) and env.action_space.shape == (2,)
    obs = env.reset()
    robs, rinfo = ref.reset()
    assert obs.tobytes() == robs.reshape(e * n, -1).tobytes()
    assert [i["seed"] for i in env.reset_infos] == np.repeat([4, 5, 6], n).tolist()
    ends = 0
    for k in range(steps):
        act = actions(k, (e, n, 2))
        obs, rew, done, infos = env.step(act.reshape(e * n, 2))
        robs, rrew, term, trunc, rinfo = ref.step(act)
        assert obs.tobytes() == robs.reshape(e * n, -1).tobytes()
        assert rew.tolist() == np.repeat(rrew, n).tolist()
        assert done.tolist() == np.repeat(term | trunc, n).tolist()
        assert all(sorted(i) in (["outcome", "seed", "t"],
                                 ["TimeLimit.truncated", "outcome", "seed", "t",
                                  "terminal_observation"]) for i in infos)
        for t in np.flatnonzero(term | trunc):
            ends += 1
            for r in range(n):
                info = infos[t * n + r]
                assert info["terminal_observation"].tobytes() == \
                    rinfo["final_obs"][t][r].tobytes()
                assert info["outcome"] == OUTCOME_CODES["timeout"]
                assert info["TimeLimit.truncated"]
                assert info["seed"] == rinfo["final_info"]["seed"][t]
    assert ends == 2 * e


def test_every_team_runs_its_own_episode_seeds_and_seed_sets_them():
    e = 4
    env = sb3_vec_env(OPEN, num_envs=e, seed=0, t_max=1.0)
    assert env.seed(100) == np.repeat(np.arange(100, 104), env.robots).tolist()
    env.reset()
    ended = []
    for k in range(40):  # 11 instants per episode: 3 episodes of every team
        _, _, done, infos = env.step(actions(k, (env.num_envs, 2)))
        ended += [infos[i]["seed"] for i in np.flatnonzero(done)[::env.robots]]
    assert sorted(ended) == list(range(100, 100 + 3 * e))  # s + i + j E: no duplicates
    assert env.seed() == np.repeat(env.episode_seeds(), env.robots).tolist()


def test_vec_monitor_reports_each_robots_episode_return_and_length():
    env = VecMonitor(sb3_vec_env(OBSTACLES, num_envs=2, seed=1, t_max=1.5))
    env.reset()
    total = np.zeros(env.num_envs)
    length = np.zeros(env.num_envs, dtype=int)
    episodes = []
    for k in range(20):
        _, rew, done, infos = env.step(actions(k, (env.num_envs, 2)))
        total += rew
        length += 1
        for i in np.flatnonzero(done):
            episodes.append((infos[i]["episode"]["r"], infos[i]["episode"]["l"]))
            np.testing.assert_allclose(infos[i]["episode"]["r"], total[i], rtol=1e-6)
            assert infos[i]["episode"]["l"] == length[i] == 16
            total[i], length[i] = 0.0, 0
    assert len(episodes) == env.num_envs  # every robot of both teams, once


def train(path: Path, seed: int) -> PPO:
    env = VecMonitor(sb3_vec_env(path, num_envs=2, t_max=4.0))
    model = PPO("MlpPolicy", env, seed=seed, n_steps=64, batch_size=128, n_epochs=2,
                device="cpu")
    model.learn(total_timesteps=3 * 64 * env.num_envs)
    assert len(model.ep_info_buffer) > 0  # episodes ended and VecMonitor reported them
    return model


@pytest.mark.parametrize("path", [OPEN, OBSTACLES], ids=["open_4", "example_obstacles"])
def test_ppo_with_a_seed_trains_to_the_same_parameters(path):
    a, b, c = train(path, 0), train(path, 0), train(path, 1)
    pa, pb, pc = (list(m.policy.parameters()) for m in (a, b, c))
    assert all(torch.equal(x, y) for x, y in zip(pa, pb, strict=True))
    assert not all(torch.equal(x, y) for x, y in zip(pa, pc, strict=True))
    assert not all(torch.equal(x, y) for x, y in
                   zip(pa, PPO("MlpPolicy", a.env, seed=0, device="cpu").policy.parameters(),
                       strict=True))  # the training moved the parameters


def test_bad_options_and_actions_are_refused():
    with pytest.raises(ValueError, match="autoreset_mode"):
        sb3_vec_env(OPEN, autoreset_mode="NextStep")
    env = sb3_vec_env(OPEN, num_envs=2)
    env.reset()
    with pytest.raises(ValueError, match=r"expected \(8, 2\)"):
        env.step(np.zeros((2, 4, 2)))
