"""`learned_ppo`: the shipped PPO policy, its export from SB3 and its reproducible training."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import comparisons.learned_ppo  # noqa: F401 - registers 'learned_ppo'
import dfcoa_opt as d
from comparisons.learned_ppo import controller
from dfcoa_opt.control.policy import load_policy, policy_digest
from dfcoa_opt.core.errors import ScenarioError

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "scenarios" / "example_obstacles.toml"


def test_the_shipped_files_load_and_are_the_ones_the_controller_expects():
    pol = load_policy(controller.SHIPPED)
    assert policy_digest(controller.SHIPPED) == controller.SHIPPED_DIGEST
    assert pol.spec.command == "velocity" and pol.spec.frame == "body" and pol.spec.clip
    assert [w.shape[1] for w, _, _ in pol.layers][0] == pol.spec.observation.size == 80
    assert list(pol.spec.action_scale) == [0.5, 0.5]  # m/s per unit, as in the training


def test_learned_ppo_runs_example_obstacles_and_a_batch_is_its_runs_alone():
    sc = d.load(EXAMPLE, t_max=8.0, team__start_noise=0.3, team__heading_noise=0.6)
    batch = d.run_batch(sc, "learned_ppo", [0, 1])
    assert [r.log.digest() for r in batch] == [d.run(sc, "learned_ppo", seed=s).log.digest()
                                               for s in (0, 1)]
    cmd = batch[1].log.command
    assert np.isfinite(cmd).all() and np.ptp(cmd[..., 0]) > 0.05  # not a constant command


def test_gains_scale_the_networks_command():
    base = controller.LearnedPPO()
    fast = controller.LearnedPPO(controller.LearnedPPO.Params(gain_forward=2.0,
                                                              gain_lateral=0.5))
    x = np.random.default_rng(0).normal(size=(7, base.spec.size))
    np.testing.assert_array_equal(fast.forward(x), base.forward(x) * [2.0, 0.5])


def test_changed_shipped_files_are_refused_until_the_digest_is_updated(monkeypatch):
    monkeypatch.setattr(controller, "SHIPPED_DIGEST", "f" * 64)
    with pytest.raises(ScenarioError, match="comparisons/learned_ppo/controller.py"):
        controller.LearnedPPO()


# ------------------------------------------------------------------ training (the rl extra)
def test_a_short_training_is_reproducible_and_exports_sb3s_deterministic_action(tmp_path):
    pytest.importorskip("stable_baselines3")
    from comparisons.learned.train import save
    from comparisons.learned_ppo import train

    a = train.train(0, train.TINY, quiet=True)
    b = train.train(0, train.TINY, quiet=True)
    c = train.train(1, train.TINY, quiet=True)
    assert sum(s.steps for s in train.TINY.curriculum) >= 4096  # a few thousand steps
    assert a[0] == b[0] and a[1].keys() == b[1].keys()
    assert all(np.array_equal(a[1][k], b[1][k]) for k in a[1])
    assert not np.array_equal(a[1]["W0"], c[1]["W0"])
    assert [{k: v for k, v in r.items() if k != "seconds"} for r in a[2]] == \
        [{k: v for k, v in r.items() if k != "seconds"} for r in b[2]]
    assert a[2][-1]["steps"] >= 4096 and sum(r["episodes"] for r in a[2]) > 0
    files = save(tmp_path, *a[:2])
    train.save_curve(tmp_path / "curve.csv", a[2])
    assert files[0].name == "learned_ppo.json"
    assert (tmp_path / "curve.csv").read_text().splitlines()[0].startswith("stage,steps,")
    # the file's network is SB3's deterministic action: the actor's mean, clipped, scaled
    model, _ = train.fit(0, train.TINY, quiet=True)
    assert train.export(model)[1]["W0"].tobytes() == a[1]["W0"].tobytes()
    x = np.random.default_rng(1).normal(size=(64, train.SPEC.size))
    want = train.ACTION_SCALE * model.predict(x.astype(np.float32), deterministic=True)[0]
    got = load_policy(files[0]).forward(x)
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-5)
    sc = d.load(EXAMPLE, t_max=2.0, controllers__learned_ppo__policy=str(files[0]))
    runs = [d.run(sc, cid, seed=0) for cid in ("learned_ppo", f"policy:{files[0]}")]
    assert runs[0].log.digest() == runs[1].log.digest()


def test_it_reaches_the_goal_from_every_noisy_start_not_already_in_contact():
    """The target: example_obstacles from the training's noisy starts, seeds 0-19.

    Three of those starts (seeds 2, 8, 10) put robots in contact at t = 0, so no
    controller can succeed there; every other seed must end in success.
    """
    sc = d.load(EXAMPLE, team__start_noise=0.3, team__heading_noise=0.6)
    runs = d.run_batch(sc, "learned_ppo", range(20))
    failed = {s: r.metrics for s, r in enumerate(runs) if r.metrics["outcome"] != "success"}
    assert sorted(failed) == [2, 8, 10]
    assert all(m["outcome"] == "collision" and m["first_contact_time"] == 0.0
               for m in failed.values())
