"""Sweep files: scenarios x variants x seeds, with parameter grids and difficulty ladders.

A sweep file (TOML)::

    name = "comparison"
    scenarios = ["../bench/*.toml"]        # files or globs, relative to this file
    controllers = ["*"]                    # ids; "*" = every registered controller
    seeds = 20                             # seeds first_seed .. first_seed + seeds - 1
    baseline = "dfcoa"                     # optional: the variant the others are compared to
    [variants.dfcoa_compensated]           # optional: named method configurations
    controller = "dfcoa"
    "controllers.dfcoa.compensate_tracking_offset" = true
    [grid]                                 # optional: Cartesian product of values
    "world.clutter.density" = [0.05, 0.1]
    [ladder]                               # optional: a difficulty ladder
    key = "world.clutter.density"
    values = [0.02, 0.04, 0.08]

Variants, grids and ladders: :mod:`dfcoa_opt.bench.sweep.variants`. Overrides are
dotted scenario keys (``a.b.c``, ``a.b[2].c`` for arrays of tables), applied to
the scenario file's contents before validation, so a controller parameter is
``controllers.<id>.<param>``, the same key a scenario file uses. A
``controllers.<id>.*`` override only reaches runs of controller ``<id>``; runs
that it does not reach are not duplicated. Each run's seed replaces the
scenario's ``seed``, so seeded parts of the scenario (random clutter, start
noise) change with it.

Every run gets a readable key ``<scenario>__<variant>[__<ladder>_<value>]__s<seed>``
that names its result files. A name longer than :data:`NAME_MAX` characters, and a
key that could exceed :data:`KEY_MAX`, is cut short and ends in ``-`` and 8 hex
digits of the SHA-256 of the whole name (:func:`shorten`), so the same name always
gives the same file name and two names give two; shorter names are kept as they are.

A sweep has at most :data:`MAX_RUNS` runs, counting every seed ``max_seeds`` may
add, and at most :data:`MAX_SEEDS` seeds per cell; a larger one is refused before
any run is built. A sweep that expands to no run at all is refused too.

The package's modules:

- :mod:`~dfcoa_opt.bench.sweep.specs`: the dataclasses, the file's keys and the naming helpers;
- :mod:`~dfcoa_opt.bench.sweep.factors`: the reading of each factor the sweep crosses
  (scenario files, grid points, seed counts);
- :mod:`~dfcoa_opt.bench.sweep.variants`: named variants, grids named by value, ladders;
- :mod:`~dfcoa_opt.bench.sweep.expand`: reading, validating and expanding a whole sweep
  (:func:`load_sweep`, :func:`sweep_from_dict`).

Every public name of them is re-exported here.
"""

from dfcoa_opt.bench.sweep.expand import check_split, expand_sweep, load_sweep, sweep_from_dict
from dfcoa_opt.bench.sweep.specs import (
    DICT_SOURCE,
    KEY_MAX,
    MAX_RUNS,
    MAX_SEEDS,
    NAME_MAX,
    RunSpec,
    Sweep,
    SweepSpec,
    canonical,
    describe_runs,
    load_run_scenario,
    safe_name,
    shorten,
)

__all__ = [
    "DICT_SOURCE",
    "KEY_MAX",
    "MAX_RUNS",
    "MAX_SEEDS",
    "NAME_MAX",
    "RunSpec",
    "Sweep",
    "SweepSpec",
    "canonical",
    "check_split",
    "describe_runs",
    "expand_sweep",
    "load_run_scenario",
    "load_sweep",
    "safe_name",
    "shorten",
    "sweep_from_dict",
]
