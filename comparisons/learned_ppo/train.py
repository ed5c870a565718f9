"""Train ``learned_ppo``: PPO (Stable-Baselines3) on the batched environments, from reward.

Usage::

    python -m comparisons.learned_ppo.train --seed 0 --out comparisons/learned_ppo/

writes ``learned_ppo.json`` and ``learned_ppo.npz`` (a ``policy:PATH`` file,
``docs/policies.md``) and ``curve.csv`` (the learning curve), the same bytes
for the same seed on the same machine kind (``docs/methods/learned.md``).

Every robot is one SB3 environment (:func:`dfcoa_opt.envs.sb3_vec_env`), so
one network is shared by all robots. The stages of :data:`CURRICULUM` run one
after the other on the same network; each stage's environments are built from
its scenarios, with E teams each. The policy acts in ``[-1, 1]^2``: a
body-frame velocity of :data:`ACTION_SCALE` m/s per unit, turned into the
unicycle's ``(v, omega)`` as the simulator does for any velocity controller
(:class:`~comparisons.learned_ppo.vec.BodyVelocity`); the exported file
carries that map as ``command``, ``frame``, ``action_scale`` and ``clip``
(SB3's deterministic action is the Gaussian's mean clipped to the box).
"""

from __future__ import annotations

import dfcoa_opt  # noqa: F401 - first: pins numpy's SIMD and OpenBLAS kernels (dispatch.py)

# isort: split
import argparse
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

from dfcoa_opt.control.features import ObservationSpec
from dfcoa_opt.envs.core import OUTCOME_CODES
from dfcoa_opt.envs.rewards import RewardSpec

ROOT = Path(__file__).resolve().parents[2]
#: The observation vector: 40 LiDAR beams, 4 neighbours, 2 moving obstacles (as ``learned``).
SPEC = ObservationSpec(beams=40, neighbours=4, obstacles=2, range=5.0, v_max=0.5)
#: Stage ``i``'s episodes start at seed ``TRAIN_SEED0 + SEED_STRIDE * i``: never an
#: evaluation seed (0-19) and, below 10 000, inside the held-out worlds' training split.
TRAIN_SEED0 = 1000
SEED_STRIDE = 2000
#: The start noise of ``learned``'s training and of the target evaluation.
NOISY = {"team.start_noise": 0.3, "team.heading_noise": 0.6}
#: The reward (``docs/envs.md``): each way to end an episode early costs more than the
#: formation terms of staying in it, so ending it is never the cheap way out.
REWARD = RewardSpec(formation=1.0, shape=1.0, progress=2.0, contact=50.0, success=50.0,
                    deadlock=50.0)
#: Network output 1 is this many m/s (body frame, x forward, y left), as ``learned``'s.
ACTION_SCALE = 0.5
#: Training-only shaping (:class:`~comparisons.learned_ppo.vec.Shaping`): 1/(m s), per step, m.
SHAPING = {"slot": 2.0, "clearance": 0.5, "margin": 0.5}


@dataclass(frozen=True)
class Stage:
    """One curriculum stage.

    Attributes:
        steps: Robot steps (SB3 timesteps) of the stage.
        scenarios: ``(scenario file, overrides)`` of its environments.
        teams: E, the teams per scenario.
    """

    steps: int
    scenarios: tuple[tuple[str, dict[str, Any]], ...]
    teams: int = 16


#: The shipped curriculum: hold the slots in the open, then the target and the
#: ``learned`` baseline's training scenarios.
CURRICULUM: tuple[Stage, ...] = (
    Stage(1_600_000, (("scenarios/envs/open_4.toml", NOISY),)),
    Stage(14_000_000, (("scenarios/example_obstacles.toml", NOISY),
                      ("scenarios/learned/clutter_rect.toml", {}),
                      ("scenarios/learned/wall_gap.toml", {}))),
)


@dataclass(frozen=True)
class Budget:
    """How to train.

    Attributes:
        curriculum: The stages.
        hidden: Hidden layer widths (tanh) of the actor and of the critic.
        n_steps: Steps per rollout and SB3 environment (robot).
        batch: Minibatch rows.
        epochs: Passes over each rollout.
        lr: Adam step size.
        gamma: Discount per step (dt = 0.1 s).
        log_std: Initial log standard deviation of the actions (unit box).
        t_max: Cap on each episode's duration, s (None: the scenario's).
    """

    curriculum: tuple[Stage, ...] = field(default=CURRICULUM)
    hidden: tuple[int, ...] = (64, 64)
    n_steps: int = 128
    batch: int = 2048
    epochs: int = 5
    lr: float = 3e-4
    gamma: float = 0.99
    log_std: float = -0.5
    t_max: float | None = None


#: The budget of the shipped weights.
FULL = Budget()
#: A few seconds (tests): two tiny stages.
TINY = Budget(curriculum=(Stage(2_048, (("scenarios/envs/open_4.toml", NOISY),), teams=2),
                          Stage(2_048, (("scenarios/example_obstacles.toml", NOISY),), teams=2)),
              hidden=(8,), n_steps=64, batch=128, epochs=2, t_max=4.0)


def make_env(stage: Stage, index: int, budget: Budget) -> Any:
    """Stage ``index``'s environments: every robot of every team, actions in ``[-1, 1]``.

    ``VecNormalize`` scales the rewards by a running estimate of the return's
    standard deviation (not the observations: the policy file reads them as
    they are).
    """
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    from comparisons.learned_ppo.vec import BodyVelocity, Concat, Shaping
    from dfcoa_opt.envs import sb3_vec_env

    keys = {} if budget.t_max is None else {"t_max": budget.t_max}
    seed = TRAIN_SEED0 + SEED_STRIDE * index
    parts = [BodyVelocity(sb3_vec_env(ROOT / path, num_envs=stage.teams, seed=seed,
                                      observation=SPEC, reward=REWARD,
                                      **{k.replace(".", "__"): v
                                         for k, v in {**over, **keys}.items()}), ACTION_SCALE)
             for path, over in stage.scenarios]
    specs = [p.venv.venv.scenario.spec for p in parts]
    if len({(s.robots.radius, s.dt) for s in specs}) > 1:
        raise ValueError("the stage's scenarios need one robot radius and one dt (the shaping)")
    range_max = np.repeat([s.sensors.lidar.range_max for s in specs],
                          [p.num_envs for p in parts])
    shaped = Shaping(VecMonitor(Concat(parts, seed)), SPEC.layout(), SPEC.range, range_max,
                     specs[0].robots.radius, specs[0].dt, **SHAPING)
    return VecNormalize(shaped, norm_obs=False, norm_reward=True, gamma=budget.gamma)


class Curve(BaseCallback):
    """The learning curve: per rollout, the episodes that ended, their return and outcomes.

    Each robot is an SB3 environment, so an episode of a team of N robots counts
    N times (its robots' returns are equal: the team's reward). Row keys:
    ``stage``, ``steps`` (robot steps so far), ``episodes``, ``return`` (mean
    undiscounted return), the share of each outcome, ``seconds`` (wall).

    Args:
        stage: The curriculum stage.
        rows: The list the rows are appended to.
        t0: ``time.perf_counter()`` at the start of the training.
        quiet: No progress lines.
    """

    def __init__(self, stage: int, rows: list[dict[str, float]], t0: float,
                 quiet: bool) -> None:
        super().__init__()
        self.stage, self.rows, self.t0, self.quiet = stage, rows, t0, quiet
        self.returns: list[float] = []
        self.outcomes: list[int] = []

    def _on_rollout_start(self) -> None:
        self.returns, self.outcomes = [], []

    def _on_step(self) -> bool:
        for info, done in zip(self.locals["infos"], self.locals["dones"], strict=True):
            if done:
                self.outcomes.append(int(info["outcome"]))
                self.returns.append(float(info["episode"]["r"]))
        return True

    def _on_rollout_end(self) -> None:
        codes = np.array(self.outcomes, dtype=int)
        row = {"stage": float(self.stage), "steps": float(self.num_timesteps),
               "episodes": float(len(codes)),
               "return": float(np.mean(self.returns)) if len(codes) else float("nan")}
        for name, code in OUTCOME_CODES.items():
            if code:
                row[name] = float(np.mean(codes == code)) if len(codes) else float("nan")
        row["seconds"] = time.perf_counter() - self.t0
        self.rows.append(row)
        if not self.quiet:
            print(f"stage {self.stage} {self.num_timesteps:10d} steps {row['seconds']:6.0f} s "
                  f"{len(codes):4d} ep  return {row['return']:8.2f}  success "
                  f"{row['success']:.2f} collision {row['collision']:.2f} deadlock "
                  f"{row['deadlock']:.2f}", flush=True)


def export(model: Any) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """The policy file (spec and arrays) of ``model``'s deterministic action.

    SB3's deterministic action is the actor's mean, clipped to ``[-1, 1]``; the
    training turned it into a body-frame velocity of :data:`ACTION_SCALE` m/s
    per unit (:class:`~comparisons.learned_ppo.vec.BodyVelocity`): the file's
    layers, ``clip``, ``action_scale`` and ``frame``.
    """
    import torch

    pi = model.policy
    linears = [m for m in pi.mlp_extractor.policy_net if isinstance(m, torch.nn.Linear)]
    linears.append(pi.action_net)
    arrays = {}
    for i, lin in enumerate(linears):
        arrays[f"W{i}"] = lin.weight.detach().numpy().astype(np.float64)
        arrays[f"b{i}"] = lin.bias.detach().numpy().astype(np.float64)
    obs = {"beams": SPEC.beams, "neighbours": SPEC.neighbours, "obstacles": SPEC.obstacles,
           "range": SPEC.range, "v_max": SPEC.v_max}
    spec = {"format": "dfcoa-policy", "version": 1, "weights": "learned_ppo.npz",
            "command": "velocity", "frame": "body", "observation": obs, "normalize": False,
            "layers": [*({"size": int(lin.out_features), "activation": "tanh"}
                         for lin in linears[:-1]), {"size": 2, "activation": "linear"}],
            "clip": True, "action_scale": [ACTION_SCALE, ACTION_SCALE],
            "action_offset": [0.0, 0.0]}
    return spec, arrays


def train(seed: int, budget: Budget = FULL, quiet: bool = False
          ) -> tuple[dict[str, Any], dict[str, np.ndarray], list[dict[str, float]]]:
    """Train from ``seed`` (:func:`fit`); the policy file's spec and arrays, and the curve."""
    model, curve = fit(seed, budget, quiet)
    return (*export(model), curve)


def fit(seed: int, budget: Budget = FULL, quiet: bool = False
        ) -> tuple[Any, list[dict[str, float]]]:
    """Train from ``seed`` through the curriculum.

    Runs torch on one thread: the same seed and budget give the same weights,
    bit for bit, on the same machine kind. The seed sets the network's initial
    weights and the action noise; the episodes are the stages' fixed training
    seeds (:data:`TRAIN_SEED0`).

    Returns:
        ``(model, curve)``: the SB3 ``PPO`` and one curve row per rollout
        (:class:`Curve`).
    """
    import torch
    from stable_baselines3 import PPO

    torch.set_num_threads(1)
    t0 = time.perf_counter()
    model = None
    curve: list[dict[str, float]] = []
    for i, stage in enumerate(budget.curriculum):
        env = make_env(stage, i, budget)
        prev = model
        model = PPO("MlpPolicy", env, seed=seed + 1000 * i, n_steps=budget.n_steps,
                    batch_size=budget.batch, n_epochs=budget.epochs,
                    learning_rate=budget.lr, gamma=budget.gamma, device="cpu",
                    policy_kwargs={"net_arch": list(budget.hidden),
                                   "log_std_init": budget.log_std})
        if prev is not None:  # the next stage goes on from this network and optimiser
            model.policy.load_state_dict(prev.policy.state_dict())
            model.policy.optimizer.load_state_dict(prev.policy.optimizer.state_dict())
            model.num_timesteps = prev.num_timesteps
        model.learn(stage.steps, reset_num_timesteps=False,
                    callback=Curve(i, curve, t0, quiet))
        env.close()
    return model, curve


def save_curve(path: Path, curve: list[dict[str, float]]) -> None:
    """Write the learning curve as CSV (one row per rollout; no times, so reproducible)."""
    cols = [k for k in curve[0] if k != "seconds"] if curve else []
    lines = [",".join(cols)] + [",".join(f"{row[c]:.6g}" for c in cols) for row in curve]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: train from ``--seed`` and write the policy file into ``--out``."""
    from comparisons.learned.train import save

    ap = argparse.ArgumentParser(prog="python -m comparisons.learned_ppo.train",
                                 description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0, help="training seed (default 0)")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent,
                    help="folder of learned_ppo.json, learned_ppo.npz and curve.csv")
    ap.add_argument("--tiny", action="store_true", help="a few seconds' budget (tests)")
    ap.add_argument("--quiet", action="store_true", help="no progress lines")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    spec, arrays, curve = train(args.seed, TINY if args.tiny else FULL, args.quiet)
    files = save(args.out, spec, arrays)
    save_curve(args.out / "curve.csv", curve)
    print(f"wrote {files[0]}, {files[1]} and {args.out / 'curve.csv'} in "
          f"{time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
