"""Benchmark harness: sweeps of scenario x controller x seed, cached results and reports.

The figure recipes live in :mod:`dfcoa_opt.bench.recipes`, one module per paper
or group. Their module paths of release 0.1 (``dfcoa_opt.bench.recipes_astar``,
...) still import, with a :class:`DeprecationWarning` naming the new path,
until 0.3.
"""

from dfcoa_opt.core.moved import keep_old_paths

keep_old_paths({f"dfcoa_opt.bench.recipes_{m}": f"dfcoa_opt.bench.recipes.{m}"
                for m in ("astar", "beyond", "dfcoa", "paper001", "paper002", "paper004")},
               removal="0.3")
