from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from dfcoa_opt.control import registry
from dfcoa_opt.core.errors import ScenarioError, UnknownNameError, did_you_mean
from dfcoa_opt.core.params import param
from dfcoa_opt.core.registry import CONTROLLERS
from dfcoa_opt.scenario.loader import load_scenario


def test_builtin_listed_and_unknown_id_has_hint():
    assert "goto_slot" in registry.available()
    with pytest.raises(UnknownNameError, match="did you mean 'goto_slot'"):
        registry.controller_class("goto_slat")


def test_did_you_mean_ignores_case():
    assert did_you_mean("kP", ["kp", "ki"]) == " (did you mean 'kp'?)"
    assert did_you_mean("KPP", ["kp", "ki"]) == " (did you mean 'kp'?)"
    assert did_you_mean("Goto_Slat", ["goto_slot", "dfcoa"]) == " (did you mean 'goto_slot'?)"
    assert did_you_mean("zzz", ["kp"]) == ""


@pytest.mark.parametrize("key", ["kP", "kpp", "KP"])
def test_a_controller_key_in_the_wrong_case_gets_a_hint(tmp_path, key):
    text = (Path(__file__).resolve().parents[1] / "scenarios" / "example_empty.toml").read_text()
    path = tmp_path / "s.toml"
    path.write_text(f"{text}\n[controllers.goto_slot]\n{key} = 1.0\n")
    with pytest.raises(ScenarioError) as err:
        load_scenario(path)
    assert str(err.value) == (f"{path}: controllers.goto_slot.{key}: unknown key "
                              "(did you mean 'kp'?)")


def test_overrides_are_validated_with_key_path():
    c = registry.make_controller("goto_slot", {"kp": 2.5}, "f.toml")
    assert c.p.kp == 2.5
    with pytest.raises(ScenarioError, match=r"f.toml: controllers.goto_slot.kp: must be > 0.0"):
        registry.make_controller("goto_slot", {"kp": -1.0}, "f.toml")


class ThirdParty:
    """A controller shipped by another package."""

    command = "velocity"

    @dataclass(frozen=True)
    class Params:
        gain: float = param(1.0, doc="Gain.")

    def __init__(self, params):
        self.params = params

    def reset(self, scenario, rng):
        pass

    def act(self, obs):
        return np.zeros((obs.n, 2))


class FakeEntryPoint:
    name = "third_party"
    value = "third_party_pkg.controllers:ThirdParty"
    module = "third_party_pkg.controllers"

    def load(self):
        return ThirdParty


def test_entry_point_group_is_discovered(monkeypatch):
    monkeypatch.setattr(CONTROLLERS, "_loaded", False)
    monkeypatch.setattr(CONTROLLERS, "_table", dict(CONTROLLERS._table))
    monkeypatch.setattr(CONTROLLERS, "entry_points", lambda: [FakeEntryPoint()])
    assert "third_party" in registry.available()
    c = registry.make_controller("third_party", {"gain": 3.0})
    assert isinstance(c, ThirdParty) and c.params.gain == 3.0 and c.name == "third_party"


def test_register_requires_params_and_unique_ids():
    with pytest.raises(TypeError):
        registry.register("nope")(type("NoParams", (), {}))
    with pytest.raises(ValueError):
        registry.register("goto_slot")(ThirdParty)


# -- the built-ins are declared through the entry-point groups --------------------------------

_DECORATORS = {"register": "dfcoa_opt.controllers", "register_filter": "dfcoa_opt.filters",
               "register_estimator": "dfcoa_opt.estimators",
               "register_planner": "dfcoa_opt.planners",
               "register_family": "dfcoa_opt.world_families", "recipe": "dfcoa_opt.recipes"}


def _decorated_ids() -> dict[str, set[str]]:
    """Every id a module of the distribution registers by decorator, by entry-point group."""
    import ast
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    found: dict[str, set[str]] = {g: set() for g in _DECORATORS.values()}
    for path in [*(root / "dfcoa_opt").rglob("*.py"), *(root / "comparisons").rglob("*.py")]:
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            for deco in getattr(node, "decorator_list", []):
                if not isinstance(deco, ast.Call) or not deco.args:
                    continue
                name = getattr(deco.func, "id", None) or getattr(deco.func, "attr", None)
                arg = deco.args[0]
                if name in _DECORATORS and isinstance(arg, ast.Constant):
                    found[_DECORATORS[name]].add(arg.value)
    return found


def test_every_built_in_is_declared_in_its_entry_point_group():
    """A new controller, filter, planner, estimator, family or recipe is named in pyproject.toml.

    Else no process would import its module, and it would be unknown.
    """
    from pathlib import Path

    from dfcoa_opt.scenario.overrides import read_toml

    declared = read_toml(Path(__file__).resolve().parents[1] / "pyproject.toml")[
        "project"]["entry-points"]
    for group, ids in _decorated_ids().items():
        assert ids == set(declared.get(group, {})), group


def test_an_uninstalled_checkout_says_how_to_install(monkeypatch):
    """Without the distribution's metadata no entry point exists: the error says so."""
    from dfcoa_opt.core.errors import UnknownNameError
    from dfcoa_opt.core.registry import Registry

    empty = Registry("planner", "dfcoa_opt.no_such_group")
    with pytest.raises(UnknownNameError, match=r"no planner is registered.*pip install -e \."):
        empty.get("astar")
