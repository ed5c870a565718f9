"""The learning environments' compiled kernels: the observation vector and the score pass
equal their numpy references bit for bit, on random and special-valued inputs."""

from __future__ import annotations

from pathlib import Path

import numpy as np

import dfcoa_opt  # noqa: F401 - first: pins numpy's SIMD dispatch

# isort: split
from dfcoa_opt.control.base import MovingObstacles, Neighbours, Observation
from dfcoa_opt.control.features import ObservationSpec, flatten, flatten_reference
from dfcoa_opt.envs import RewardSpec, rewards, vector_env
from dfcoa_opt.envs.kernels import score_runs
from dfcoa_opt.envs.rewards import PathTable, path_arc_length
from dfcoa_opt.scenario.schema import MetricSpec
from dfcoa_opt.sim.stall import BatchStall
from dfcoa_opt.world.lidar import LaserScan

CROSSING = Path(__file__).resolve().parents[1] / "scenarios" / "bench" / "crossing.toml"


def same_bits(a, b) -> bool:
    """Equal bit for bit (a NaN's sign and payload aside: the kernels' NaN may differ)."""
    a, b = (np.where(np.isnan(x), np.nan, x) if x.dtype.kind == "f" else x
            for x in (np.asarray(a), np.asarray(b)))
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


def random_observation(rng, r: int, kn: int, m: int, beams: int, batched: bool, special: bool):
    def f(*shape):
        x = rng.normal(size=shape) * rng.choice([0.01, 1.0, 50.0])
        if special:  # zeros of both signs, infinities, NaN, extremes
            hit = rng.random(shape) < 0.1
            x[hit] = rng.choice([0.0, -0.0, np.inf, -np.inf, np.nan, 1e300, -1e-300], hit.sum())
        return x

    e = max(1, r // 3)
    ranges = np.abs(f(r, beams))
    ranges[rng.random((r, beams)) < 0.2] = rng.choice([np.inf, -np.inf])
    scan = LaserScan(-np.pi, 0.1, 0.05, float(rng.uniform(0.5, 8.0)), ranges)
    mv_pos = f(r, m, 2)
    if m and rng.random() < 0.3:
        mv_pos[:] = mv_pos[:, :1]  # equal distances: the stable order decides
    return Observation(
        0.0, 0.1, np.arange(r), f(r, 3), f(r, 2), f(r, 2), scan if rng.random() < 0.8 else None,
        Neighbours(rng.integers(-1, r, (r, kn)), f(r, kn, 2), f(r, kn, 2), np.abs(f(r, kn))),
        MovingObstacles(mv_pos, f(r, m, 2), np.abs(f(r, m)), rng.random((r, m)) < 0.6),
        f(e, 5) if batched else f(5), f(2), f(r, 2), f(r, 2),
        np.sort(rng.integers(0, e, r)) if batched else None)


def test_the_compiled_flatten_is_the_numpy_reference_bit_for_bit():
    rng = np.random.default_rng(0)
    for trial in range(1500):
        obs = random_observation(rng, int(rng.integers(1, 30)), int(rng.integers(0, 8)),
                                 int(rng.integers(0, 7)), int(rng.integers(1, 40)),
                                 trial % 2 == 0, trial % 3 == 0)
        spec = ObservationSpec(int(rng.integers(0, 20)), int(rng.integers(0, 7)),
                               int(rng.integers(0, 5)), float(rng.uniform(0.3, 9.0)),
                               float(rng.uniform(0.1, 3.0)))
        with np.errstate(all="ignore"):
            assert same_bits(flatten(obs, spec), flatten_reference(obs, spec)), (trial, spec)
    env = vector_env(CROSSING, num_envs=3, t_max=30.0)  # moving obstacles in range
    env.reset(seed=5)
    for k in range(250):
        env.step(np.tile([0.3, 0.1 * np.sin(0.05 * k)], (3, env.core.n, 1)))
        obs = env.toolkit_observation
        assert flatten(obs, env.core.obs_spec).tobytes() == \
            flatten_reference(obs, env.core.obs_spec).tobytes()
    assert obs.obstacles.mask.any()


def test_the_compiled_score_is_the_numpy_reference_bit_for_bit():
    """Formation errors, arc length, contacts, reward and stall flags of random logs."""
    rng = np.random.default_rng(1)
    flags_seen = set()
    for trial in range(600):
        e, t = int(rng.integers(1, 10)), int(rng.integers(2, 30))
        n = int(rng.choice([1, 2, 3, 4, 5, 8, 9, 20, 129] + ([300] if e < 3 else [])))
        scale = rng.choice([0.1, 3.0, 40.0])
        pose = rng.normal(size=(e, t, n, 3)) * scale
        slots = pose[..., :2] + rng.normal(size=(e, t, n, 2)) * rng.choice([0.0, 0.01, 1.0])
        if trial % 10 == 0:
            pose[rng.random(pose.shape) < 0.01] = np.nan
        hits = [(rng.random((e, t)) < 0.1).astype(np.int32) for _ in range(3)]
        active = np.sort(rng.choice(e, int(rng.integers(1, e + 1)), replace=False))
        kk = rng.integers(0, t, len(active))
        table, paths = PathTable(), []
        for g in range(int(rng.integers(1, 30))):  # a group's path replaced: appended, compacted
            path = rng.normal(size=(int(rng.choice([1, 2, 3, 10, 50])), 2)) * scale
            if len(path) > 2 and g % 3 == 0:
                path[1] = path[0]  # a repeated point
            paths[g % 3:g % 3 + 1] = [path]
            table.set(g % 3, path)
        group = rng.integers(0, len(paths), e)
        spec = RewardSpec(*rng.uniform(0.0, 5.0, 6).tolist())
        dt, arc_prev = float(rng.uniform(0.01, 0.5)), rng.normal(size=e) * scale
        cfg = MetricSpec(deadlock_window=float(rng.uniform(0.05, 2.0)),
                         deadlock_advance=float(rng.uniform(0.0, 2.0 * scale)),
                         deadlock_displacement=float(rng.uniform(0.0, 3.0 * scale)))
        stall, ref = (BatchStall(e, t, dt, float(rng.uniform(0.0, 2.0 * scale)), cfg)
                      for _ in range(2))
        ref.settle = stall.settle
        ref.progress[:] = stall.progress[:] = rng.normal(size=(e, t)) * scale * 0.1
        prev = arc_prev.copy()
        with np.errstate(all="ignore"):
            reward, contact, e_c, e_s, arc = score_runs(
                pose, slots, *hits, active, kk, group, table.start, table.count, table.data,
                arc_prev, np.array([spec.formation, spec.shape, spec.progress, spec.contact]),
                dt, stall.progress, stall.flags, True, stall.lag, stall.advance, stall.settle,
                stall.displacement)
            ref_ec, ref_es = rewards.formation_errors(pose[active, kk], slots[active, kk])
            centroid = pose[active, kk, :, :2].mean(axis=1)
            ref_arc = np.array([path_arc_length(paths[group[s]], centroid[j:j + 1])[0]
                                for j, s in enumerate(active)])
            ref_contact = np.any([h[active, kk] > 0 for h in hits], axis=0)
            advance = np.where(kk == 0, 0.0, ref_arc - prev[active])
            ref_reward = rewards.dense_reward(spec, dt, ref_ec, ref_es, advance, ref_contact)
            ref.update_reference(ref_arc, active, kk, pose, slots)
        for got, want in ((e_c, ref_ec), (e_s, ref_es), (arc, ref_arc), (contact, ref_contact),
                          (reward, ref_reward), (arc_prev[active], ref_arc),
                          (stall.progress, ref.progress), (stall.flags, ref.flags)):
            assert same_bits(got, want), (trial, n)
        flags_seen |= set(stall.flags[active].tolist())
    assert flags_seen == {False, True}


