"""Controller registry: ids -> controller classes, plus entry-point discovery.

A controller class has a ``Params`` frozen dataclass (fields made with
:func:`dfcoa_opt.params.param`) and is constructed as ``cls(params)``. Register
it with ``@register("my_id")`` in an imported module, or -- from another
package -- through the entry-point group ``dfcoa_opt.controllers``::

    [project.entry-points."dfcoa_opt.controllers"]
    my_id = "my_pkg.my_module:MyController"

Scenario files override parameters in ``[controllers.<id>]``; unknown keys are
errors with a "did you mean" hint, like everywhere else.

Safety filters register the same way with ``@register_filter("my_filter")``
(a class with ``Params``, built as ``cls(params)``, implementing
:class:`~dfcoa_opt.control.base.SafetyFilter`). The id ``"<controller>+<filter>"``
names a controller whose output passes through the filter
(:class:`~dfcoa_opt.control.base.Filtered`); each part takes its parameters
from its own ``[controllers.<id>]`` table.
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
BUILTIN_MODULES = ("dfcoa_opt.control.goto_slot", "dfcoa_opt.control.dfcoa",
                   "comparisons.orca.filter", "comparisons.consensus", "comparisons.lf_vo",
                   "comparisons.virtual_spring", "comparisons.cbf", "comparisons.nmpc",
                   "comparisons.reshape")

_REGISTRY: dict[str, type] = {}
_FILTERS: dict[str, type] = {}
_loaded = False
C = TypeVar("C", bound=type)


def _registrar(table: dict[str, type], kind: str, key: str) -> Callable[[C], C]:
    """Class decorator putting a class with ``Params`` into ``table`` under ``key``."""

    def deco(cls: C) -> C:
        if key in table and table[key] is not cls:
            raise ValueError(f"{kind} id {key!r} is already registered")
        if not hasattr(cls, "Params"):
            raise TypeError(f"{cls.__name__} needs a Params dataclass")
        cls.name = key
        table[key] = cls
        return cls

    return deco


def register(controller_id: str) -> Callable[[C], C]:
    """Class decorator registering a controller under ``controller_id``.

    Example (README, "Add your own controller", for the whole interface)::

        import dfcoa_opt as d

        @d.register("my_goto")
        class MyGoto:
            command = "velocity"
            ...

        d.run("scenarios/example_empty.toml", "my_goto")
    """
    return _registrar(_REGISTRY, "controller", controller_id)


def register_filter(filter_id: str) -> Callable[[C], C]:
    """Class decorator registering a safety filter under ``filter_id``."""
    return _registrar(_FILTERS, "filter", filter_id)


def available_filters() -> list[str]:
    """Sorted ids of all registered safety filters."""
    _load_all()
    return sorted(_FILTERS)


def _parts(controller_id: str) -> tuple[str, str | None]:
    """``("dfcoa", "orca")`` for ``"dfcoa+orca"``; ``(id, None)`` without a filter."""
    base, sep, filt = controller_id.partition("+")
    return base, (filt if sep else None)


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


def known_to_workers(controller_id: str) -> bool:
    """Whether a fresh process finds ``controller_id`` (and its filter) in the registry.

    True for classes of :data:`BUILTIN_MODULES` and of the entry-point group; a
    class registered with :func:`register` in a notebook or a script is known
    only to the process that ran it, so a sweep's worker processes cannot build it.
    """
    _load_all()
    points = {ep.name for ep in entry_points(group=ENTRY_POINT_GROUP)}
    for part, table in zip(_parts(controller_id), (_REGISTRY, _FILTERS), strict=True):
        if part is None or part in points:
            continue
        module = getattr(table.get(part), "__module__", "")
        if not any(module == m or module.startswith(m + ".") for m in BUILTIN_MODULES):
            return False
    return True


def available() -> list[str]:
    """Sorted ids of all registered controllers (built-in and entry points)."""
    _load_all()
    return sorted(_REGISTRY)


def controller_class(controller_id: str) -> type:
    """The class registered under ``controller_id`` (the controller part of ``a+filter``).

    Raises:
        UnknownNameError: Unknown controller or filter, with a "did you mean" hint.
    """
    _load_all()
    base, filt = _parts(controller_id)
    if filt is not None and filt not in _FILTERS:
        raise UnknownNameError(
            f"unknown safety filter '{filt}' in '{controller_id}'{did_you_mean(filt, _FILTERS)}; "
            f"available filters: {', '.join(sorted(_FILTERS))}")
    try:
        return _REGISTRY[base]
    except KeyError:
        raise UnknownNameError(
            f"unknown controller '{base}'{did_you_mean(base, _REGISTRY)}; "
            f"available: {', '.join(sorted(_REGISTRY))}") from None


def component_classes(controller_id: str) -> list[type]:
    """The classes behind an id: the controller's, and the filter's of ``"a+filter"``.

    Raises:
        UnknownNameError: Unknown controller or filter (:func:`controller_class`).
    """
    classes = [controller_class(controller_id)]
    filt = _parts(controller_id)[1]
    if filt is not None:
        classes.append(_FILTERS[filt])
    return classes


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
    base, filt = _parts(controller_id)
    if filt is not None:
        raise ValueError(f"'{controller_id}' has a filter: use build_controller")
    params = build(cls.Params, dict(overrides or {}), source, f"controllers.{base}")
    return cls(params)


def build_controller(controller_id: str, tables: Mapping[str, Mapping[str, Any]] | None = None,
                     source: str = "<overrides>") -> Any:
    """Build ``"<controller>"`` or ``"<controller>+<filter>"`` from a file's tables.

    Args:
        controller_id: Registry id, optionally ``+`` a filter id.
        tables: The file's ``[controllers.*]`` tables; each part reads its own.
        source: File name for error messages.

    Raises:
        UnknownNameError: Unknown controller or filter id.
        ScenarioError: Bad parameter (names ``controllers.<id>.<key>``).
    """
    tables = tables or {}
    base, filt = _parts(controller_id)
    controller_class(controller_id)  # validates both parts
    ctrl = make_controller(base, tables.get(base, {}), source)
    if filt is None:
        return ctrl
    from dfcoa_opt.control.base import Filtered

    fcls = _FILTERS[filt]
    return Filtered(ctrl, fcls(build(fcls.Params, dict(tables.get(filt, {})), source,
                                     f"controllers.{filt}")))


def check_overrides(controllers: Mapping[str, Mapping[str, Any]], source: str) -> None:
    """Validate every ``[controllers.<id>]`` table of a file.

    Raises:
        ScenarioError: Unknown controller id or a bad key.
    """
    _load_all()
    for cid, table in controllers.items():
        cls = _REGISTRY.get(cid, _FILTERS.get(cid))
        if cls is None:
            raise ScenarioError(source, f"controllers.{cid}", "unknown controller or filter"
                                + did_you_mean(cid, [*_REGISTRY, *_FILTERS]))
        build(cls.Params, dict(table), source, f"controllers.{cid}")
