"""Environment steps per second: our ``vector_env`` against VMAS (``navigation``), one thread each.

VMAS (Bettini et al., 2022) steps many 2-D multi-robot environments as torch
tensors. Its nearest task to ours is ``navigation`` with 4 agents and its
default 12-ray LiDAR; ours is ``scenarios/envs/open_4.toml`` (4 unicycles, an
open map) with the same number of LiDAR beams (12) and the same reach in robot
radii (VMAS: rays of 0.35 for agents of radius 0.1; ours: 3.5 x 0.2 m = 0.7 m).
Both take random actions within their action space and autoreset finished
sub-environments. Each row times whole vector steps at E = 1, 64 and 1024 in
:data:`~benchmarks.timing.REPS` interleaved repetitions, torch and numba on one
thread each (``torch.set_num_threads(1)``, ``numba.set_num_threads(1)``); the
ratio is VMAS's time per step over ours. Targets: 10x at E = 1, 2x at E = 64,
1x at E = 1024. Needs the ``bench`` extra (torch's CPU build 2.13.0 and vmas);
without them the rows are left out.

``python -m benchmarks.bench_vmas`` prints the rows.
"""

from __future__ import annotations

import time
from pathlib import Path

import numba
import numpy as np

from benchmarks.timing import REPS, print_rows, row

ROOT = Path(__file__).resolve().parents[1]
#: Sub-environments per row, and vector steps timed per repetition.
CASES = ((1, 200), (64, 60), (1024, 12))
BEAMS = 12


def ours(num_envs: int):
    """``step()`` of our vector env (random actions), after a reset."""
    from dfcoa_opt.envs import vector_env

    env = vector_env(ROOT / "scenarios" / "envs" / "open_4.toml", num_envs=num_envs,
                     sensors__lidar__beams=BEAMS, sensors__lidar__range_max=0.7)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    low, high = env.action_space.low, env.action_space.high

    def step() -> None:
        env.step(rng.uniform(low, high))

    return step


def vmas_step(num_envs: int):
    """``step()`` of VMAS ``navigation`` (4 agents, random actions, autoreset of done envs)."""
    import torch
    import vmas

    env = vmas.make_env("navigation", num_envs=num_envs, device="cpu",
                        continuous_actions=True, n_agents=4, seed=0)
    env.reset()
    gen = torch.Generator().manual_seed(0)

    def step() -> None:
        actions = [torch.rand((num_envs, 2), generator=gen) * 2.0 - 1.0 for _ in env.agents]
        _obs, _rew, dones, _info = env.step(actions)
        for i in torch.nonzero(dones).flatten().tolist():
            env.reset_at(i)

    return step


def _per_step_us(step, steps: int) -> float:
    t0 = time.perf_counter()
    for _ in range(steps):
        step()
    return (time.perf_counter() - t0) / steps * 1e6


def run() -> list[dict]:
    """One row per E: our vector step against VMAS's (skipped without torch or vmas)."""
    try:
        import torch
        import vmas  # noqa: F401
    except ImportError:
        print("bench_vmas: torch or vmas not installed (pip install -e '.[bench]'); skipped")
        return []
    threads_torch, threads_numba = torch.get_num_threads(), numba.get_num_threads()
    torch.set_num_threads(1)
    numba.set_num_threads(1)
    rows = []
    try:
        for e, steps in CASES:
            a, b = ours(e), vmas_step(e)
            a(), b()  # warm-up: compilation, caches
            mine: list[np.ndarray] = []
            theirs: list[np.ndarray] = []
            for rep in range(REPS):
                turns = [(a, mine), (b, theirs)]
                for fn, out in (turns if rep % 2 == 0 else turns[::-1]):
                    out.append(np.array([_per_step_us(fn, steps)]))
            rows.append(row(f"vector env step, 4 robots, {BEAMS}-beam LiDAR, E={e}, one thread",
                            mine, "VMAS navigation step (torch CPU, one thread)", theirs))
    finally:
        torch.set_num_threads(threads_torch)
        numba.set_num_threads(threads_numba)
    return rows


if __name__ == "__main__":
    print_rows(run())
