"""The learning environments: PettingZoo and gymnasium contracts, seeds, autoreset, dynamics."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import dfcoa_opt as d

# isort: split
import gymnasium as gym
from gymnasium.utils.env_checker import check_env
from gymnasium.utils.passive_env_checker import check_obs
from gymnasium.vector import AutoresetMode, VectorEnv
from pettingzoo.test import parallel_api_test, parallel_seed_test
from pettingzoo.test.state_test import test_parallel_env as parallel_state_test

from dfcoa_opt.control.adapters import convert
from dfcoa_opt.control.features import ObservationSpec
from dfcoa_opt.control.registry import make_controller
from dfcoa_opt.core.errors import DfcoaError
from dfcoa_opt.envs import OUTCOME_CODES, OUTCOME_NAMES, RewardSpec, parallel_env, vector_env
from dfcoa_opt.envs.rewards import path_arc_length
from dfcoa_opt.metrics import formation_centroid_error, formation_shape_error, summary
from dfcoa_opt.metrics.outcome import leader_path
from dfcoa_opt.planning.pure_pursuit import PurePursuit
from dfcoa_opt.sim.stall import formation_progress

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = [ROOT / "scenarios" / "example_obstacles.toml",
             ROOT / "scenarios" / "bench" / "corridor.toml",
             ROOT / "scenarios" / "bench" / "crossing.toml"]
IDS = [p.stem for p in SCENARIOS]
OPEN = ROOT / "scenarios" / "envs" / "open_4.toml"
D = ObservationSpec().size


def expert_actions(env, ctrl) -> np.ndarray:
    """``ctrl``'s command for the env's current observation, as the robots' own command kind."""
    obs = env.toolkit_observation
    cmd = convert(np.asarray(ctrl.act(obs), dtype=float), ctrl.command, env.core.kind, obs.pose,
                  obs.velocity, obs.dt, env.scenario.spec.robots.nid_distance)
    return cmd.reshape(-1, env.core.n, 2)


def drive(env, ctrl, seed: int):
    """Run one episode of a parallel env with a controller; its log, rewards and last info."""
    env.reset(seed=seed)
    st = env.core.stepper
    ctrl.reset_batch(st.sim.scenarios, st.rngs)
    rewards, info = [], {}
    while env.agents:
        cmd = expert_actions(env, ctrl)[0]
        _, rew, _, _, info = env.step({a: cmd[i] for i, a in enumerate(env.agents)})
        rewards.append(rew["robot_0"])
    return env.episode_log(), np.array(rewards), info["robot_0"]


class GotoThenStop:
    """``goto_slot`` for ``moving`` steps, then standing still: it stalls after moving."""

    name, command, uses_scan, batched = "goto_then_stop", "velocity", False, True

    def __init__(self, moving: int) -> None:
        self.inner, self.moving, self.k = make_controller("goto_slot"), moving, 0

    def reset_batch(self, scenarios, rngs) -> None:
        self.k = 0

    def reset(self, scenario, rng) -> None:
        self.k = 0

    def act(self, obs):
        self.k += 1
        cmd = self.inner.act(obs)
        return cmd if self.k <= self.moving else np.zeros_like(cmd)


SAME_LOG = ("pose", "pose_est", "velocity", "twist", "slots", "leader", "clearance",
            "robot_contacts", "obstacle_contacts", "dynamic_contacts", "collision_events", "t")


def assert_same_run(log, ref) -> None:
    for name in SAME_LOG:
        a, b = getattr(log, name), getattr(ref, name)
        assert a.shape == b.shape and a.tobytes() == b.tobytes(), name


# ------------------------------------------------------------------ import, API checks
def test_importing_the_package_imports_neither_gymnasium_nor_pettingzoo():
    code = ("import sys, dfcoa_opt, dfcoa_opt.envs\nfrom dfcoa_opt.envs import RewardSpec\n"
            "RewardSpec()\nassert 'gymnasium' not in sys.modules and 'pettingzoo' not in "
            "sys.modules, sorted(m for m in sys.modules if 'gym' in m or 'petting' in m)\n")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT)


@pytest.mark.parametrize("path", SCENARIOS, ids=IDS)
def test_parallel_env_passes_pettingzoos_api_test(path):
    env = parallel_env(path, seed=3, t_max=5.0)
    parallel_api_test(env, num_cycles=200)
    parallel_seed_test(lambda: parallel_env(path, t_max=5.0), num_cycles=100)
    parallel_state_test(env, seed=2)
    obs, _ = env.reset(seed=1)
    assert env.possible_agents == [f"robot_{i}" for i in range(env.core.n)]
    for _ in range(5):
        for a in env.agents:
            assert obs[a] in env.observation_space(a) and obs[a].dtype == np.float64
        obs, *_ = env.step({a: env.action_space(a).sample() for a in env.agents})
    assert env.state().shape == env.state_space.shape


def test_action_box_is_the_robot_models_command_within_its_limits():
    uni = parallel_env(SCENARIOS[0])
    box = uni.action_space("robot_0")
    robots = uni.scenario.spec.robots
    assert uni.core.kind == "unicycle"
    assert box.low.tolist() == [robots.v_lower, -robots.w_max]
    assert box.high.tolist() == [robots.v_max, robots.w_max]
    vel = parallel_env(SCENARIOS[0], robots__model="single_integrator")
    assert vel.core.kind == "velocity" and vel.action_space("robot_0").high.tolist() == [0.6, 0.6]
    acc = parallel_env(SCENARIOS[0], robots__model="double_integrator", robots__a_max=0.8)
    assert acc.core.kind == "acceleration"
    assert acc.action_space("robot_0").low.tolist() == [-0.8, -0.8]
    space = uni.observation_space("robot_0")
    lay = ObservationSpec().layout()
    assert space.shape == (D,)
    assert np.all(space.low[lay["lidar"]] == 0.0) and np.all(space.high[lay["lidar"]] == 1.0)
    assert np.all(space.high[lay["heading"]] == 1.0)
    assert np.isinf(space.high[lay["slot"]]).all()
    present = np.r_[lay["neighbours"]][4::5]
    assert space.low[present].tolist() == [0.0] * 4 and space.high[present].tolist() == [1.0] * 4


def test_the_env_runs_its_scenario_with_the_episode_end_settings():
    sc = d.load(OPEN)
    env = parallel_env(sc, t_max=12.0)
    spec = env.scenario.spec
    assert spec.stop_on_collision and spec.stop_on_deadlock and spec.leader.wait_for_formation
    assert spec.t_max == 12.0 and not sc.spec.stop_on_collision  # the given one is unchanged
    assert parallel_env(env.scenario).scenario is env.scenario  # already so: as it is
    assert not vector_env(OPEN, stop_on_deadlock=False).scenario.spec.stop_on_deadlock


class OneTeam(gym.Env):
    """Sub-environment 0 of a one-slot vector env as a gymnasium Env (for ``check_env``)."""

    metadata = {"render_modes": []}

    def __init__(self, path: Path) -> None:
        self.venv = vector_env(path, num_envs=1, t_max=5.0)
        self.observation_space = self.venv.single_observation_space
        self.action_space = self.venv.single_action_space

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        obs, info = self.venv.reset(seed=seed)
        return obs[0], {"seed": int(info["seed"][0])}

    def step(self, action):
        obs, rew, term, trunc, _ = self.venv.step(np.asarray(action)[None])
        return obs[0], float(rew[0]), bool(term[0]), bool(trunc[0]), {}


@pytest.mark.filterwarnings("ignore:.*infinity:UserWarning",
                            "ignore:.*symmetric and normalized:UserWarning")
@pytest.mark.parametrize("path", SCENARIOS, ids=IDS)
def test_one_sub_environment_passes_gymnasiums_env_checker(path):
    check_env(OneTeam(path), skip_render_check=True)


@pytest.mark.parametrize("path", SCENARIOS, ids=IDS)
def test_vector_env_keeps_the_vector_env_contract(path):
    e = 3
    env = vector_env(path, num_envs=e, seed=5, t_max=2.0)
    assert isinstance(env, VectorEnv) and env.num_envs == e
    assert env.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    n = env.core.n
    assert env.single_observation_space.shape == (n, D)
    assert env.observation_space.shape == (e, n, D)
    assert env.single_action_space.shape == (n, 2) and env.action_space.shape == (e, n, 2)
    assert env.observation_space.dtype == env.action_space.dtype == np.float64
    obs, info = env.reset(seed=5)
    check_obs(obs, env.observation_space, "reset")
    assert info["seed"].tolist() == [5, 6, 7] and info["_seed"].all()
    env.action_space.seed(0)
    ended = 0
    for _ in range(25):  # t_max 2 s: 21 instants, every sub-env ends and starts again
        obs, rew, term, trunc, info = env.step(env.action_space.sample())
        check_obs(obs, env.observation_space, "step")
        assert rew.shape == (e,) and rew.dtype == np.float64 and np.all(np.isfinite(rew))
        assert term.shape == trunc.shape == (e,) and term.dtype == trunc.dtype == np.bool_
        assert not np.any(term & trunc)
        if term.any() or trunc.any():
            assert info["_outcome"].tolist() == (term | trunc).tolist()
            ended += int((term | trunc).sum())
    assert ended >= e
    assert env.episode_seeds().min() >= 5 + e  # every sub-env is in its second episode


def test_infos_have_the_same_numeric_keys_at_the_reset_and_every_step():
    """torchrl builds its info spec from the reset's infos: no key may appear later."""
    env = parallel_env(OPEN, t_max=2.0)
    _, infos = env.reset(seed=3)
    seen = [infos]
    while env.agents:
        *_, infos = env.step({a: env.action_space(a).sample() for a in env.agents})
        seen.append(infos)
    for infos in seen:
        for info in infos.values():
            assert sorted(info) == ["outcome", "seed", "t"]
            assert all(isinstance(v, (int, float)) for v in info.values())
    assert [i["robot_0"]["outcome"] for i in seen[:-1]] == [0] * (len(seen) - 1)
    assert OUTCOME_NAMES[seen[-1]["robot_1"]["outcome"]] == summary(env.episode_log())["outcome"]
    assert seen[-1]["robot_0"]["t"] == env.episode_log().t[-1] and seen[-1]["robot_0"]["seed"] == 3
    assert OUTCOME_NAMES == ("running", "success", "collision", "deadlock", "timeout")
    assert all(OUTCOME_NAMES[code] == name for name, code in OUTCOME_CODES.items())
    venv = vector_env(OPEN, num_envs=2, t_max=2.0)
    _, infos = venv.reset(seed=0)
    keys = sorted(infos)
    ends = 0
    for _ in range(30):
        *_, term, trunc, infos = venv.step(venv.action_space.sample())
        assert sorted(infos) == keys == ["_outcome", "_seed", "_t", "outcome", "seed", "t"]
        assert all(infos[k].shape == (2,) and infos[k].dtype.kind in "bif" for k in keys)
        assert ((infos["outcome"] != 0) == (term | trunc)).all()
        assert (infos["outcome"][term | trunc] == OUTCOME_CODES["timeout"]).all()  # 2 s, no end
        ends += int((term | trunc).sum())
    assert ends == 2


def whole_episode(env, seed: int) -> list:
    """Every observation, reward, flag and info of one episode, with seeded random actions."""
    obs, infos = env.reset(seed=seed)
    for a in env.possible_agents:
        env.action_space(a).seed(seed)
    out = [obs, infos]
    while env.agents:
        out.extend(env.step({a: env.action_space(a).sample() for a in env.agents}))
    return out


def same(a, b) -> bool:
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    return np.asarray(a).dtype == np.asarray(b).dtype and np.asarray(a).tobytes() == \
        np.asarray(b).tobytes()


def test_the_same_seed_gives_the_same_whole_parallel_episode():
    """Whole episodes to their end (pettingzoo 1.27's parallel_seed_test stops after one step)."""
    path = ROOT / "scenarios" / "bench" / "clutter.toml"  # the world is drawn from the seed
    a, b = (whole_episode(parallel_env(path, t_max=3.0), 7) for _ in range(2))
    c = whole_episode(parallel_env(path, t_max=3.0), 8)
    assert len(a) == len(b) > 100 and all(same(x, y) for x, y in zip(a, b, strict=True))
    assert not all(same(x, y) for x, y in zip(a, c, strict=False))


# ------------------------------------------------------------------ seeds, autoreset
def rollout(env, steps: int, seed: int) -> list[np.ndarray]:
    env.action_space.seed(seed)
    obs, _ = env.reset(seed=seed)
    out = [obs]
    for _ in range(steps):
        obs, rew, term, trunc, _ = env.step(env.action_space.sample())
        out += [obs, rew, term, trunc]
    return out


def test_the_same_seed_gives_the_same_episodes_bit_for_bit():
    def run(seed):
        return rollout(vector_env(OPEN, num_envs=4, t_max=3.0), 70, seed)  # ends, restarts

    a, b, c = run(11), run(11), run(12)
    assert all(x.dtype == y.dtype and x.tobytes() == y.tobytes() for x, y in zip(a, b, strict=True))
    assert any(x.tobytes() != y.tobytes() for x, y in zip(a, c, strict=True))
    env = parallel_env(SCENARIOS[2], t_max=3.0)
    runs = []
    for _ in range(2):
        obs, _ = env.reset(seed=4)
        seq = [obs["robot_0"]]
        while env.agents:
            obs, rew, *_ = env.step({a: np.array([0.3, 0.1]) for a in env.agents})
            seq += [obs["robot_2"], np.array([rew["robot_1"]])]
        runs.append(np.concatenate(seq))
    assert runs[0].tobytes() == runs[1].tobytes()
    env.reset(seed=4)
    assert env.reset()[1]["robot_0"]["seed"] == 5  # without a seed: the next one


def test_each_sub_env_is_the_parallel_env_of_its_seed_bit_for_bit():
    venv = vector_env(SCENARIOS[2], num_envs=3, seed=20)
    obs, _ = venv.reset()
    steps = 40
    acts = [np.tile([0.3, 0.2 * np.sin(0.3 * k)], (3, venv.core.n, 1)) for k in range(steps)]
    vobs, vrew = [obs], []
    for a in acts:
        obs, rew, term, trunc, _ = venv.step(a)
        assert not (term | trunc).any()
        vobs.append(obs)
        vrew.append(rew)
    for i in range(3):
        env = parallel_env(SCENARIOS[2])
        o, _ = env.reset(seed=20 + i)
        assert np.stack([o[a] for a in env.agents]).tobytes() == vobs[0][i].tobytes()
        for k, a in enumerate(acts):
            o, r, *_ = env.step({ag: a[i, j] for j, ag in enumerate(env.agents)})
            assert np.stack([o[ag] for ag in env.agents]).tobytes() == vobs[k + 1][i].tobytes()
            assert r["robot_0"] == vrew[k][i]


def collide_sub_env_0(n: int, k: int) -> np.ndarray:
    """Sub-env 0: robot 1 drives into robot 0 ahead of it; sub-env 1 follows the leader."""
    act = np.zeros((2, n, 2))
    act[0, 1] = [0.6, 0.0]
    act[1, :, 0] = 0.3
    return act


@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
def test_a_sub_env_that_ends_starts_its_next_episode_while_the_other_goes_on(mode):
    env = vector_env(OPEN, num_envs=2, seed=100, autoreset_mode=mode)
    n = env.core.n
    obs, _ = env.reset()
    fresh = parallel_env(OPEN)
    reset_obs = np.stack(list(fresh.reset(seed=102)[0].values()))  # episode 1 of sub-env 0
    for k in range(100):
        prev = obs
        obs, rew, term, trunc, info = env.step(collide_sub_env_0(n, k))
        if term[0]:
            break
    else:
        pytest.fail("sub-env 0 did not collide")
    assert not term[1] and not trunc[1] and rew[0] < -RewardSpec().contact + 1.0
    if mode == AutoresetMode.NEXT_STEP:
        assert info["outcome"][0] == OUTCOME_CODES["collision"]
        assert info["_outcome"].tolist() == [True, False]
        assert obs[0].tobytes() == prev[0].tobytes()  # the final observation
        log = env.episode_log(0)
        assert log.meta["seed"] == 100 and summary(log)["outcome"] == "collision"
        obs, rew, term, trunc, info = env.step(collide_sub_env_0(n, k + 1))
        assert rew[0] == 0.0 and not term[0] and not trunc[0]
    else:
        assert info["final_info"]["outcome"][0] == OUTCOME_CODES["collision"]
        assert info["final_info"]["seed"][0] == 100 and info["outcome"][0] == 0
        assert info["_final_obs"].tolist() == [True, False]
        assert info["final_obs"][0].tobytes() == prev[0].tobytes()
    assert info["seed"][0] == 102 and info["_seed"].tolist() == [True, False]
    assert obs[0].tobytes() == reset_obs.tobytes()
    assert env.core.stepper.k.tolist() == [0, k + 2 if mode == AutoresetMode.NEXT_STEP else k + 1]
    for _ in range(5):  # both go on
        obs, rew, term, trunc, _ = env.step(np.tile([0.3, 0.0], (2, n, 1)))
        assert not (term | trunc).any()
    assert env.core.stepper.k[0] == 5


# ------------------------------------------------------------------ dynamics and reward
@pytest.mark.parametrize("path", SCENARIOS, ids=IDS)
def test_goto_slot_through_the_env_gives_the_runs_trajectory(path):
    env = parallel_env(path, t_max=40.0)  # goto_slot hits a wall, a disc or an obstacle
    log, _, info = drive(env, make_controller("goto_slot"), seed=6)
    ref = d.run(env.scenario, "goto_slot", seed=6)
    assert_same_run(log, ref.log)
    name = OUTCOME_NAMES[info["outcome"]]
    assert name == ref.metrics["outcome"] == summary(log)["outcome"] == "collision"


def test_goto_slot_through_the_vector_env_gives_each_seeds_runs_across_autoresets():
    """Clutter drawn per seed: runs end apart, restart mid-batch, each world its own path."""
    venv = vector_env(ROOT / "scenarios" / "bench" / "clutter.toml", num_envs=3, seed=30,
                      t_max=40.0)
    venv.reset()
    ctrl = make_controller("goto_slot")
    logs = {}
    while len(logs) < 6:
        act = np.zeros((3, venv.core.n, 2))
        if venv.toolkit_observation is not None:
            act[np.unique(venv.toolkit_observation.env)] = expert_actions(venv, ctrl)
        _, _, term, trunc, _ = venv.step(act)
        for i in np.flatnonzero(term | trunc):
            log = venv.episode_log(int(i))
            logs[log.meta["seed"]] = log
    assert sorted(logs) == list(range(30, 36))  # s + i + j E, for j = 0, 1
    assert len({len(log.t) for log in logs.values()}) > 1
    for seed, log in logs.items():
        assert_same_run(log, d.run(venv.scenario, "goto_slot", seed=seed).log)


@pytest.mark.parametrize("path", [OPEN, ROOT / "scenarios" / "bench" / "large_20.toml"],
                         ids=["open_4", "large_20"])
def test_a_stalled_run_ends_as_a_deadlock_at_the_instant_of_the_toolkits_monitor(path):
    env = parallel_env(path, t_max=40.0)
    log, rewards, info = drive(env, GotoThenStop(60), seed=2)
    ref = d.run(env.scenario, GotoThenStop(60), seed=2)
    assert OUTCOME_NAMES[info["outcome"]] == ref.metrics["outcome"] == "deadlock"
    assert_same_run(log, ref.log)
    assert len(rewards) == len(ref.log.t) > 100


def test_the_reward_is_the_toolkits_metrics_summed():
    w = {"formation": 0.0, "shape": 0.0, "progress": 0.0, "contact": 0.0, "success": 0.0}
    returns = {}
    for term in ("formation", "shape", "progress", "success"):
        env = parallel_env(OPEN, reward=RewardSpec(**{**w, term: 1.0}))
        log, rewards, info = drive(env, make_controller("goto_slot"), seed=1)
        returns[term] = rewards.sum()
    assert OUTCOME_NAMES[info["outcome"]] == "success"
    dt = env.scenario.spec.dt
    np.testing.assert_allclose(returns["formation"], -dt * formation_centroid_error(log).sum())
    np.testing.assert_allclose(returns["shape"], -dt * formation_shape_error(log).sum())
    prog = formation_progress(log.pose[..., :2], leader_path(log))
    np.testing.assert_allclose(returns["progress"], prog[-1] - prog[0], rtol=1e-12)
    assert returns["success"] == 1.0
    env = parallel_env(SCENARIOS[0], reward=RewardSpec(**{**w, "contact": 1.0}), t_max=60.0)
    _, rewards, info = drive(env, make_controller("goto_slot"), seed=2)
    assert OUTCOME_NAMES[info["outcome"]] == "collision"
    assert rewards.sum() == -1.0 and rewards[-1] == -1.0


def test_the_arc_length_is_pure_pursuits_bit_for_bit():
    rng = np.random.default_rng(0)
    for path in [*SCENARIOS, ROOT / "scenarios" / "dfcoa_s1.toml"]:
        leader = d.load(path).leader_path
        pts = rng.uniform(-2.0, 25.0, size=(500, 2))
        ref = PurePursuit(leader, 0.0, 0.0, 0.0).arc_length(pts)
        assert path_arc_length(leader, pts).tobytes() == ref.tobytes(), path.stem


# ------------------------------------------------------------------ bad input
def test_bad_input_is_refused_with_a_message():
    with pytest.raises(ValueError, match="formation"):
        RewardSpec(formation=-1.0)
    with pytest.raises(ValueError, match="not offered"):
        vector_env(OPEN, num_envs=2, autoreset_mode=AutoresetMode.DISABLED)
    env = parallel_env(OPEN)
    with pytest.raises(DfcoaError, match="reset"):
        env.step({})
    env.reset(seed=0)
    with pytest.raises(ValueError, match="robot_3"):
        env.step({a: np.zeros(2) for a in env.agents[:3]})
    with pytest.raises(ValueError, match="NaN"):
        env.step({a: np.full(2, np.nan) for a in env.agents})
    venv = vector_env(OPEN, num_envs=2)
    venv.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        venv.step(np.zeros((2, 4, 3)))
    with pytest.raises(ValueError, match=r"sub-environment\(s\) \[1\]"):
        venv.step(np.stack([np.zeros((4, 2)), np.full((4, 2), np.inf)]))
    with pytest.raises(ValueError, match="reset_mask"):
        venv.reset(options={"reset_mask": np.array([True, False])})
