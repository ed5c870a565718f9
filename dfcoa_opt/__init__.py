"""dfcoa_opt: multi-robot formation control with obstacle avoidance.

The DFCOA reference implementation (paper 000), companion-paper controllers
(package ``comparisons``), a simulator with LiDAR and a benchmark harness.

From Python (:mod:`dfcoa_opt.api`)::

    import dfcoa_opt as d

    s = d.load("scenarios/dfcoa_s1.toml")      # a Scenario (overrides as keywords)
    r = d.run(s, "dfcoa", seed=0)              # a Run: .log, .metrics, .plot(), .animate()
    print(r.metrics["outcome"], d.controllers())
    res = d.sweep("scenarios/sweeps/examples.toml", "results/examples")   # a Results
    res.table(); res.report()                  # rows (a DataFrame with pandas); report.md

``d.register("my_id")`` registers a controller class (README, "Add your own
controller").
"""

import importlib.util as _util
from pathlib import Path as _Path

from dfcoa_opt.core.runtime import dispatch as _dispatch

# before anything imports numpy: the same SIMD loops, so the same bits, on every x86-64
# machine (dfcoa_opt/core/runtime/dispatch.py; DFCOA_SIMD_CAP=native turns it off)
_dispatch.pin()

from dfcoa_opt.core.runtime.kernel_cache import refresh as _refresh_kernel_cache  # noqa: E402

# before any kernel runs: numba's cache would keep code of edited modules a kernel imports
_spec = _util.find_spec("comparisons")
_refresh_kernel_cache([_Path(__file__).parent]
                      + ([_Path(_spec.origin).parent] if _spec and _spec.origin else []))

from dfcoa_opt.api import (  # noqa: E402 - after the kernel cache check
    Results,
    Run,
    controllers,
    load,
    register,
    report,
    run,
    run_batch,
    sweep,
)

__version__ = "0.1.0"
__all__ = ["Results", "Run", "__version__", "controllers", "load", "register", "report", "run",
           "run_batch", "sweep"]
