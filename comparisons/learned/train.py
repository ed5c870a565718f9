"""Train the ``learned`` policy: behaviour cloning with DAgger from ``goto_slot+cbf``.

Usage::

    python -m comparisons.learned.train --seed 0 --out comparisons/learned/

writes ``learned.json`` and ``learned.npz`` (a ``policy:PATH`` file,
``docs/policies.md``), the same bytes for the same seed (``docs/methods/learned.md``).

Round 0 rolls out the teacher alone and records, at every recorded step, each
robot's observation vector and the teacher's velocity command in the robot's
frame. Each later round rolls out ``beta * teacher + (1 - beta) * student``
with the network of the round before, again recording the teacher's command
in the states the mixture visits, adds the rows to the data set and trains on
all of them (Adam on the mean squared error, warm-started). The seed sets the
initial weights, the minibatch order and the rollout seeds.
"""

from __future__ import annotations

import dfcoa_opt  # noqa: F401 - first: pins numpy's SIMD and OpenBLAS kernels (dispatch.py)

# isort: split
import argparse
import io
import json
import os
import sys
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from comparisons.learned import mlp
from comparisons.learned.dagger import Mixture, collect
from dfcoa_opt.control.features import ObservationSpec
from dfcoa_opt.control.policy.file import ACTIVATIONS, LoadedPolicy, PolicySpec
from dfcoa_opt.core.params import build

ROOT = Path(__file__).resolve().parents[2]
#: The observation vector: 40 LiDAR beams, 4 neighbours, 2 moving obstacles.
SPEC = ObservationSpec(beams=40, neighbours=4, obstacles=2, range=5.0, v_max=0.5)
#: Network output 1 is this many m/s (body frame, x forward, y left).
ACTION_SCALE = (0.5, 0.5)
#: Floor of the input standard deviations (inputs are scaled to about [-1, 1]).
STD_FLOOR = 0.05
#: ``(scenario file, overrides)`` the rollouts run on; seeds from TRAIN_SEED0 on.
TRAIN_SCENARIOS: tuple[tuple[str, dict[str, Any]], ...] = (
    ("scenarios/example_obstacles.toml", {"team.start_noise": 0.3, "team.heading_noise": 0.6}),
    ("scenarios/dfcoa_s1.toml", {"team.start_noise": 0.2, "team.heading_noise": 0.3}),
    ("scenarios/learned/clutter_rect.toml", {}),
    ("scenarios/learned/wall_gap.toml", {}),
    ("scenarios/learned/grid_circles.toml", {}),
)
#: First rollout seed (the evaluation uses seeds 0-19).
TRAIN_SEED0 = 1000


@dataclass(frozen=True)
class Budget:
    """How much to train.

    Attributes:
        hidden: Hidden layer widths (tanh).
        betas: Teacher weight of each round's rollouts (round 0: 1, the teacher).
        seeds: Rollout seeds per scenario and round.
        every: Record every ``every``-th step.
        epochs: Training epochs after each round's collection (one entry per round).
        batch: Minibatch rows.
        lr: Adam step size.
        t_max: Cap on each rollout's duration, s (None: the scenario's).
        teacher: ``(key, value)`` parameters of the teacher's ``cbf`` filter.
        scenarios: ``(scenario file, overrides)`` of the rollouts.
    """

    hidden: tuple[int, ...] = (64, 64)
    betas: tuple[float, ...] = (1.0, 0.5, 0.25, 0.0, 0.0, 0.0)
    seeds: int = 20
    every: int = 2
    epochs: tuple[int, ...] = (30, 10, 10, 10, 10, 20)
    batch: int = 256
    lr: float = 1e-3
    t_max: float | None = None
    teacher: tuple[tuple[str, Any], ...] = ()
    scenarios: tuple[tuple[str, dict[str, Any]], ...] = field(default=TRAIN_SCENARIOS)


#: The budget of the shipped weights.
FULL = Budget()
#: A budget of a few seconds (tests).
TINY = Budget(hidden=(8,), betas=(1.0, 0.0), seeds=2, every=10, epochs=(2, 1), t_max=6.0,
              scenarios=TRAIN_SCENARIOS[:2])


def spec_dict(hidden: tuple[int, ...], weights: str = "learned.npz") -> dict[str, Any]:
    """The JSON spec of the policy file (``docs/policies.md``)."""
    obs = {"beams": SPEC.beams, "neighbours": SPEC.neighbours, "obstacles": SPEC.obstacles,
           "range": SPEC.range, "v_max": SPEC.v_max}
    return {"format": "dfcoa-policy", "version": 1, "weights": weights, "command": "velocity",
            "frame": "body", "observation": obs, "normalize": True,
            "layers": [*({"size": h, "activation": "tanh"} for h in hidden),
                       {"size": 2, "activation": "linear"}],
            "clip": False, "action_scale": list(ACTION_SCALE), "action_offset": [0.0, 0.0]}


def arrays_of(layers: mlp.Layers, mean: np.ndarray, std: np.ndarray) -> dict[str, np.ndarray]:
    """The ``.npz`` arrays: ``W{i}``, ``b{i}``, ``obs_mean``, ``obs_std`` (float64)."""
    out = {}
    for i, (w, b) in enumerate(layers):
        out[f"W{i}"], out[f"b{i}"] = w.copy(), b.copy()
    out["obs_mean"], out["obs_std"] = mean.copy(), std.copy()
    return out


def as_policy(spec: dict[str, Any], arrays: dict[str, np.ndarray]) -> LoadedPolicy:
    """The in-memory policy the file would load as (the same kernel as ``policy:PATH``)."""
    ps = build(PolicySpec, spec, "<training>")
    layers = tuple((np.ascontiguousarray(arrays[f"W{i}"]), np.ascontiguousarray(arrays[f"b{i}"]),
                    ACTIVATIONS.index(layer.activation)) for i, layer in enumerate(ps.layers))
    return LoadedPolicy(ps, layers, arrays["obs_mean"], arrays["obs_std"],
                        (Path("<training>"), Path("<training>")))


def _log(msg: str, quiet: bool) -> None:
    if not quiet:
        print(msg, flush=True)


def train(seed: int, budget: Budget = FULL, quiet: bool = False
          ) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """Run DAgger and return the policy file's spec and arrays (OpenBLAS on one thread).

    The same seed and budget give the same arrays, bit for bit, on machines
    with the same OpenBLAS kernels (``dfcoa_opt/core/runtime/dispatch.py``); the training's
    matrix products run on one OpenBLAS thread (:func:`mlp.one_blas_thread`),
    as their rounding depends on the thread count.

    Args:
        seed: Sets the initial weights, the minibatch order and the rollout seeds.
        budget: Rounds, seeds, epochs, network size.
        quiet: No progress lines.

    Returns:
        ``(spec, arrays)``: the JSON spec (a dict) and the ``.npz`` arrays.
    """
    with mlp.one_blas_thread() as pinned:
        if not pinned and os.environ.get("OPENBLAS_NUM_THREADS") != "1":
            _log("warning: OpenBLAS not found to set one thread; the weights may depend on "
                 "the thread count (set OPENBLAS_NUM_THREADS=1)", quiet)
        return _train(seed, budget, quiet)


def _train(seed: int, budget: Budget, quiet: bool
           ) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """:func:`train` (its BLAS threads already set)."""
    import dfcoa_opt as d

    if not budget.betas or len(budget.epochs) != len(budget.betas) or budget.betas[0] != 1.0:
        raise ValueError("one epochs entry per round, and round 0 is the teacher (beta 1)")
    rng = np.random.default_rng(seed)
    spec = spec_dict(budget.hidden)
    layers = mlp.init_layers([SPEC.size, *budget.hidden, 2], rng)
    opt = mlp.Adam(lr=budget.lr)
    keys = {"t_max": budget.t_max} if budget.t_max is not None else {}
    scenarios = [d.load(ROOT / path, overrides={**over, **keys})
                 for path, over in budget.scenarios]
    x = np.zeros((0, SPEC.size))  # every row so far, standardized
    y = np.zeros((0, 2))
    mean = std = None
    policy = None
    t0 = time.perf_counter()
    for rnd, (beta, epochs) in enumerate(zip(budget.betas, budget.epochs, strict=True)):
        new_x, new_y = [], []
        for k, sc in enumerate(scenarios):
            start = TRAIN_SEED0 + 10_000 * seed + budget.seeds * (len(scenarios) * rnd + k)
            mix = Mixture(SPEC, ACTION_SCALE, beta, policy, budget.every,
                          {"cbf": dict(budget.teacher)})
            got = collect(sc, range(start, start + budget.seeds), mix)
            new_x.append(got.x)
            new_y.append(got.y)
            tally = ", ".join(f"{n} {o}" for o, n in sorted(Counter(got.outcomes).items()))
            _log(f"round {rnd} beta {beta:.2f} {sc.name}: {len(got.x)} rows; {tally}", quiet)
        if mean is None or std is None:  # from the teacher's rows of round 0, then fixed
            x0 = np.concatenate(new_x)
            mean, std = x0.mean(axis=0), np.maximum(x0.std(axis=0), STD_FLOOR)
            del x0
        x = np.concatenate([x, *((c - mean) / std for c in new_x)])
        y = np.concatenate([y, *new_y])
        del new_x, new_y
        hist = mlp.fit(layers, x, y, epochs, budget.batch, opt, rng)
        _log(f"round {rnd}: {len(x)} rows, {epochs} epochs, loss {hist[0]:.5f} -> "
             f"{hist[-1]:.5f} ({time.perf_counter() - t0:.0f} s)", quiet)
        arrays = arrays_of(layers, mean, std)
        policy = as_policy(spec, arrays)
    return spec, arrays


def save(out: Path, spec: dict[str, Any], arrays: dict[str, np.ndarray]) -> tuple[Path, Path]:
    """Write the spec and its weights (``learned.npz``) in ``out``, byte-reproducibly.

    The JSON is named after the weights (``spec["weights"]`` with ``.json``).

    ``np.savez`` stamps every member with the current time; writing the members
    through :mod:`zipfile` with a fixed date keeps the bytes a function of the arrays.
    """
    import zipfile

    out.mkdir(parents=True, exist_ok=True)
    npz = out / spec["weights"]
    with zipfile.ZipFile(npz, "w", zipfile.ZIP_STORED) as zf:
        for name, arr in arrays.items():
            buf = io.BytesIO()
            np.lib.format.write_array(buf, np.ascontiguousarray(arr), allow_pickle=False)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            zf.writestr(info, buf.getvalue())
    path = npz.with_suffix(".json")
    path.write_text(json.dumps(spec, indent=2) + "\n", encoding="utf-8")
    return path, npz


def main(argv: list[str] | None = None) -> int:
    """Command line: train from ``--seed`` and write the policy file into ``--out``."""
    ap = argparse.ArgumentParser(prog="python -m comparisons.learned.train",
                                 description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0, help="training seed (default 0)")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent,
                    help="folder of learned.json and learned.npz")
    ap.add_argument("--tiny", action="store_true", help="a few seconds' budget (tests)")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    spec, arrays = train(args.seed, TINY if args.tiny else FULL)
    files = save(args.out, spec, arrays)
    print(f"wrote {files[0]} and {files[1]} in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
