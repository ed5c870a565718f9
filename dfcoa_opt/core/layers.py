"""The layer contract: which rooms of the code may import which.

Layers, bottom up (:data:`LAYERS`); a module may import only modules of its
own room or of a lower layer, counting every ``import`` statement: at the top
of a module, inside a function and under ``TYPE_CHECKING``. Rooms that share a
layer are independent: neither imports the other. No two modules import each
other, directly or through others (no cycle).

``tests/test_layers.py`` checks the contract over every module of
``dfcoa_opt``, ``comparisons`` and ``benchmarks``, and ``docs/architecture.md``
draws it from :func:`layers_markdown`. The results store reads it too: the
rooms of :data:`RUN_LAYERS` are the code every simulated run executes
(:mod:`dfcoa_opt.bench.results.fingerprint`).
"""

from __future__ import annotations

#: The layers, bottom up; each is a tuple of rooms (dotted module prefixes).
LAYERS: tuple[tuple[str, ...], ...] = (
    ("dfcoa_opt.core",),
    ("dfcoa_opt.world",),
    ("dfcoa_opt.planning",),
    ("dfcoa_opt.scenario",),
    ("dfcoa_opt.control",),
    ("comparisons",),
    ("dfcoa_opt.sim",),
    ("dfcoa_opt.metrics",),
    ("dfcoa_opt.envs", "dfcoa_opt.viz"),
    ("dfcoa_opt.bench",),
    ("dfcoa_opt.api",),
    ("dfcoa_opt.cli",),
    ("dfcoa_opt",),
)

#: Modules above every layer, which may import any of them: the training scripts of the
#: learned controllers (run by hand, never by a simulated run) and the benchmarks.
TOOLS: tuple[str, ...] = ("comparisons.learned.dagger", "comparisons.learned.evaluate",
                          "comparisons.learned.train", "comparisons.learned_ppo.train",
                          "benchmarks")

#: What each room holds, for the architecture page.
ROOMS: dict[str, str] = {
    "dfcoa_opt.core": "errors, typed parameters, geometry, the registry class, runtime pins",
    "dfcoa_opt.world": "maps, obstacles, generated worlds, LiDAR; robots/: models and drives",
    "dfcoa_opt.planning": "A\\* (traditional, improved, clearance), post-processing, "
                          "pure pursuit",
    "dfcoa_opt.scenario": "the scenario file: schema, loader, checks, formation slots",
    "dfcoa_opt.control": "the Controller / SafetyFilter contract, registry API, observation "
                         "vector, the DFCOA controller",
    "comparisons": "the companion papers' controllers, one package per method",
    "dfcoa_opt.sim": "stepping batches of runs: stepper, comms, leader, stall test, log; "
                     "localization/",
    "dfcoa_opt.metrics": "pure functions of a run log: paper metrics, outcome, contacts, units",
    "dfcoa_opt.envs": "PettingZoo, gymnasium, SB3 and torchrl over the batch",
    "dfcoa_opt.viz": "figures, animations and MCAP files of runs",
    "dfcoa_opt.bench": "sweeps, executors, results and fingerprint, reports, tuning, recipes",
    "dfcoa_opt.api": "the Python facade (import dfcoa_opt as d)",
    "dfcoa_opt.cli": "the dfcoa command",
    "dfcoa_opt": "the package root: pins the runtime, re-exports the facade",
}

#: The layers whose code every simulated run executes (the results store's fingerprint).
RUN_LAYERS: tuple[str, ...] = ("dfcoa_opt.core", "dfcoa_opt.world", "dfcoa_opt.planning",
                               "dfcoa_opt.scenario", "dfcoa_opt.sim", "dfcoa_opt.metrics")


def within(module: str, room: str) -> bool:
    """Whether ``module`` is ``room`` or one of its submodules."""
    return module == room or module.startswith(room + ".")


def room_of(module: str) -> str | None:
    """The room of a module: the longest prefix in :data:`LAYERS` (None: none, or a tool)."""
    if any(within(module, t) for t in TOOLS):
        return None
    rooms = [r for layer in LAYERS for r in layer if within(module, r)]
    return max(rooms, key=len) if rooms else None


def layer_of(module: str) -> int | None:
    """The index in :data:`LAYERS` of a module's layer (None for a tool or an unknown module)."""
    room = room_of(module)
    if room is None:
        return None
    return next(i for i, layer in enumerate(LAYERS) if room in layer)


def is_tool(module: str) -> bool:
    """Whether ``module`` is one of :data:`TOOLS` (above every layer)."""
    return any(within(module, t) for t in TOOLS)


def layers_markdown() -> str:
    """The contract as a Markdown table, top layer first (``docs/architecture.md``)."""
    out = ["| layer | room | holds |", "|---|---|---|"]
    out.append("| tools | " + ", ".join(f"`{t}`" for t in TOOLS) + " | may import every layer |")
    for i in range(len(LAYERS) - 1, -1, -1):
        for room in LAYERS[i]:
            out.append(f"| {i} | `{room}` | {ROOMS[room]} |")
    return "\n".join(out)
