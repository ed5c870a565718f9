"""The layer contract (dfcoa_opt.core.layers): every import runs down, and no import cycle.

Every ``import`` statement of every module of ``dfcoa_opt``, ``comparisons`` and
``benchmarks`` counts: at the top, inside functions and under ``TYPE_CHECKING``.
"""

from __future__ import annotations

import ast
import re
from collections.abc import Mapping
from pathlib import Path

import pytest

from dfcoa_opt.core import layers

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("dfcoa_opt", "comparisons", "benchmarks")


def sources(root: Path = ROOT) -> dict[str, tuple[str, bool]]:
    """Module name -> (source, is a package ``__init__``)."""
    out = {}
    for pkg in PACKAGES:
        for path in sorted((root / pkg).rglob("*.py")):
            parts = list(path.relative_to(root).with_suffix("").parts)
            init = parts[-1] == "__init__"
            out[".".join(parts[:-1] if init else parts)] = (path.read_text(encoding="utf-8"), init)
    return out


def import_edges(mods: Mapping[str, tuple[str, bool]]) -> dict[str, dict[str, int]]:
    """Module -> {imported module of ``mods``: line of the first import of it}.

    ``from a.b import c`` imports ``a.b.c`` when that is a module, else ``a.b``.
    """
    edges: dict[str, dict[str, int]] = {}
    for name, (text, init) in mods.items():
        out: dict[str, int] = {}
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    pkg = name.split(".")[: len(name.split(".")) - node.level + (1 if init else 0)]
                    base = ".".join([*pkg, base] if base else pkg)
                targets = [f"{base}.{a.name}" for a in node.names] + [base]
            else:
                continue
            for target in targets:
                parts = target.split(".")
                hit = next((".".join(parts[:i]) for i in range(len(parts), 0, -1)
                            if ".".join(parts[:i]) in mods), None)
                if hit is not None and hit != name:
                    out.setdefault(hit, node.lineno)
                    break
        edges[name] = out
    return edges


def violations(mods: Mapping[str, tuple[str, bool]]) -> list[str]:
    """Every import that breaks the contract, and every module no layer holds."""
    out = []
    for name, deps in import_edges(mods).items():
        if layers.is_tool(name):
            continue
        me = layers.layer_of(name)
        if me is None:
            out.append(f"{name}: in no layer of dfcoa_opt.core.layers")
            continue
        for dep, line in deps.items():
            them = layers.layer_of(dep)
            if them is None or them > me or (them == me and layers.room_of(dep)
                                               != layers.room_of(name)):
                out.append(f"{name}:{line} imports {dep} ({layers.room_of(name)} -> "
                           f"{layers.room_of(dep) or 'a tool'})")
    return out


def cycles(mods: Mapping[str, tuple[str, bool]]) -> list[list[str]]:
    """The import cycles: strongly connected sets of more than one module (Tarjan)."""
    graph = {m: list(d) for m, d in import_edges(mods).items()}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in graph:
        if v not in index:
            visit(v)
    return out


@pytest.fixture(scope="module")
def mods():
    return sources()


def test_every_import_runs_down_the_layers(mods):
    assert violations(mods) == []


def test_no_import_cycle(mods):
    assert cycles(mods) == []


def test_an_injected_upward_import_breaks_the_contract(mods):
    text, init = mods["dfcoa_opt.world.grid"]
    injected = {**mods, "dfcoa_opt.world.grid": (
        text + "\n\ndef _later():\n    from dfcoa_opt.bench.harness import run_sweep\n", init)}
    assert any(v.startswith("dfcoa_opt.world.grid:") and "dfcoa_opt.bench.harness" in v
               for v in violations(injected))


def test_a_type_only_import_counts(mods):
    text, init = mods["dfcoa_opt.core.geometry"]
    injected = {**mods, "dfcoa_opt.core.geometry": (
        text + "\nfrom typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
               "    from dfcoa_opt.world.grid import OccupancyGrid\n", init)}
    assert [v for v in violations(injected) if v.startswith("dfcoa_opt.core.geometry:")]


def test_sibling_rooms_of_a_layer_are_independent(mods):
    text, init = mods["dfcoa_opt.viz.plotting"]
    injected = {**mods, "dfcoa_opt.viz.plotting": (text + "\nimport dfcoa_opt.envs.spaces\n",
                                                   init)}
    assert any("dfcoa_opt.envs.spaces" in v for v in violations(injected))


def test_an_injected_cycle_is_found(mods):
    text, init = mods["dfcoa_opt.core.errors"]
    injected = {**mods, "dfcoa_opt.core.errors": (text + "\nimport dfcoa_opt.core.params\n",
                                                  init)}
    assert ["dfcoa_opt.core.errors", "dfcoa_opt.core.params"] in cycles(injected)


def test_the_architecture_page_draws_the_contract():
    text = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    block = re.search(r"<!-- layers -->\n(.*?)\n<!-- /layers -->", text, re.S)
    assert block, "docs/architecture.md: no <!-- layers --> block"
    assert block.group(1) == layers.layers_markdown(), "regenerate: layers_markdown()"
