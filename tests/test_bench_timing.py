"""benchmarks.timing: interleaved repetitions and the per-repetition ratio of each row."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.timing import blocks, interleave, ratio_text, row


def test_interleave_warms_up_then_alternates_the_order_every_repetition():
    calls: list[str] = []
    out = interleave({"a": (lambda k: calls.append("a"), 2),
                      "b": (lambda k: calls.append("b"), 1)}, reps=3)
    assert calls == ["a", "b",  # warm-up
                     "a", "a", "b", "b", "a", "a", "a", "a", "b"]
    assert [len(x) for x in out["a"]] == [2, 2, 2] and [len(x) for x in out["b"]] == [1, 1, 1]


def test_row_ratio_is_the_median_of_the_repetitions_ratios():
    ours = [np.array([1.0, 1.0]), np.array([2.0, 2.0]), np.array([1.0, 3.0])]
    ref = [np.array([3.0]), np.array([2.0]), np.array([10.0])]
    r = row("x", ours, "ref", ref)
    # per repetition: 3 / 1, 2 / 2, 10 / 2 -> median 3, min 1, max 5
    assert (r["ratio"], r["ratio_min"], r["ratio_max"], r["reps"]) == (3.0, 1.0, 5.0, 3)
    assert r["median_us"] == 1.5 and r["samples"] == 6 and r["ref_median_us"] == 3.0
    assert ratio_text(r) == "3.00x (1.00-5.00, 3 reps)"
    with pytest.raises(ValueError, match="3 repetitions of ours, 2 of the reference"):
        row("x", ours, "ref", ref[:2])
    assert "ratio" not in row("no peer", np.array([1.0, 2.0]))


def test_blocks_split_paired_samples_in_order():
    parts = blocks(np.arange(12.0), reps=5)
    assert len(parts) == 5 and np.array_equal(np.concatenate(parts), np.arange(12.0))
