"""Statistics of the report against published values and independent computations."""

import itertools
import math
import warnings

import numpy as np
import pytest
from scipy import optimize
from scipy import stats as sps

from dfcoa_opt.bench.report import stats


# ------------------------------------------------------------------------- Wilson
@pytest.mark.parametrize("k, n, lo, hi", [
    # Newcombe (1998), Statistics in Medicine 17:857-872, Table I, method 3 (score interval)
    (81, 263, 0.2553, 0.3662), (15, 148, 0.0624, 0.1605), (0, 20, 0.0, 0.1611),
    (1, 29, 0.0061, 0.1718),
])
def test_wilson_matches_newcombe_1998(k, n, lo, hi):
    got = stats.wilson_interval(k, n)
    assert got == pytest.approx((lo, hi), abs=5e-5)


def test_wilson_inverts_the_score_test():
    """The bounds are where the score statistic |p_hat - p| / sqrt(p (1-p) / n) equals z."""
    rng = np.random.default_rng(7)
    for _ in range(50):
        n = int(rng.integers(1, 200))
        k = int(rng.integers(0, n + 1))
        p_hat = k / n

        def score(p, p_hat=p_hat, n=n):
            return abs(p_hat - p) / math.sqrt(p * (1 - p) / n) - stats.Z95

        lo, hi = stats.wilson_interval(k, n)
        if k > 0:
            assert lo == pytest.approx(optimize.brentq(score, 1e-12, min(p_hat, 1 - 1e-12)),
                                    abs=1e-9)
        else:
            assert lo == 0.0
        if k < n:
            assert hi == pytest.approx(optimize.brentq(score, max(p_hat, 1e-12), 1 - 1e-12),
                                    abs=1e-9)
        else:
            assert hi == 1.0


def test_half_widths_the_ladders_rely_on():
    assert max(stats.wilson_half_width(k, 40) for k in range(41)) <= 0.15
    assert stats.wilson_half_width(0, 20) == pytest.approx(0.0806, abs=1e-4)
    assert stats.wilson_half_width(10, 20) > 0.15
    assert stats.wilson_half_width(0, 10) < 0.15  # a cell that never succeeds settles at 10
    assert all(math.isnan(v) for v in stats.wilson_interval(0, 0))
    with pytest.raises(ValueError):
        stats.wilson_interval(5, 4)


# ---------------------------------------------------------------- paired differences
def test_paired_difference_is_reproducible_and_drops_undefined_pairs():
    rng = np.random.default_rng(3)
    x = rng.normal(1.0, 1.0, 20)
    y = x - rng.normal(0.5, 0.3, 20)
    a = stats.paired_difference(list(x), list(y), seed=5)
    b = stats.paired_difference(list(x), list(y), seed=5)
    assert a == b  # bit for bit
    assert a.ci_low <= a.median <= a.ci_high and a.n == 20
    assert a.median == pytest.approx(np.median(x - y))
    xs, ys = list(x), list(y)
    xs[0], ys[1], xs[2] = None, float("nan"), float("inf")
    dropped = stats.paired_difference(xs, ys)
    assert (dropped.n, dropped.excluded, a.excluded) == (17, 3, 0)
    none = stats.paired_difference([float("inf")] * 2, [1.0, 2.0])
    assert (none.n, none.excluded) == (0, 2) and math.isnan(none.median)


def test_a_constant_shift_has_a_degenerate_interval():
    x = [3.0, 5.0, 2.0, 8.0]
    d = stats.paired_difference(x, [v - 1.0 for v in x])
    assert (d.median, d.ci_low, d.ci_high) == (1.0, 1.0, 1.0)
    zero = stats.paired_difference(x, x)
    assert (zero.median, zero.p_value) == (0.0, 1.0)
    one = stats.paired_difference([1.0], [0.0])
    assert one.n == 1 and math.isnan(one.ci_low)
    assert stats.paired_difference([], []).n == 0


def test_bootstrap_interval_covers_the_true_median_shift():
    """Percentile bootstrap of the median: covers the true shift in most of 200 samples."""
    rng = np.random.default_rng(11)
    hits = 0
    for i in range(200):
        d = rng.normal(0.7, 1.0, 25)
        r = stats.paired_difference(list(d), [0.0] * 25, seed=i, n_resamples=999)
        hits += r.ci_low <= 0.7 <= r.ci_high
    assert 0.88 <= hits / 200 <= 0.99


def _exact_signed_rank_p(d):
    """Two-sided exact Wilcoxon p-value by enumerating all 2^n sign assignments."""
    ranks = sps.rankdata(np.abs(d))
    w = ranks[d > 0].sum()
    total = ranks.sum()
    stat = min(w, total - w)
    count = 0
    for signs in itertools.product((0, 1), repeat=len(d)):
        s = sum(r for r, g in zip(ranks, signs, strict=True) if g)
        count += min(s, total - s) <= stat
    return count / 2 ** len(d)


def test_wilcoxon_against_exact_enumeration_and_scipy():
    rng = np.random.default_rng(5)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for n in (4, 6, 9):
            x = rng.normal(0.5, 1.0, n)
            y = rng.normal(0.0, 1.0, n)
            p = stats.paired_difference(list(x), list(y)).p_value
            assert p == pytest.approx(_exact_signed_rank_p(x - y), rel=1e-9)
            assert p == pytest.approx(sps.wilcoxon(x - y).pvalue, rel=1e-12)
        # ties and zeros: no warning escapes, zeros are dropped ("wilcox")
        p = stats.paired_difference([1, 2, 2, 3, 5, 5], [1, 1, 1, 1, 1, 1]).p_value
        assert p == pytest.approx(_exact_signed_rank_p(np.array([1, 1, 2, 4, 4.0])), rel=0.3)


# ------------------------------------------------------------------------- McNemar
def test_mcnemar_textbook_example_and_binomial_sum():
    a = [True] * 9 + [False] + [True] * 5   # 9 variant-only wins, 1 baseline-only win
    b = [False] * 9 + [True] + [True] * 5
    m = stats.mcnemar_exact(a, b)
    assert (m.b01, m.b10, m.n) == (1, 9, 15)
    assert m.p_value == pytest.approx(0.021484375)  # 2 * (1 + 10) / 2^10
    assert m.p_value == pytest.approx(2 * sum(math.comb(10, k) for k in (0, 1)) / 2 ** 10)
    assert m.difference == pytest.approx(8 / 15)
    assert stats.mcnemar_exact([True, False], [True, False]).p_value == 1.0
    assert math.isnan(stats.mcnemar_exact([], []).p_value)
    # one-sided, the variant better: P(X >= 9), X ~ Bin(10, 1/2) = 11 / 2^10, half the above
    assert stats.mcnemar_greater_p(m) == pytest.approx(11 / 2 ** 10)
    worse = stats.mcnemar_exact(b, a)  # the baseline better: P(X >= 1) = 1 - 1 / 2^10
    assert stats.mcnemar_greater_p(worse) == pytest.approx(1 - 1 / 2 ** 10)
    assert stats.mcnemar_greater_p(stats.mcnemar_exact([True, False], [True, False])) == 1.0


# --------------------------------------------------------------------------- Holm
def test_mcnemar_sample_size_by_hand():
    # p_only_a = 0.20, p_only_b = 0.05: p_disc = 0.25, d = 0.15, d^2 = 0.0225;
    # z_0.975 sqrt(p_disc)       = 1.959964 * 0.5               = 0.979982
    # z_0.80 sqrt(p_disc - d^2) = 0.841621 * sqrt(0.2275) = 0.841621 * 0.476970 = 0.401428
    # n = (0.979982 + 0.401428)^2 / 0.0225 = 1.381410^2 / 0.0225 = 1.908293 / 0.0225 = 84.813
    assert stats.mcnemar_sample_size(0.20, 0.05) == pytest.approx(84.813, abs=1e-3)
    assert stats.mcnemar_sample_size(0.05, 0.20) == stats.mcnemar_sample_size(0.20, 0.05)
    # the worked example of Connor's formula (p10 = 0.05, p01 = 0.45, two-sided 5 %, 80 %
    # power) in the R code of powerandsamplesize.com's McNemar calculator: 23 pairs
    assert math.ceil(stats.mcnemar_sample_size(0.05, 0.45)) == 23
    # more power, a stricter alpha or a smaller difference all need more pairs
    assert stats.mcnemar_sample_size(0.20, 0.05, power=0.9) > 84.813
    assert stats.mcnemar_sample_size(0.20, 0.05, alpha=0.01) > 84.813
    assert stats.mcnemar_sample_size(0.15, 0.05) > 84.813


def test_mcnemar_sample_size_has_no_estimate_without_a_difference():
    assert math.isnan(stats.mcnemar_sample_size(0.1, 0.1))
    assert math.isnan(stats.mcnemar_sample_size(0.0, 0.0))
    for bad in ((0.7, 0.5), (-0.1, 0.2), (0.2, 1.5)):
        with pytest.raises(ValueError, match="discordant"):
            stats.mcnemar_sample_size(*bad)
    with pytest.raises(ValueError, match="alpha and power"):
        stats.mcnemar_sample_size(0.2, 0.1, alpha=0.0)


def test_holm_textbook_example():
    assert stats.holm([0.01, 0.04, 0.03, 0.005]) == pytest.approx([0.03, 0.06, 0.06, 0.02])


def _holm_by_definition(p):
    p = np.asarray(p, float)
    m = len(p)
    order = np.argsort(p, kind="stable")
    out = np.empty(m)
    for i, j in enumerate(order):
        out[j] = min(1.0, max((m - k) * p[order[k]] for k in range(i + 1)))
    return out


def test_holm_equals_its_definition_and_ignores_nan():
    rng = np.random.default_rng(2)
    for _ in range(100):
        p = rng.uniform(0, 0.2, int(rng.integers(1, 12)))
        np.testing.assert_allclose(stats.holm(p), _holm_by_definition(p), rtol=1e-12)
    adj = stats.holm([0.01, float("nan"), 0.02])
    assert math.isnan(adj[1]) and adj[[0, 2]] == pytest.approx([0.02, 0.02])


def test_verdict_direction():
    assert stats.verdict(0.2, 0.01, higher_is_better=True) == "better"
    assert stats.verdict(0.2, 0.01, higher_is_better=False) == "worse"
    assert stats.verdict(-0.2, 0.01, higher_is_better=False) == "better"
    assert stats.verdict(0.2, 0.2, higher_is_better=True) == "no difference"
    assert stats.verdict(float("nan"), 0.01, higher_is_better=True) == "no difference"
