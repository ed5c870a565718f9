"""Policies as controllers: ``policy:PATH`` files (JSON spec + .npz) and registered callables."""

from __future__ import annotations

import json
import pickle
import re
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import dfcoa_opt as d
from dfcoa_opt.bench.executors import ExecutorConfig
from dfcoa_opt.bench.harness import run_sweep
from dfcoa_opt.bench.results import fingerprint
from dfcoa_opt.bench.sweep import load_sweep
from dfcoa_opt.cli import main
from dfcoa_opt.control import registry
from dfcoa_opt.control.features import ObservationSpec
from dfcoa_opt.core.errors import ScenarioError, UnknownNameError
from dfcoa_opt.scenario.loader import load_scenario
from dfcoa_opt.sim.simulator import run_batch_logs, run_scenario

ROOT = Path(__file__).resolve().parents[1]
TINY = ROOT / "tests" / "data" / "bench" / "tiny.toml"  # 3 robots, one obstacle, LiDAR, 4 s
#: The slot blocks only: slot (2), heading (2), velocity (2), slot velocity (2).
SLOT_ONLY = ObservationSpec(beams=0, neighbours=0, obstacles=0, range=5.0, v_max=0.5)


def slot_tracking_weights(spec: ObservationSpec = SLOT_ONLY, kp: float = 1.0) -> np.ndarray:
    """``W`` of ``u_body = W x``: ``goto_slot``'s kp (slot - p) + slot velocity, in the body frame.

    The slot block is ``R(-th) (slot - p) / range`` and the slot-velocity block
    ``R(-th) v_slot / v_max``, so these gains undo the scales.
    """
    w = np.zeros((2, spec.size))
    lay = spec.layout()
    w[:, lay["slot"]] = kp * spec.range * np.eye(2)
    w[:, lay["slot_velocity"]] = spec.v_max * np.eye(2)
    return w


def write_policy(path: Path, layers, spec: ObservationSpec = SLOT_ONLY, *, command="velocity",
                 scale=(1.0, 1.0), arrays=None, frame="body", **keys) -> Path:
    """Write ``path`` (JSON spec) and ``path.npz``; ``arrays`` replaces the .npz's contents."""
    data = {"format": "dfcoa-policy", "version": 1, "command": command,
            "weights": path.with_suffix(".npz").name,
            "observation": {"beams": spec.beams, "neighbours": spec.neighbours,
                            "obstacles": spec.obstacles, "range": spec.range,
                            "v_max": spec.v_max},
            "layers": [{"size": len(w), "activation": a} for w, _, a in layers],
            "action_scale": list(scale), **({"frame": frame} if frame else {}), **keys}
    if arrays is None:
        arrays = {}
        for i, (w, b, _) in enumerate(layers):
            arrays[f"W{i}"], arrays[f"b{i}"] = np.asarray(w), np.asarray(b)
    np.savez(path.with_suffix(".npz"), **arrays)
    path.write_text(json.dumps(data))
    return path


def linear_policy(folder: Path, name: str = "pol.json") -> Path:
    return write_policy(folder / name, [(slot_tracking_weights(), np.zeros(2), "linear")])


def mlp_policy(folder: Path, name: str = "mlp.json", seed: int = 0) -> Path:
    """A random two-layer tanh network reading LiDAR, neighbours and obstacles, standardized."""
    spec = ObservationSpec(beams=8, neighbours=2, obstacles=1)
    rng = np.random.default_rng(seed)
    layers = [(rng.normal(0, 0.3, (16, spec.size)), rng.normal(0, 0.1, 16), "tanh"),
              (rng.normal(0, 0.3, (2, 16)).astype(np.float32), np.zeros(2, np.float32), "tanh")]
    arrays = {"W0": layers[0][0], "b0": layers[0][1], "W1": layers[1][0], "b1": layers[1][1],
              "obs_mean": rng.normal(0, 0.1, spec.size),
              "obs_std": rng.uniform(0.5, 2.0, spec.size)}
    return write_policy(folder / name, layers, spec, scale=(0.4, 0.4), arrays=arrays,
                        normalize=True, clip=True)


# -- running -----------------------------------------------------------------------------------

def test_a_linear_policy_file_is_proportional_slot_tracking(tmp_path):
    pol = linear_policy(tmp_path)
    s = d.load(TINY)
    run, ref = d.run(s, f"policy:{pol}"), d.run(s, "goto_slot")
    np.testing.assert_allclose(run.log.pose, ref.log.pose, rtol=0, atol=1e-12)
    assert run.metrics["collisions"] == 0
    cls = registry.controller_class(f"policy:{pol}")
    assert cls.command == "velocity" and cls.uses_scan is False and cls.batched is True
    assert not any(c.startswith("policy:") for c in d.controllers())  # not listed


def test_dfcoa_run_with_a_relative_policy_path(tmp_path):
    linear_policy(tmp_path)
    proc = subprocess.run([sys.executable, "-m", "dfcoa_opt", "run", str(TINY), "--controller",
                           "policy:pol.json", "--json", "--out", "out"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    obj = json.loads(proc.stdout)
    ref = d.run(d.load(TINY), "goto_slot").metrics
    assert obj["controller"] == "policy:pol.json"
    assert obj["metrics"]["fce_rms"] == pytest.approx(ref["fce_rms"], abs=1e-12)


def test_dfcoa_run_seeds_with_a_dotted_id_write_one_log_per_seed(tmp_path):
    """``policy:pol.json`` has a dot and a colon: every seed's files keep their own name."""
    linear_policy(tmp_path)
    assert main(["run", str(TINY), "--controller", f"policy:{tmp_path / 'pol.json'}",
                 "--seeds", "0-1", "--out", str(tmp_path / "out"), "--json"]) == 0
    logs = sorted(p.name for p in (tmp_path / "out").glob("*.npz"))
    assert len(logs) == 2 and logs[0].endswith("-s0.npz") and logs[1].endswith("-s1.npz")
    assert all(":" not in name and "/" not in name for name in logs)


@pytest.mark.parametrize("filtered", ["", "+cbf"])
def test_a_batch_is_its_runs_alone_bit_for_bit(tmp_path, filtered):
    cid = f"policy:{mlp_policy(tmp_path)}{filtered}"
    sc = load_scenario(TINY, 7)
    seeds = (0, 1, 2)
    batch = run_batch_logs(sc, cid, seeds)
    singles = [run_scenario(load_scenario(TINY, s), cid) for s in seeds]
    assert [b.digest() for b in batch] == [s.digest() for s in singles]
    assert np.ptp(batch[0].pose[:, :, :2], axis=0).max() > 0.1  # the robots did move
    if filtered:
        assert d.run(load_scenario(TINY, 0), cid).log.digest() == singles[0].digest()


def test_a_two_run_sweep_on_two_processes_reruns_when_the_file_changes(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # the relative PATH: relative to the working folder
    linear_policy(tmp_path)
    sweep = tmp_path / "sweep.toml"
    sweep.write_text(f'scenarios = ["{TINY.as_posix()}"]\ncontrollers = ["policy:pol.json"]\n'
                     'seeds = 2\n')
    assert registry.known_to_workers("policy:pol.json")
    assert registry.known_to_workers("policy:pol.json+cbf")
    res = run_sweep(sweep, tmp_path / "out", ExecutorConfig("process", 2), progress=False)
    assert (res.ran, res.failed) == (2, 0)
    rows = res.store.rows()
    direct = [d.run(d.load(TINY), "policy:pol.json", seed=s).log.digest() for s in (0, 1)]
    assert [r["digest"] for r in rows] == direct
    code = rows[0]["code"]
    assert code == fingerprint.run_fingerprint("policy:pol.json") != fingerprint.code_fingerprint(
        "policy:pol.json")
    runs = load_sweep(sweep).runs
    assert res.store.pending(runs) == []
    # the same id, other weights: its rows are no longer done, and run again
    write_policy(tmp_path / "pol.json", [(slot_tracking_weights(kp=2.0), np.zeros(2),
                                          "linear")])
    assert res.store.pending(runs) == list(runs)
    again = run_sweep(sweep, tmp_path / "out", ExecutorConfig("process", 2), progress=False)
    assert (again.ran, again.skipped) == (2, 0)
    assert [r["digest"] for r in again.store.rows()] != direct
    assert again.store.rows()[0]["code"] != code


def test_the_facade_sweep_keeps_policy_files_on_worker_processes(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    linear_policy(tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)  # no "registered in this process only"
        res = d.sweep({"scenarios": [str(TINY)], "controllers": ["policy:pol.json+cbf"],
                       "seeds": 2}, tmp_path / "res", jobs=2)
    assert [r["status"] for r in res.rows] == ["ok", "ok"]


def test_the_code_fingerprint_of_a_policy_covers_the_policy_modules_only(tmp_path):
    core = set(fingerprint.fingerprint_sources("goto_slot")) - {"dfcoa_opt/control/goto_slot.py"}
    own = set(fingerprint.fingerprint_sources(f"policy:{linear_policy(tmp_path)}")) - core
    assert own == {"dfcoa_opt/control/policy/__init__.py",
                   "dfcoa_opt/control/policy/controller.py", "dfcoa_opt/control/policy/file.py",
                   "dfcoa_opt/control/features.py", "dfcoa_opt/control/features_kernel.py"}


# -- bad files -----------------------------------------------------------------------------------

W_OK = slot_tracking_weights()


def _bad_arrays(**change):
    arrays = {"W0": W_OK, "b0": np.zeros(2)}
    arrays.update(change)
    return {k: v for k, v in arrays.items() if v is not None}


BAD = {
    # name: (what to write, what the one line says after the file name)
    "missing spec": (None, "nope.json: policy file not found"),
    "bad JSON": ("{not json", "pol.json: not valid JSON"),
    "not an object": ("[1, 2]", "pol.json: must be a JSON object"),
    "a key twice": ('{"format": "dfcoa-policy", "format": "x"}', "is given twice"),
    "wrong format": ({"format": "onnx"}, "pol.json: format: must be 'dfcoa-policy'"),
    "future version": ({"version": 2}, "pol.json: version: unsupported version 2"),
    "unknown key": ({"layer": []}, "pol.json: layer: unknown key (did you mean 'layers'?)"),
    "bad activation": ({"layers": [{"size": 2, "activation": "gelu"}]},
                       "pol.json: layers[0].activation: must be one of"),
    "last layer not 2": ({"layers": [{"size": 3}]}, "pol.json: layers[0].size: the last"),
    "bad command": ({"command": "torque"}, "pol.json: command: must be one of"),
    "world unicycle": ({"command": "unicycle", "frame": "world"}, "pol.json: frame:"),
    "no frame": ({"frame": None}, "pol.json: frame: is required for a velocity command"),
    "observation default": ({"observation": {"beams": 0}},
                            "pol.json: observation.neighbours: is required"),
    "NaN in the spec": ({"action_scale": [float("nan"), 1.0]},
                        "pol.json: action_scale[0]: must be a number, got NaN"),
    "missing weights": ({"weights": "gone.npz"}, "gone.npz: weights file not found"),
    "missing array": (_bad_arrays(b0=None), "pol.npz: b0: missing array"),
    "extra array": (_bad_arrays(W1=np.zeros(2)), "pol.npz: W1: unexpected array"),
    "wrong shape": (_bad_arrays(W0=np.zeros((2, 7))),
                    "pol.npz: W0: shape (2, 7), expected (2, 8)"),
    "wrong dtype": (_bad_arrays(b0=np.zeros(2, dtype=np.int64)), "pol.npz: b0: dtype int64"),
    "NaN weights": (_bad_arrays(W0=np.full((2, 8), np.nan)), "pol.npz: W0: holds NaN or inf"),
    "inf weights": (_bad_arrays(b0=np.array([np.inf, 0.0])), "pol.npz: b0: holds NaN or inf"),
    "object array": (_bad_arrays(W0=np.full((2, 8), None, dtype=object)),
                     "pol.npz: W0: holds Python objects (pickled data); refused"),
    "not a zip": (b"garbage, not an archive", "pol.npz: not an .npz archive"),
    "a pickle": (pickle.dumps({"W0": W_OK}), "pol.npz: holds Python objects (pickled data)"),
    "one .npy": (b"npy", "pol.npz: is one .npy array"),
}


def _write_bad(folder: Path, what) -> str:
    """Write the case; returns the controller id."""
    pol = linear_policy(folder)
    if what is None:
        return "policy:nope.json"
    if isinstance(what, str):
        pol.write_text(what)
    elif isinstance(what, dict) and all(isinstance(v, np.ndarray) for v in what.values()):
        np.savez(folder / "pol.npz", **what)
    elif isinstance(what, dict):
        data = json.loads(pol.read_text())
        data.update(what)
        pol.write_text(json.dumps(data))
    elif what == b"npy":
        with open(folder / "pol.npz", "wb") as fh:
            np.save(fh, W_OK)
    else:
        (folder / "pol.npz").write_bytes(what)
    return "policy:pol.json"


@pytest.mark.parametrize("case", list(BAD))
def test_every_bad_policy_file_is_exit_2_and_one_line_naming_it(tmp_path, monkeypatch, capsys,
                                                                 case):
    monkeypatch.chdir(tmp_path)
    what, message = BAD[case]
    cid = _write_bad(tmp_path, what)
    assert main(["run", str(TINY), "--controller", cid, "--out", "out"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("dfcoa: error: ") and message in err[0], err
    assert main(["run", str(TINY), "--controller", cid + "+cbf", "--out", "out"]) == 2
    with pytest.raises(ScenarioError, match=re.escape(message.split(": ")[0])):
        d.run(d.load(TINY), cid)


class Bomb:
    """Unpickling one would record it (a pickle runs code when it is loaded)."""

    def __reduce__(self):
        return (_exploded.append, ("unpickled",))


_exploded: list[str] = []


def test_a_pickled_object_array_is_refused_and_never_unpickled(tmp_path):
    pol = linear_policy(tmp_path)
    w = np.empty((2, 8), dtype=object)
    w[:] = [[Bomb() for _ in range(8)] for _ in range(2)]
    np.savez(tmp_path / "pol.npz", W0=w, b0=np.zeros(2))  # savez pickles object arrays
    with pytest.raises(ScenarioError, match=r"pol.npz: W0: holds Python objects"):
        d.run(d.load(TINY), f"policy:{pol}")
    assert _exploded == []


def test_a_bad_policy_in_a_sweep_fails_before_any_run(tmp_path):
    pol = write_policy(tmp_path / "pol.json", [(np.zeros((2, 5)), np.zeros(2), "linear")])
    with pytest.raises(ScenarioError, match=r"pol.npz: W0: shape \(2, 5\), expected \(2, 8\)"):
        d.sweep({"scenarios": [str(TINY)], "controllers": [f"policy:{pol}"], "seeds": 2},
                tmp_path / "res")
    assert not (tmp_path / "res").exists()


def test_policy_ids_take_no_parameter_table_and_are_reserved(tmp_path):
    with pytest.raises(ScenarioError, match=r"f.toml: controllers.policy:p.json: a policy"):
        registry.check_overrides({"policy:p.json": {"gain": 1.0}}, "f.toml")
    registry.check_overrides({"goto_slot": {"kp": 2.0}}, "f.toml")  # the others as before
    with pytest.raises(ValueError, match="reserved"):
        registry.register("policy:mine")(type("P", (), {"Params": object}))
    with pytest.raises(UnknownNameError, match="names no policy file"):
        registry.controller_class("policy:")


# -- callables -----------------------------------------------------------------------------------

@pytest.fixture
def fresh_registry(monkeypatch):
    """Registrations of one test only (the registry is restored)."""
    registry.available()  # load the built-ins before the copy
    monkeypatch.setattr(registry.CONTROLLERS, "_table", dict(registry.CONTROLLERS._table))


def test_a_registered_callable_policy_runs_by_id(fresh_registry):
    w = slot_tracking_weights()
    seen = []

    def track(x):
        """Slot tracking as a function of the observation vectors."""
        seen.append(x.shape)
        return x @ w.T

    assert d.register("test_track", command="velocity", spec=SLOT_ONLY, frame="body")(
        track) is track
    assert "test_track" in d.controllers()
    assert not registry.known_to_workers("test_track")  # a sweep keeps it in this process
    s = d.load(TINY)
    run, ref = d.run(s, "test_track"), d.run(s, "goto_slot")
    np.testing.assert_allclose(run.log.pose, ref.log.pose, rtol=0, atol=1e-12)
    assert seen[0] == (3, SLOT_ONLY.size)
    seen.clear()
    runs = d.run_batch(s, "test_track", [0, 1])
    assert seen[0] == (6, SLOT_ONLY.size)  # one call for every row of both runs
    assert [r.log.meta["seed"] for r in runs] == [0, 1]


def test_an_unbatched_callable_sees_one_run_and_batches_equal_single_runs(fresh_registry):
    w = slot_tracking_weights()
    d.register("test_track_each", command="velocity", spec=SLOT_ONLY, frame="body",
               batched=False)(lambda x: x @ w.T)
    s = d.load(TINY)
    batch = d.run_batch(s, "test_track_each", [0, 1])
    assert [r.log.digest() for r in batch] == [d.run(s, "test_track_each", seed=k).log.digest()
                                               for k in (0, 1)]


def test_register_checks_what_it_is_given(fresh_registry):
    with pytest.raises(TypeError, match="needs command="):
        d.register("test_no_kind")(lambda x: x)
    with pytest.raises(ValueError, match="command must be"):
        d.register("test_bad_kind", command="torque")(lambda x: x)
    with pytest.raises(ValueError, match="frame"):
        d.register("test_bad_frame", command="velocity", frame="robot")(lambda x: x)
    with pytest.raises(ValueError, match="reserved"):
        d.register("policy:x.json", command="velocity")(lambda x: x)
    with pytest.raises(TypeError, match="is a class"):
        d.register("test_cls", command="velocity")(type("C", (), {}))


@pytest.mark.parametrize("command,frame,sign", [("velocity", "body", -1), ("velocity", "world", 1),
                                                ("acceleration", "body", -1),
                                                ("unicycle", None, -1)])
def test_the_action_frame(tmp_path, command, frame, sign):
    """A constant action (0.2, 0): along the heading in the body frame, along +x in the world's.

    The team starts facing -x (the leader goes from right to left). A unicycle
    action (v, omega) needs no frame.
    """
    pol = write_policy(tmp_path / "c.json", [(np.zeros((2, 8)), np.array([0.2, 0.0]), "linear")],
                       command=command, frame=frame)
    s = d.load(TINY, t_max=1.0, leader__start=[10.0, 3.0], leader__goal=[2.0, 3.0])
    pose = d.run(s, f"policy:{pol}").log.pose
    assert np.cos(pose[0, :, 2]).max() < -0.9  # facing -x
    dx = pose[-1, :, 0] - pose[0, :, 0]
    assert (np.sign(dx) == sign).all() and (abs(dx) > 0.01).all(), dx
