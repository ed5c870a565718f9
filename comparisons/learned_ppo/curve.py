"""Plot ``learned_ppo``'s learning curve: episode return and outcome shares against steps.

Usage::

    python -m comparisons.learned_ppo.curve [--csv comparisons/learned_ppo/curve.csv]
        [--out docs/methods/learned_ppo_curve.png] [--bins 40]

reads the curve the training writes (one row per rollout) and draws, in bins of
equal robot steps, the mean return of the episodes that ended in the bin
(weighted by their count) and the share of each outcome; dashed lines mark the
curriculum's stages.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]


def read_curve(path: Path) -> dict[str, np.ndarray]:
    """The CSV's columns as float arrays."""
    lines = path.read_text(encoding="utf-8").split()
    cols = lines[0].split(",")
    data = np.array([[float(v) for v in line.split(",")] for line in lines[1:]])
    return {c: data[:, i] for i, c in enumerate(cols)}


def binned(curve: dict[str, np.ndarray], bins: int) -> dict[str, np.ndarray]:
    """Episode-weighted means of ``return`` and the outcome shares in ``bins`` step bins."""
    steps, n = curve["steps"], curve["episodes"]
    edges = np.linspace(0.0, steps.max(), bins + 1)
    idx = np.clip(np.searchsorted(edges, steps, side="left") - 1, 0, bins - 1)
    out = {"steps": 0.5 * (edges[1:] + edges[:-1])}
    weight = np.bincount(idx, weights=n, minlength=bins)
    for key in ("return", "success", "collision", "deadlock", "timeout"):
        vals = np.nan_to_num(curve[key]) * n
        with np.errstate(invalid="ignore", divide="ignore"):
            out[key] = np.bincount(idx, weights=vals, minlength=bins) / weight
    return out


def plot(curve: dict[str, np.ndarray], out: Path, bins: int) -> None:
    """Draw the two panels into ``out`` (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    b = binned(curve, bins)
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(7.0, 5.5), sharex=True)
    x = b["steps"] / 1e6
    ax1.plot(x, b["return"], color="C0")
    ax1.set_ylabel("episode return")
    for key, color in (("success", "C2"), ("collision", "C3"), ("deadlock", "C1"),
                       ("timeout", "C7")):
        ax2.plot(x, 100.0 * b[key], label=key, color=color)
    ax2.set_ylabel("episodes ending so (%)")
    ax2.set_xlabel("robot steps (millions)")
    ax2.set_ylim(-2, 102)
    ax2.legend(loc="center right", fontsize=8)
    stages = curve["stage"]
    for k in np.flatnonzero(np.diff(stages)):
        for ax in (ax1, ax2):
            ax.axvline(curve["steps"][k] / 1e6, color="k", ls="--", lw=0.8)
    ax1.set_title("learned_ppo: PPO training (episodes that ended, per bin)")
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110, metadata={"Software": None})
    plt.close(fig)


def main(argv: Sequence[str] | None = None) -> int:
    """Command line (module docstring)."""
    ap = argparse.ArgumentParser(prog="python -m comparisons.learned_ppo.curve",
                                 description=__doc__.splitlines()[0])
    ap.add_argument("--csv", type=Path, default=HERE / "curve.csv")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "methods" /
                    "learned_ppo_curve.png")
    ap.add_argument("--bins", type=int, default=40)
    args = ap.parse_args(argv)
    plot(read_curve(args.csv), args.out, args.bins)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
