"""Benchmark harness: sweeps of scenario x controller x seed, cached results and reports."""
