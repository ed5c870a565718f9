"""Benchmarks run by ``make bench`` (not tests)."""

# first: numpy loads with the SIMD dispatch of every result (dfcoa_opt/core/runtime/dispatch.py)
import dfcoa_opt  # noqa: F401
