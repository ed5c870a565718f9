"""Figure recipes: the registry that ``make figures`` runs and ``dfcoa list recipes`` reads.

A *figure recipe* is a sweep file (under ``scenarios/sweeps/``) plus a
renderer that turns the sweep's saved results into tables and figures. A
recipe without a sweep (``sweep=None``, e.g. the planner comparison, which
simulates nothing) computes its artefacts itself. One module per paper or
group registers its recipes (index order: :data:`ORDER`):

- :mod:`~dfcoa_opt.bench.recipes.examples`: every controller on the example scenarios;
- :mod:`~dfcoa_opt.bench.recipes.comparison`: the cross-method comparison;
- :mod:`~dfcoa_opt.bench.recipes.beyond`: ``nmpc`` and ``cbf`` beside the papers' methods;
- :mod:`~dfcoa_opt.bench.recipes.reshape`: the reshaping formation, with the corridor GIF;
- :mod:`~dfcoa_opt.bench.recipes.ladders`: difficulty ladders (where each method breaks);
- :mod:`~dfcoa_opt.bench.recipes.heldout`: every method, defaults and tuned, on unseen
  generated worlds;
- :mod:`~dfcoa_opt.bench.recipes.dfcoa`: paper 000 Table 5 and its figures;
- :mod:`~dfcoa_opt.bench.recipes.astar`: traditional vs improved A* (paper 000 §4.1);
- :mod:`~dfcoa_opt.bench.recipes.paper001`, :mod:`~dfcoa_opt.bench.recipes.paper002`,
  :mod:`~dfcoa_opt.bench.recipes.paper004`: the companion papers' tables.

``make figures`` runs them in this order. ``beyond`` and ``reshape`` come right
after the comparison, whose runs they reuse: their sweeps are short and their
renderings long (about 20 s each, the corridor GIF), so those renderings
overlap the ladders' sweep instead of running after the last sweep.

Adding a recipe::

    from dfcoa_opt.bench.recipes import Artefact, recipe

    @recipe("dfcoa_tables", title="Paper 000: Table 5 and Figs 15, 20",
            sweep="sweeps/dfcoa_paper.toml")
    def render(store, dest):
        ...                                    # read store.rows(), write into dest
        return [Artefact("table5.md", "paper 000 Table 5", "metrics of S1 and S2")]

A recipe's ``budget`` is what it may cost, in CPU-s on :data:`BUDGET_MACHINE`: the
simulation time of its runs (the rows' ``provenance.wall_time``, runs copied from
another recipe excluded) plus its rendering's wall time. ``make figures`` prints
each recipe's cost against it, ``make bench`` has a row per recipe, and
``docs/performance.md`` holds :func:`budget_table`. A recipe over its budget is
made cheaper, or its budget raised with the reason in ``budget_why``.

and name the recipe's module in the entry-point group ``dfcoa_opt.recipes`` of
``pyproject.toml`` (``dfcoa_tables = "my_pkg.my_recipes"``), as the built-in
ones are (:data:`RECIPES`, a :class:`~dfcoa_opt.core.registry.Registry`).
:func:`dfcoa_opt.bench.figures.make_figures` runs the sweeps and the renderers.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from dfcoa_opt.core.registry import Registry

#: The recipes ``make figures`` runs first, in this order; any other follows, in the order
#: it was registered.
ORDER = ("examples", "comparison", "beyond", "reshape", "ladders", "heldout", "dfcoa_paper",
         "astar_comparison", "paper001_ivo", "paper001_consensus", "paper002_tables",
         "paper004_tables", "paper004_baseline")


#: The machine class of the budgets: the one every budget was measured on.
BUDGET_MACHINE = "a 2-core x86-64 cloud machine (AMD EPYC), one sweep worker per core"


@dataclass(frozen=True)
class Artefact:
    """One generated file.

    Attributes:
        path: Path relative to the recipe's output folder.
        paper: Its paper counterpart ("paper 000 Table 5"), or "-" if none.
        what: One-line description.
    """

    path: str
    paper: str
    what: str


#: ``render(store, dest)`` for a recipe with a sweep; ``render(scenarios, dest)``
#: (the scenario root) for a recipe without one.
Renderer = Callable[[Any, Path], list[Artefact]]


@dataclass(frozen=True)
class Recipe:
    """A sweep and the renderer of its artefacts.

    Attributes:
        name: Recipe id, also the output sub-folder.
        sweep: Sweep file, relative to the scenario root, or None for a recipe
            that computes its artefacts without simulating.
        title: Heading in the index.
        render: ``render(store, dest) -> artefacts`` (with a sweep) or
            ``render(scenarios, dest) -> artefacts`` (without).
        budget: What the recipe may cost, CPU-s on :data:`BUDGET_MACHINE` (module
            docstring); None: no budget (a plugin's recipe that sets none).
        budget_why: Why the budget is what it is, when it was raised above what the
            recipe cost when it was set.
    """

    name: str
    sweep: str | None
    title: str
    render: Renderer
    budget: float | None = None
    budget_why: str = ""


#: The figure recipes (entry-point group ``dfcoa_opt.recipes``).
RECIPES: Registry[Recipe] = Registry("figure recipe", "dfcoa_opt.recipes")


def recipe(name: str, title: str, sweep: str | None = None, budget: float | None = None,
           budget_why: str = "") -> Callable[[Renderer], Renderer]:
    """Decorator registering a renderer as the recipe ``name`` (see :class:`Recipe`).

    Raises:
        ValueError: A budget that is not a positive number of CPU-s.
    """
    if budget is not None and not (isinstance(budget, int | float) and budget > 0):
        raise ValueError(f"recipe {name}: budget must be a positive number of CPU-s, "
                         f"got {budget!r}")

    def deco(fn: Renderer) -> Renderer:
        RECIPES.register(name)(Recipe(name, sweep, title, fn, budget, budget_why))
        return fn

    return deco


def budget_table() -> str:
    """The recipes' budgets as a markdown table (``docs/performance.md`` holds it)."""
    lines = [f"Budgets in CPU-s on {BUDGET_MACHINE}: the simulation time of a recipe's "
             "runs plus its rendering's wall time.", "",
             "| recipe | budget (CPU-s) | why |", "|---|---|---|"]
    for r in registered():
        cell = "none" if r.budget is None else f"{r.budget:g}"
        lines.append(f"| {r.name} | {cell} | {r.budget_why or '-'} |")
    return "\n".join(lines) + "\n"


def registered() -> list[Recipe]:
    """Every registered recipe, in index order (:data:`ORDER`, then registration order)."""
    rank = {name: i for i, name in enumerate(ORDER)}
    return sorted(RECIPES.items().values(), key=lambda r: rank.get(r.name, len(rank)))


#: Names of the 0.1 module ``dfcoa_opt.bench.recipes`` -> the module that holds them now.
_FORMER_NAMES = {"EXAMPLE_COLUMNS": "examples", "render_examples": "examples",
                 "render_comparison": "comparison", "report_artefacts": "comparison"}


def __getattr__(name: str) -> Any:
    """The 0.1 names of this package's former module, from their new modules (until 0.3)."""
    if name in _FORMER_NAMES:
        return getattr(importlib.import_module(f"{__name__}.{_FORMER_NAMES[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
