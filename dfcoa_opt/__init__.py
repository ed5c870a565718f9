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

from dfcoa_opt.core.moved import keep_old_paths as _keep_old_paths  # noqa: E402
from dfcoa_opt.core.runtime.kernel_cache import refresh as _refresh_kernel_cache  # noqa: E402

#: Module paths of release 0.1 -> their rooms since 0.2 (docs/architecture.md); the old
#: paths import, with a DeprecationWarning naming the new one, until 0.3.
MOVED = {
    "dfcoa_opt.animation": "dfcoa_opt.viz.animation",
    "dfcoa_opt.atomic": "dfcoa_opt.core.atomic",
    "dfcoa_opt.bench.factors": "dfcoa_opt.bench.sweep.factors",
    "dfcoa_opt.bench.failures": "dfcoa_opt.bench.report.failures",
    "dfcoa_opt.bench.heldout": "dfcoa_opt.bench.report.heldout",
    "dfcoa_opt.bench.ladders": "dfcoa_opt.bench.report.ladders",
    "dfcoa_opt.bench.logs": "dfcoa_opt.bench.results.logs",
    **{f"dfcoa_opt.bench.recipes_{m}": f"dfcoa_opt.bench.recipes.{m}"
       for m in ("astar", "beyond", "dfcoa", "paper001", "paper002", "paper004")},
    "dfcoa_opt.bench.mcap_runs": "dfcoa_opt.bench.report.mcap_runs",
    "dfcoa_opt.bench.paired": "dfcoa_opt.bench.report.paired",
    "dfcoa_opt.bench.plots": "dfcoa_opt.bench.report.plots",
    "dfcoa_opt.bench.shared_open": "dfcoa_opt.bench.report.shared_open",
    "dfcoa_opt.bench.specs": "dfcoa_opt.bench.sweep.specs",
    "dfcoa_opt.bench.stats": "dfcoa_opt.bench.report.stats",
    "dfcoa_opt.bench.store": "dfcoa_opt.bench.results.store",
    "dfcoa_opt.bench.tables": "dfcoa_opt.bench.report.tables",
    "dfcoa_opt.bench.trajectories": "dfcoa_opt.bench.report.trajectories",
    "dfcoa_opt.bench.variants": "dfcoa_opt.bench.sweep.variants",
    "dfcoa_opt.cli_text": "dfcoa_opt.cli.text",
    "dfcoa_opt.contacts": "dfcoa_opt.metrics.contacts",
    "dfcoa_opt.control.formation_law": "dfcoa_opt.control.dfcoa.formation_law",
    "dfcoa_opt.control.plugins": "dfcoa_opt.core.plugins",
    "dfcoa_opt.control.policy_file": "dfcoa_opt.control.policy.file",
    "dfcoa_opt.control.vfh": "dfcoa_opt.control.dfcoa.histogram",
    "dfcoa_opt.control.vfh_star": "dfcoa_opt.control.dfcoa.vfh_star",
    "dfcoa_opt.dispatch": "dfcoa_opt.core.runtime.dispatch",
    "dfcoa_opt.environment": "dfcoa_opt.core.runtime.provenance",
    "dfcoa_opt.envs.observation": "dfcoa_opt.control.features",
    "dfcoa_opt.errors": "dfcoa_opt.core.errors",
    "dfcoa_opt.figure_layout": "dfcoa_opt.viz.layout",
    "dfcoa_opt.figures": "dfcoa_opt.bench.figures",
    "dfcoa_opt.formation": "dfcoa_opt.scenario.formation",
    "dfcoa_opt.geometry": "dfcoa_opt.core.geometry",
    "dfcoa_opt.kernel_cache": "dfcoa_opt.core.runtime.kernel_cache",
    "dfcoa_opt.localization": "dfcoa_opt.sim.localization",
    "dfcoa_opt.localization.mcl": "dfcoa_opt.sim.localization.mcl",
    "dfcoa_opt.localization.mcl_models": "dfcoa_opt.sim.localization.mcl",
    "dfcoa_opt.localization.mcl_setup": "dfcoa_opt.sim.localization.mcl",
    "dfcoa_opt.metrics_deploy": "dfcoa_opt.metrics.deploy",
    "dfcoa_opt.metrics_risk": "dfcoa_opt.metrics.risk",
    "dfcoa_opt.metrics_robots": "dfcoa_opt.metrics.robots",
    "dfcoa_opt.metrics_units": "dfcoa_opt.metrics.units",
    "dfcoa_opt.metrics_world": "dfcoa_opt.metrics.world",
    "dfcoa_opt.moved": "dfcoa_opt.core.moved",
    "dfcoa_opt.outcome": "dfcoa_opt.metrics.outcome",
    "dfcoa_opt.params": "dfcoa_opt.core.params",
    "dfcoa_opt.planning.astar_improved": "dfcoa_opt.planning.improved_astar",
    "dfcoa_opt.plotting": "dfcoa_opt.viz.plotting",
    "dfcoa_opt.robots": "dfcoa_opt.world.robots",
    "dfcoa_opt.robots.actuated": "dfcoa_opt.world.robots.actuated",
    "dfcoa_opt.robots.models": "dfcoa_opt.world.robots.models",
    "dfcoa_opt.robots.profiles": "dfcoa_opt.world.robots.profiles",
    "dfcoa_opt.robots.unicycle_kernel": "dfcoa_opt.world.robots.unicycle_kernel",
    "dfcoa_opt.scalar_kernels": "dfcoa_opt.core.scalar_kernels",
    "dfcoa_opt.sim.budget": "dfcoa_opt.scenario.budget",
    "dfcoa_opt.sim.checks": "dfcoa_opt.scenario.placement",
    "dfcoa_opt.sim.checks_start": "dfcoa_opt.scenario.placement",
    "dfcoa_opt.sim.docs": "dfcoa_opt.scenario.reference",
    "dfcoa_opt.sim.loader": "dfcoa_opt.scenario.loader",
    "dfcoa_opt.sim.map_files": "dfcoa_opt.scenario.map_files",
    "dfcoa_opt.sim.mcap": "dfcoa_opt.viz.mcap",
    "dfcoa_opt.sim.observe": "dfcoa_opt.sim.stepper",
    "dfcoa_opt.sim.scenario": "dfcoa_opt.scenario.scenario",
    "dfcoa_opt.sim.schema": "dfcoa_opt.scenario.schema",
    "dfcoa_opt.sim.schema_robots": "dfcoa_opt.world.robots.spec",
    "dfcoa_opt.sim.schema_world": "dfcoa_opt.world.spec",
    "dfcoa_opt.simple_polygons": "dfcoa_opt.core.polygons",
    "dfcoa_opt.threads": "dfcoa_opt.core.runtime.threads",
}
_keep_old_paths(MOVED, removal="0.3")

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
from dfcoa_opt.core.runtime.version import __version__  # noqa: E402

__all__ = ["Results", "Run", "RunLog", "__version__", "controllers", "load", "register", "report",
           "run", "run_batch", "sweep"]


def __getattr__(name: str) -> object:
    """``RunLog`` (a run's log: ``RunLog.load(path)``), imported on first use."""
    if name == "RunLog":
        from dfcoa_opt.sim.log import RunLog

        return RunLog
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
