"""The package layout: one package per method, recipes in one package, old paths for one release."""

import importlib
import re
import sys
import warnings
from pathlib import Path

import pytest

import comparisons
import dfcoa_opt
from dfcoa_opt.cli import main
from dfcoa_opt.control.registry import available, controller_class

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("folder", ["comparisons", "dfcoa_opt", "benchmarks"])
def test_no_module_has_prefixed_siblings(folder):
    """A family `x.py`, `x_core.py` is a package `x/` instead.

    The one exception is a numba twin, `x_kernel.py` beside `x.py`, tested bit for
    bit against it.
    """
    for d in [ROOT / folder, *(p for p in (ROOT / folder).rglob("*") if p.is_dir())]:
        stems = {p.stem for p in d.glob("*.py")} - {"__init__"}
        family = sorted(f"{a}.py / {b}.py" for a in stems for b in stems
                        if b.startswith(f"{a}_") and b != f"{a}_kernel")
        assert not family, f"{d.relative_to(ROOT)}: {family}"


def test_the_package_root_holds_about_a_dozen_rooms():
    entries = {p.name for p in (ROOT / "dfcoa_opt").iterdir() if p.name != "__pycache__"}
    rooms = {p for p in entries if (ROOT / "dfcoa_opt" / p).is_dir()}
    assert entries - rooms == {"__init__.py", "__main__.py", "py.typed", "api.py"}
    assert rooms == {"core", "world", "planning", "scenario", "control", "sim", "metrics",
                     "envs", "viz", "bench", "cli"}


def test_each_multi_module_method_is_a_package_named_by_its_id():
    for cid in available():
        module = controller_class(cid).__module__
        if not module.startswith("comparisons."):
            continue
        package = module.split(".")[1]
        if (ROOT / "comparisons" / f"{package}.py").is_file():
            continue  # a one-file method (consensus.py)
        assert (ROOT / "comparisons" / package / "__init__.py").is_file(), cid
        assert cid.startswith(package), (cid, module)  # virtual_spring_basic: virtual_spring/


@pytest.mark.parametrize("old,new", sorted(comparisons.MOVED.items())
                         + sorted(dfcoa_opt.MOVED.items()))
def test_old_module_paths_import_the_new_modules_with_a_warning(old, new, monkeypatch):
    monkeypatch.delitem(sys.modules, old, raising=False)
    with pytest.warns(DeprecationWarning, match=re.escape(f"{old} moved to {new}")):
        mod = importlib.import_module(old)
    assert mod is importlib.import_module(new)
    assert mod.__name__ == new and mod.__spec__.name == new  # the new module is untouched


def test_a_moved_package_gives_one_module_and_one_class_by_either_path(monkeypatch):
    """``dfcoa_opt.robots`` moved whole: its old submodule names load no second copy."""
    from dfcoa_opt.world.robots.models import Unicycle

    for old in ("dfcoa_opt.robots", "dfcoa_opt.robots.models"):
        monkeypatch.delitem(sys.modules, old, raising=False)
    with pytest.warns(DeprecationWarning, match="dfcoa_opt.robots.models moved to "
                                                "dfcoa_opt.world.robots.models"):
        from dfcoa_opt.robots.models import Unicycle as OldUnicycle
    assert OldUnicycle is Unicycle
    assert sys.modules["dfcoa_opt.robots.models"] is sys.modules["dfcoa_opt.world.robots.models"]
    copies = {id(m) for m in sys.modules.values()
              if (getattr(m, "__file__", None) or "").endswith("world/robots/models.py")}
    assert copies == {id(sys.modules["dfcoa_opt.world.robots.models"])}


def test_old_public_names_still_import_without_warnings():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        from comparisons.cbf import CbfFilter
        from comparisons.lf_vo import LeaderFollowerVO
        from comparisons.nmpc import Nmpc
        from comparisons.virtual_spring import VirtualSpring, VirtualSpringBasic
        from dfcoa_opt.bench.figures import Artefact, recipe, recipes
        from dfcoa_opt.bench.recipes import report_artefacts
    assert {c.name for c in (CbfFilter, LeaderFollowerVO, Nmpc, VirtualSpring,
                             VirtualSpringBasic)} == {"cbf", "lf_vo", "nmpc", "virtual_spring",
                                                      "virtual_spring_basic"}
    assert callable(report_artefacts) and callable(recipe)
    assert Artefact("a", "-", "b").path == "a"
    assert recipes()[0].name == "examples"
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        importlib.import_module("dfcoa_opt.bench.recipes").nothing  # noqa: B018


def test_list_recipes_prints_every_recipe_including_those_without_a_sweep(capsys):
    from dfcoa_opt.bench.recipes import registered

    assert main(["list", "recipes"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [ln.split()[0] for ln in lines] == [r.name for r in registered()]
    assert any("(no sweep)" in ln for ln in lines)  # astar_comparison used to crash the list


_PATH = re.compile(r"`((?:comparisons|dfcoa_opt|benchmarks|tests)/[\w/]+\.py)")


@pytest.mark.parametrize("doc", ["README.md", "docs/architecture.md",
                                 *sorted(p.relative_to(ROOT).as_posix()
                                         for p in (ROOT / "docs" / "methods").glob("*.md"))])
def test_docs_name_only_files_that_exist(doc):
    missing = [p for p in _PATH.findall((ROOT / doc).read_text(encoding="utf-8"))
               if not (ROOT / p).is_file()]
    assert not missing, f"{doc}: {missing}"
