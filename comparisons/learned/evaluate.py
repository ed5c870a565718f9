"""Outcomes of a policy over seeds 0-19 on the target and the common scenarios.

Usage::

    python -m comparisons.learned.evaluate [--controller learned] [--seeds 20]

prints one line per scenario: the count of each ``metrics["outcome"]``, the
mean formation error and the wall time of the batch (``dfcoa_opt.run_batch``).
"""

from __future__ import annotations

import dfcoa_opt  # noqa: F401 - first: pins numpy's SIMD and OpenBLAS kernels (dispatch.py)

# isort: split
import argparse
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
#: The two target scenarios, then the seven common comparison scenarios.
SCENARIOS = ("example_obstacles.toml", "dfcoa_s1.toml", "dfcoa_s2.toml", "bench/clutter.toml",
             "bench/corridor.toml", "bench/crossing.toml", "bench/large_20.toml",
             "bench/large_100.toml")


def evaluate(controller: str, scenario: str, seeds: int) -> tuple[Counter[str], float, float]:
    """Outcomes of ``controller`` on ``scenario`` (under ``scenarios/``) for seeds 0..seeds-1.

    Returns:
        ``(outcome counts, mean fce_rms (m) over the runs, wall time (s))``.
    """
    import dfcoa_opt as d

    t0 = time.perf_counter()
    runs = d.run_batch(ROOT / "scenarios" / scenario, controller, range(seeds))
    wall = time.perf_counter() - t0
    fce = float(np.nanmean([r.metrics.get("fce_rms", np.nan) for r in runs]))
    return Counter(str(r.metrics["outcome"]) for r in runs), fce, wall


def main(argv: list[str] | None = None) -> int:
    """Command line (module docstring)."""
    ap = argparse.ArgumentParser(prog="python -m comparisons.learned.evaluate",
                                 description=__doc__.splitlines()[0])
    ap.add_argument("--controller", default="learned", help="controller id (default learned)")
    ap.add_argument("--seeds", type=int, default=20, help="seeds 0..N-1 (default 20)")
    ap.add_argument("--only", nargs="*", default=None, help="scenario files (under scenarios/)")
    args = ap.parse_args(argv)
    for sc in args.only or SCENARIOS:
        counts, fce, wall = evaluate(args.controller, sc, args.seeds)
        tally = ", ".join(f"{n} {o}" for o, n in sorted(counts.items()))
        print(f"{sc:24s} {tally:40s} fce_rms {fce:.3f} m  ({wall:.1f} s)", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
