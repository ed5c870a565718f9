"""Timing helpers shared by the ``benchmarks/bench_*`` modules.

Every ratio in ``benchmarks/results.md`` compares our code with a reference
measured in the same process. The machine is noisy (2 shared cores), so a
ratio is never taken from one block of calls: :func:`interleave` times the
candidates in :data:`REPS` alternating repetitions (the order flips every
repetition, so a slow spell hits both sides), and :func:`row` reports the
median of the per-repetition ratios with their min-max, so one noisy
repetition cannot flip a verdict.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping

import numpy as np

#: Interleaved repetitions per comparison (issue 21: at least 5).
REPS = 5


def time_calls(fn: Callable[[int], object], samples: int, warm: bool = True) -> np.ndarray:
    """Per-call times in us of ``fn(k)`` for ``k = 0 .. samples-1`` (after one warm-up call)."""
    if warm:
        fn(0)
    out = np.empty(samples)
    for k in range(samples):
        t0 = time.perf_counter()
        fn(k)
        out[k] = time.perf_counter() - t0
    return out * 1e6


def interleave(calls: Mapping[str, tuple[Callable[[int], object], int]],
               reps: int = REPS) -> dict[str, list[np.ndarray]]:
    """Time several candidates in alternating repetitions.

    Args:
        calls: Name -> (``fn(k)``, calls per repetition). Each ``fn`` is called
            once to warm up (numba compilation, caches) before any timing.
        reps: Repetitions; in odd ones the candidates run in reverse order.

    Returns:
        Name -> one array of per-call times (us) per repetition.
    """
    for fn, _ in calls.values():
        fn(0)
    out: dict[str, list[np.ndarray]] = {name: [] for name in calls}
    names = list(calls)
    for rep in range(reps):
        for name in (names if rep % 2 == 0 else names[::-1]):
            fn, samples = calls[name]
            out[name].append(time_calls(fn, samples, warm=False))
    return out


def row(what: str, ours: list[np.ndarray] | np.ndarray, reference: str = "",
        ref: list[np.ndarray] | np.ndarray | None = None) -> dict:
    """One result row: our median and min-max (us) and the ratio ``ref / ours``.

    Args:
        what: Row title.
        ours: Our per-call times (us): one array per repetition (from
            :func:`interleave` or :func:`blocks`), or one array.
        reference: The reference's name ("" = no peer).
        ref: The reference's times, repetition for repetition as ``ours``.

    Returns:
        ``median_us``, ``min_us``, ``max_us``, ``samples`` of ours; with a
        reference also ``ref_median_us``, ``ratio`` (median over repetitions of
        ``median(ref) / median(ours)``), ``ratio_min``, ``ratio_max`` and ``reps``.
    """
    ours_reps = [np.asarray(a) for a in ours] if isinstance(ours, list) else [np.asarray(ours)]
    flat = np.concatenate(ours_reps)
    out = {"what": what, "median_us": float(np.median(flat)), "min_us": float(flat.min()),
           "max_us": float(flat.max()), "samples": len(flat), "reference": reference}
    if ref is None:
        return out
    ref_reps = [np.asarray(a) for a in ref] if isinstance(ref, list) else [np.asarray(ref)]
    if len(ref_reps) != len(ours_reps):
        raise ValueError(f"{what}: {len(ours_reps)} repetitions of ours, {len(ref_reps)} of "
                         "the reference")
    ratios = np.array([np.median(r) / np.median(o) for o, r in zip(ours_reps, ref_reps,
                                                                    strict=True)])
    return {**out, "ref_median_us": float(np.median(np.concatenate(ref_reps))),
            "ratio": float(np.median(ratios)), "ratio_min": float(ratios.min()),
            "ratio_max": float(ratios.max()), "reps": len(ratios)}


def blocks(times: np.ndarray, reps: int = REPS) -> list[np.ndarray]:
    """Split per-call times measured call for call alternately into ``reps`` blocks."""
    return [np.asarray(b) for b in np.array_split(np.asarray(times), reps)]


def ratio_text(r: dict) -> str:
    """``"1.23x (1.10-1.40, 5 reps)"``, or ``"1.23x (1 rep)"``."""
    if r.get("reps", 1) > 1:
        return f"{r['ratio']:.2f}x ({r['ratio_min']:.2f}-{r['ratio_max']:.2f}, {r['reps']} reps)"
    return f"{r['ratio']:.2f}x (1 rep)"


def print_rows(rows: list[dict]) -> None:
    """Print rows made by :func:`row`, one line each (``python -m benchmarks.bench_*``)."""
    for r in rows:
        line = (f"{r['what']}: median {r['median_us']:.1f} us (min {r['min_us']:.1f}, "
                f"max {r['max_us']:.1f}, n={r['samples']})")
        if "ratio" in r:
            line += f"; {r['reference']}: {r['ref_median_us']:.1f} us; ratio {ratio_text(r)}"
        print(line)
