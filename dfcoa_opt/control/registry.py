"""Controller registry: ids -> controller classes, plus entry-point discovery.

A controller class has a ``Params`` frozen dataclass (fields made with
:func:`dfcoa_opt.params.param`) and is constructed as ``cls(params)``. Register
it with ``@register("my_id")`` in an imported module, or -- from another
package -- through the entry-point group ``dfcoa_opt.controllers``::

    [project.entry-points."dfcoa_opt.controllers"]
    my_id = "my_pkg.my_module:MyController"

Scenario files override parameters in ``[controllers.<id>]``; unknown keys are
errors with a "did you mean" hint, like everywhere else.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from importlib.metadata import entry_points
from typing import Any, TypeVar

from dfcoa_opt.errors import ScenarioError, UnknownNameError, did_you_mean
from dfcoa_opt.params import build

ENTRY_POINT_GROUP = "dfcoa_opt.controllers"
#: Modules of this distribution that register controllers when imported.
BUILTIN_MODULES = ("dfcoa_opt.control.goto_slot", "dfcoa_opt.control.dfcoa")

_REGISTRY: dict[str, type] = {}
_loaded = False
C = TypeVar("C", bound=type)


def register(controller_id: str) -> Callable[[C], C]:
    """Class decorator registering a controller under ``controller_id``."""

    def deco(cls: C) -> C:
        if controller_id in _REGISTRY and _REGISTRY[controller_id] is not cls:
            raise ValueError(f"controller id {controller_id!r} is already registered")
        if not hasattr(cls, "Params"):
            raise TypeError(f"{cls.__name__} needs a Params dataclass")
        cls.name = controller_id
        _REGISTRY[controller_id] = cls
        return cls

    return deco


def _load_all() -> None:
    global _loaded
    if _loaded:
        return
    _loaded = True
    for mod in BUILTIN_MODULES:
        importlib.import_module(mod)
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        if ep.name not in _REGISTRY:
            _REGISTRY[ep.name] = ep.load()
            _REGISTRY[ep.name].name = ep.name


def available() -> list[str]:
    """Sorted ids of all registered controllers (built-in and entry points)."""
    _load_all()
    return sorted(_REGISTRY)


def controller_class(controller_id: str) -> type:
    """The class registered under ``controller_id``.

    Raises:
        UnknownNameError: With a "did you mean" hint.
    """
    _load_all()
    try:
        return _REGISTRY[controller_id]
    except KeyError:
        raise UnknownNameError(
            f"unknown controller '{controller_id}'{did_you_mean(controller_id, _REGISTRY)}; "
            f"available: {', '.join(sorted(_REGISTRY))}") from None


def make_controller(controller_id: str, overrides: Mapping[str, Any] | None = None,
                    source: str = "<overrides>") -> Any:
    """Build a controller with its parameters validated.

    Args:
        controller_id: Registry id.
        overrides: ``[controllers.<id>]`` table of the scenario (or sweep) file.
        source: File name for error messages.

    Raises:
        UnknownNameError: Unknown id.
        ScenarioError: Bad override (names ``controllers.<id>.<key>``).
    """
    cls = controller_class(controller_id)
    params = build(cls.Params, dict(overrides or {}), source, f"controllers.{controller_id}")
    return cls(params)


def check_overrides(controllers: Mapping[str, Mapping[str, Any]], source: str) -> None:
    """Validate every ``[controllers.<id>]`` table of a file.

    Raises:
        ScenarioError: Unknown controller id or a bad key.
    """
    _load_all()
    for cid, table in controllers.items():
        if cid not in _REGISTRY:
            raise ScenarioError(source, f"controllers.{cid}", "unknown controller"
                                + did_you_mean(cid, _REGISTRY))
        build(_REGISTRY[cid].Params, dict(table), source, f"controllers.{cid}")
