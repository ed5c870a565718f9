"""The scenario file: schema, loader, checks and formation slots -> a frozen :class:`Scenario`.

``load_scenario(path, seed, overrides)`` (:mod:`dfcoa_opt.scenario.loader`)
reads a TOML file, applies dotted overrides, validates every key against the
schema (:mod:`~dfcoa_opt.scenario.schema`), builds the world and checks it
(:mod:`~dfcoa_opt.scenario.names`, :mod:`~dfcoa_opt.scenario.placement`,
:mod:`~dfcoa_opt.scenario.budget`).
"""
