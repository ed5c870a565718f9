from dataclasses import dataclass

import numpy as np
import pytest

from dfcoa_opt.control import registry
from dfcoa_opt.errors import ScenarioError, UnknownNameError
from dfcoa_opt.params import param


def test_builtin_listed_and_unknown_id_has_hint():
    assert "goto_slot" in registry.available()
    with pytest.raises(UnknownNameError, match="did you mean 'goto_slot'"):
        registry.controller_class("goto_slat")


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

    def load(self):
        return ThirdParty


def test_entry_point_group_is_discovered(monkeypatch):
    monkeypatch.setattr(registry, "_loaded", False)
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))
    def fake_entry_points(group):
        return [FakeEntryPoint()] if group == registry.ENTRY_POINT_GROUP else []

    monkeypatch.setattr(registry, "entry_points", fake_entry_points)
    assert "third_party" in registry.available()
    c = registry.make_controller("third_party", {"gain": 3.0})
    assert isinstance(c, ThirdParty) and c.params.gain == 3.0 and c.name == "third_party"


def test_register_requires_params_and_unique_ids():
    with pytest.raises(TypeError):
        registry.register("nope")(type("NoParams", (), {}))
    with pytest.raises(ValueError):
        registry.register("goto_slot")(ThirdParty)
