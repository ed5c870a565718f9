"""`learned`: the shipped policy (BC + DAgger from goto_slot+cbf) and its reproducible training."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import comparisons.learned  # noqa: F401 - registers 'learned'
import dfcoa_opt as d
from comparisons.learned import controller, train
from dfcoa_opt.control.policy import load_policy, policy_digest
from dfcoa_opt.core.errors import ScenarioError

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "scenarios" / "example_obstacles.toml"


def test_the_shipped_files_load_and_are_the_ones_the_controller_expects():
    pol = load_policy(controller.SHIPPED)
    assert policy_digest(controller.SHIPPED) == controller.SHIPPED_DIGEST
    assert pol.spec.command == "velocity" and pol.spec.frame == "body"
    assert pol.spec.observation == train.SPEC
    assert [w.shape for w, _, _ in pol.layers] == [(64, train.SPEC.size), (64, 64), (2, 64)]


def test_learned_reaches_the_goal_without_contact_on_example_obstacles():
    r = d.run(EXAMPLE, "learned", seed=0)
    assert np.isfinite(r.log.command).all()
    assert r.metrics["outcome"] == "success"
    assert r.metrics["collisions"] == 0
    assert r.metrics["fce_rms"] < 0.05  # m; random weights never get near this


def test_a_batch_is_its_runs_alone():
    sc = d.load(EXAMPLE, t_max=5.0, team__start_noise=0.2)
    batch = d.run_batch(sc, "learned", [0, 1])
    assert [r.log.digest() for r in batch] == [d.run(sc, "learned", seed=s).log.digest()
                                               for s in (0, 1)]
    assert batch[0].log.digest() != batch[1].log.digest()


def test_changed_shipped_files_are_refused_until_the_digest_is_updated(monkeypatch):
    monkeypatch.setattr(controller, "SHIPPED_DIGEST", "f" * 64)
    with pytest.raises(ScenarioError, match="SHIPPED_DIGEST"):
        controller.Learned()


def test_training_is_reproducible_from_its_seed(tmp_path):
    a = train.train(0, train.TINY, quiet=True)
    b = train.train(0, train.TINY, quiet=True)
    c = train.train(1, train.TINY, quiet=True)
    assert a[0] == b[0] and a[1].keys() == b[1].keys() == c[1].keys()
    for name in a[1]:
        assert np.array_equal(a[1][name], b[1][name]), name
    assert not np.array_equal(a[1]["W0"], c[1]["W0"])
    files = [train.save(tmp_path / k, *ab) for k, ab in (("a", a), ("b", b))]
    assert [f.read_bytes() for f in files[0]] == [f.read_bytes() for f in files[1]]
    # the written file runs as the controller's 'policy' parameter and as policy:PATH
    sc = d.load(EXAMPLE, t_max=2.0, controllers__learned__policy=str(files[0][0]))
    runs = [d.run(sc, cid, seed=0) for cid in ("learned", f"policy:{files[0][0]}")]
    assert runs[0].log.digest() == runs[1].log.digest()


@pytest.mark.slow
def test_the_training_script_reproduces_the_shipped_files_from_seed_0(tmp_path):
    """The full budget: the same bytes as the shipped files.

    Paper-scale (6 min on an idle core of the 2-core Intel Xeon, 7 min beside the rest of
    the suite): run by ``make check-training``, not ``make test``; the short training above checks
    the same code.
    """
    proc = subprocess.run([sys.executable, "-m", "comparisons.learned.train", "--seed", "0",
                           "--out", str(tmp_path)], cwd=ROOT, capture_output=True, text=True,
                          timeout=1200)
    assert proc.returncode == 0, proc.stderr[-2000:]
    for name in ("learned.json", "learned.npz"):
        assert (tmp_path / name).read_bytes() == (controller.SHIPPED.parent / name).read_bytes()
