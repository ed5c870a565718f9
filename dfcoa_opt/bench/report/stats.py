"""Statistics that let a report rank methods: rates with intervals, paired tests, Holm.

Every variant of a sweep runs on the same seeds, so a variant and the baseline
are compared seed by seed (paired). Conventions:

- rates are fractions in [0, 1] with Wilson score intervals (good coverage at
  small n and at rates near 0 or 1, where the normal interval fails);
- a paired metric is summarised by the median of the per-seed differences
  ``x - y`` with a percentile bootstrap CI (:func:`scipy.stats.bootstrap`; the
  median is not smooth, and BCa's jackknife acceleration is unreliable for it
  with few seeds and many ties) and tested with the two-sided Wilcoxon
  signed-rank test (:func:`scipy.stats.wilcoxon`, ``zero_method="wilcox"``:
  seeds with equal values carry no sign information and are dropped);
- paired success is tested with McNemar's exact test (a binomial test on the
  discordant seeds, :func:`scipy.stats.binomtest`);
- the p-values of one table are corrected together by Holm's step-down method;
- the pairs McNemar's test would need at observed discordant proportions come
  from Connor's (1987) normal approximation.

Everything is deterministic: the bootstrap draws from a ``np.random.Generator``
seeded by the caller.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import stats as sps

#: Two-sided 95 % standard normal quantile.
Z95 = 1.959963984540054


def _z(confidence: float) -> float:
    return Z95 if confidence == 0.95 else float(sps.norm.ppf(0.5 + confidence / 2.0))


def wilson_interval(successes: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion.

    Args:
        successes: Successes, ``0 <= successes <= n``.
        n: Trials.
        confidence: Two-sided confidence level.

    Returns:
        ``(low, high)`` as fractions; ``(nan, nan)`` when ``n == 0``.

    Raises:
        ValueError: ``successes`` outside ``[0, n]``.
    """
    if not 0 <= successes <= n:
        raise ValueError(f"successes must be in [0, {n}], got {successes}")
    if n == 0:
        return math.nan, math.nan
    z = _z(confidence)
    p = successes / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    # at 0 or n successes one bound is exactly 0 or 1; keep rounding from moving it
    lo = 0.0 if successes == 0 else max(0.0, centre - half)
    hi = 1.0 if successes == n else min(1.0, centre + half)
    return lo, hi


def wilson_half_width(successes: int, n: int, confidence: float = 0.95) -> float:
    """Half the width of :func:`wilson_interval` (fraction; NaN when ``n == 0``)."""
    lo, hi = wilson_interval(successes, n, confidence)
    return (hi - lo) / 2.0


def _finite_pairs(x: Sequence[Any], y: Sequence[Any]) -> tuple[NDArray[np.float64],
                                                                NDArray[np.float64]]:
    """The pairs where both values are finite numbers (None, NaN, inf dropped)."""
    if len(x) != len(y):
        raise ValueError(f"paired samples differ in length: {len(x)} and {len(y)}")
    a = np.array([np.nan if v is None else float(v) for v in x], dtype=float)
    b = np.array([np.nan if v is None else float(v) for v in y], dtype=float)
    keep = np.isfinite(a) & np.isfinite(b)
    return a[keep], b[keep]


@dataclass(frozen=True)
class PairedDifference:
    """Median paired difference ``x - y``, its bootstrap CI and the Wilcoxon p-value.

    Attributes:
        n: Pairs used (both values finite).
        excluded: Pairs left out because a value was not finite (None, NaN or inf:
            a failed run, no time to goal, a risk after a contact).
        median: Median of the differences, in the values' unit (NaN when n = 0).
        ci_low: Lower end of the percentile bootstrap CI of the median (NaN when n < 2).
        ci_high: Upper end.
        p_value: Two-sided Wilcoxon signed-rank p-value (1 when every difference is
            zero, NaN when n = 0).
    """

    n: int
    median: float
    ci_low: float
    ci_high: float
    p_value: float
    excluded: int = 0


def paired_difference(x: Sequence[Any], y: Sequence[Any], *, seed: int = 0,
                      n_resamples: int = 9999, confidence: float = 0.95) -> PairedDifference:
    """Compare paired samples (aligned by seed): median difference, CI, Wilcoxon test.

    Args:
        x: The variant's values, one per seed.
        y: The baseline's values on the same seeds.
        seed: Seed of the bootstrap's generator (results are reproducible bit for bit).
        n_resamples: Bootstrap resamples.
        confidence: Confidence level of the CI.

    Returns:
        The :class:`PairedDifference` of the pairs whose values are both finite
        (``excluded`` counts the others). With identical differences the CI is
        that value (no resampling can change it); with fewer than two pairs it
        is NaN.
    """
    a, b = _finite_pairs(x, y)
    d = a - b
    n = int(d.size)
    excluded = len(x) - n
    if n == 0:
        return PairedDifference(0, math.nan, math.nan, math.nan, math.nan, excluded)
    med = float(np.median(d))
    if np.all(d == d[0]):
        lo = hi = med if n >= 2 else math.nan
        return PairedDifference(n, med, lo, hi, 1.0 if d[0] == 0 else _wilcoxon(d), excluded)
    lo = hi = math.nan
    if n >= 2:
        res = sps.bootstrap((d,), np.median, n_resamples=n_resamples, vectorized=True,
                            confidence_level=confidence, method="percentile",
                            rng=np.random.default_rng(seed))
        lo, hi = float(res.confidence_interval.low), float(res.confidence_interval.high)
    return PairedDifference(n, med, lo, hi, _wilcoxon(d), excluded)


def _wilcoxon(d: NDArray[np.float64]) -> float:
    """Two-sided Wilcoxon signed-rank p-value of differences ``d`` (zeros dropped)."""
    nz = d[d != 0]
    if nz.size == 0:
        return 1.0
    with warnings.catch_warnings():
        # scipy warns that the exact distribution is unavailable with ties and
        # falls back to the normal approximation: expected with repeated values.
        warnings.simplefilter("ignore", UserWarning)
        return float(sps.wilcoxon(nz, zero_method="wilcox", alternative="two-sided").pvalue)


@dataclass(frozen=True)
class McNemar:
    """McNemar's exact test of paired binary outcomes (a: variant, b: baseline).

    Attributes:
        n: Pairs.
        b01: Pairs where a failed and b succeeded.
        b10: Pairs where a succeeded and b failed.
        p_value: Exact two-sided p-value (1 without discordant pairs; NaN when n = 0).
        difference: ``(sum(a) - sum(b)) / n``, the difference of the success rates.
    """

    n: int
    b01: int
    b10: int
    p_value: float
    difference: float


def mcnemar_exact(a: Sequence[bool], b: Sequence[bool]) -> McNemar:
    """McNemar's exact test: binomial test of ``b10`` among the discordant pairs, p = 1/2."""
    if len(a) != len(b):
        raise ValueError(f"paired samples differ in length: {len(a)} and {len(b)}")
    x, y = np.asarray(a, dtype=bool), np.asarray(b, dtype=bool)
    n = int(x.size)
    b01, b10 = int(np.sum(~x & y)), int(np.sum(x & ~y))
    if n == 0:
        return McNemar(0, 0, 0, math.nan, math.nan)
    p = 1.0 if b01 + b10 == 0 else float(sps.binomtest(b10, b01 + b10, 0.5).pvalue)
    return McNemar(n, b01, b10, p, (b10 - b01) / n)


def mcnemar_greater_p(test: McNemar) -> float:
    """One-sided p-value of McNemar's exact test that ``a`` succeeds more often than ``b``.

    ``P(X >= b10)`` for ``X ~ Binomial(b01 + b10, 1/2)``: 1 without discordant pairs.
    """
    n = test.b01 + test.b10
    return 1.0 if n == 0 else float(sps.binom.sf(test.b10 - 1, n, 0.5))


def mcnemar_sample_size(p_only_a: float, p_only_b: float, alpha: float = 0.05,
                        power: float = 0.8) -> float:
    """Pairs McNemar's test needs to tell two paired success rates apart (Connor 1987).

    Connor's normal approximation (R. J. Connor, "Sample size for testing
    differences in proportions for the paired-sample design", Biometrics 43(1),
    1987, 207-211, p. 209), two-sided::

        n = (z_{1-alpha/2} sqrt(p_disc) + z_{power} sqrt(p_disc - d^2))^2 / d^2

    with ``p_disc = p_only_a + p_only_b`` the proportion of discordant pairs and
    ``d = p_only_a - p_only_b`` their difference (= the difference of the two
    success rates). At alpha 0.05 and power 0.8, ``z`` are 1.95996 and 0.84162.

    Args:
        p_only_a: Proportion of the pairs (worlds) where only ``a`` succeeded, in [0, 1].
        p_only_b: Proportion where only ``b`` succeeded; ``p_only_a + p_only_b <= 1``.
        alpha: Two-sided significance level of the test, in (0, 1).
        power: Probability of a significant result at these proportions, in (0, 1).

    Returns:
        The number of pairs (worlds), not rounded (round up for a plan); NaN when
        ``d == 0`` (no difference to detect, no estimate).

    Raises:
        ValueError: A proportion outside [0, 1], their sum above 1, or ``alpha`` or
            ``power`` outside (0, 1).
    """
    if not (0.0 <= p_only_a <= 1.0 and 0.0 <= p_only_b <= 1.0
            and p_only_a + p_only_b <= 1.0 + 1e-12):
        raise ValueError(f"discordant proportions must be in [0, 1] with a sum <= 1, got "
                         f"{p_only_a} and {p_only_b}")
    if not (0.0 < alpha < 1.0 and 0.0 < power < 1.0):
        raise ValueError(f"alpha and power must be in (0, 1), got {alpha} and {power}")
    d = p_only_a - p_only_b
    if d == 0.0:
        return math.nan
    p_disc = p_only_a + p_only_b
    z_alpha, z_power = _z(1.0 - alpha), float(sps.norm.ppf(power))
    # p_disc >= |d| >= d^2, so the root is real; max() only absorbs rounding
    root = z_alpha * math.sqrt(p_disc) + z_power * math.sqrt(max(0.0, p_disc - d * d))
    return root * root / (d * d)


def holm(p_values: Sequence[float]) -> NDArray[np.float64]:
    """Holm-Bonferroni adjusted p-values (step-down, monotone, capped at 1).

    NaN entries stay NaN and do not count among the ``m`` tests.
    """
    p = np.asarray(p_values, dtype=float)
    out = np.full(p.shape, np.nan)
    idx = np.flatnonzero(np.isfinite(p))
    m = idx.size
    if m == 0:
        return out
    order = idx[np.argsort(p[idx], kind="stable")]
    adjusted = np.minimum(1.0, np.maximum.accumulate((m - np.arange(m)) * p[order]))
    out[order] = adjusted
    return out


def verdict(difference: float, adjusted_p: float, higher_is_better: bool,
            alpha: float = 0.05) -> str:
    """``"better"``, ``"worse"`` or ``"no difference"`` for a variant against the baseline.

    Significant (``adjusted_p < alpha``) with a positive difference is better when
    higher is better, worse otherwise; a NaN difference or p-value, a zero
    difference or a p-value at or above ``alpha`` is ``"no difference"`` (an
    untestable cell, e.g. no paired values, says nothing either way).
    """
    if not (math.isfinite(difference) and math.isfinite(adjusted_p)) or difference == 0:
        return "no difference"
    if adjusted_p >= alpha:
        return "no difference"
    return "better" if (difference > 0) == higher_is_better else "worse"


def cvar(values: Sequence[float], alpha: float = 0.9) -> float:
    """Conditional value at risk: the mean of the worst ``1 - alpha`` of ``values`` (upper tail).

    The discrete definition of Rockafellar and Uryasev (2002) with equal weights:
    the ``m = (1 - alpha) n`` largest values are averaged, the last of them
    counted with its fractional weight ``m - floor(m)``; with ``m <= 1`` it is
    the largest value. Larger is worse (errors, times); NaN counts as ``inf``
    (a run with no value is a worst case).

    Args:
        values: The sample (at least one value).
        alpha: Confidence level in ``[0, 1)``.

    Returns:
        The CVaR, in the values' unit.

    Raises:
        ValueError: No values, or ``alpha`` outside ``[0, 1)``.
    """
    if not 0.0 <= alpha < 1.0:
        raise ValueError(f"alpha must be in [0, 1), got {alpha}")
    x = np.sort(np.nan_to_num(np.asarray(values, dtype=float), nan=np.inf))[::-1]
    if len(x) == 0:
        raise ValueError("cvar needs at least one value")
    m = (1.0 - alpha) * len(x)
    if m <= 1.0:
        return float(x[0])
    whole = int(math.floor(m))
    total = float(x[:whole].sum())
    if m > whole:
        total += (m - whole) * float(x[whole])
    return total / m
