"""Benchmark harness: sweeps of scenario x controller x seed, cached results and reports.

- :mod:`~dfcoa_opt.bench.sweep`: sweep files expanded into runs;
- :mod:`~dfcoa_opt.bench.runner`, :mod:`~dfcoa_opt.bench.executors`,
  :mod:`~dfcoa_opt.bench.lifecycle`: running them (serial, processes, Dask);
- :mod:`~dfcoa_opt.bench.results`: the store of rows and logs, and the code fingerprint;
- :mod:`~dfcoa_opt.bench.report`: tables, statistics and figures of saved results;
- :mod:`~dfcoa_opt.bench.harness`, :mod:`~dfcoa_opt.bench.precision`,
  :mod:`~dfcoa_opt.bench.tune`, :mod:`~dfcoa_opt.bench.figures`: sweeps end to end,
  more seeds where a rate is not yet precise, tuning, ``make figures``;
- :mod:`~dfcoa_opt.bench.recipes`: the figure recipes, one module per paper or group.
"""
