"""Controller registry: ids -> controller classes, plus entry-point discovery.

A controller class has a ``Params`` frozen dataclass (fields made with
:func:`dfcoa_opt.core.params.param`) and is constructed as ``cls(params)``. Register
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

``"policy:PATH"`` (``+filter`` too) names a policy file, a network in a JSON
spec and an ``.npz`` (:mod:`dfcoa_opt.control.policy.controller`, ``docs/policies.md``):
any process builds it from the file, so it is not listed by :func:`available`
and takes no ``[controllers.*]`` table; a relative PATH is relative to the
working folder. :func:`data_digest` hashes its files, which the results store
adds to the run's identity.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from dataclasses import replace
from importlib.metadata import entry_points
from typing import Any, TypeVar

from dfcoa_opt.core import plugins
from dfcoa_opt.core.errors import DfcoaError, ScenarioError, UnknownNameError, did_you_mean
from dfcoa_opt.core.params import Tunable, build, check_robot_indices, tunables

ENTRY_POINT_GROUP = "dfcoa_opt.controllers"
#: Controller ids ``policy:PATH`` name a policy file; its classes come from this module.
POLICY_PREFIX, POLICY_MODULE = "policy:", "dfcoa_opt.control.policy.controller"
#: Modules of this distribution that register controllers when imported (or, the policy
#: module, build them from files).
BUILTIN_MODULES = ("dfcoa_opt.control.goto_slot", "dfcoa_opt.control.dfcoa.controller",
                   "comparisons.orca.filter", "comparisons.consensus", "comparisons.lf_vo",
                   "comparisons.virtual_spring", "comparisons.cbf", "comparisons.nmpc",
                   "comparisons.reshape", "comparisons.learned", "comparisons.learned_ppo",
                   POLICY_MODULE)

_REGISTRY: dict[str, type] = {}
_FILTERS: dict[str, type] = {}
_loaded = False
C = TypeVar("C", bound=type)
T = TypeVar("T")


def _registrar(table: dict[str, type], kind: str, key: str) -> Callable[[C], C]:
    """Class decorator putting a class with ``Params`` into ``table`` under ``key``."""

    def deco(cls: C) -> C:
        if table is _REGISTRY and (key.startswith(POLICY_PREFIX) or "+" in key):
            raise ValueError(f"controller id {key!r}: '+' and the prefix {POLICY_PREFIX!r} "
                             "are reserved (filters, policy files)")
        if key in table and table[key] is not cls:
            raise ValueError(f"{kind} id {key!r} is already registered")
        if not hasattr(cls, "Params"):
            raise TypeError(f"{cls.__name__} needs a Params dataclass")
        cls.name = key
        table[key] = cls
        return cls

    return deco


def register(controller_id: str, *, command: str | None = None, spec: Any = None,
             frame: str = "world", batched: bool = True) -> Callable[[T], T]:
    """Decorator registering a controller class, or a policy function, under ``controller_id``.

    A class (README, "Add your own controller") is registered as it is. A
    function is a *policy* (``docs/policies.md``): ``fn(x)`` gets ``x`` ``(R, D)``,
    one observation vector per row (:func:`dfcoa_opt.control.features.flatten`
    with ``spec``), every row of every run of a batch, and returns ``(R, 2)``
    actions of kind ``command``. The decorator returns what it was given::

        import dfcoa_opt as d

        @d.register("my_goto")
        class MyGoto:
            command = "velocity"
            ...

        @d.register("my_pol", command="velocity", spec=ObservationSpec(beams=8))
        def my_pol(x):
            return net(x)

        d.run("scenarios/example_empty.toml", "my_pol")

    Args:
        controller_id: The id (no ``+``, not ``policy:...``).
        command: A function's action kind, required for one: ``unicycle``
            (v m/s, omega rad/s), ``velocity`` (m/s) or ``acceleration`` (m/s^2).
        spec: A function's :class:`~dfcoa_opt.control.features.ObservationSpec`
            (default ``ObservationSpec()``).
        frame: A velocity or acceleration action in the ``world`` frame (as the
            learning environments apply actions) or in the robot's ``body``
            frame (x forward, y left; rotated by its heading).
        batched: False: ``fn`` gets one run's rows at a time (when its rows depend
            on how many rows it gets, so that a batch still equals single runs).

    Raises:
        TypeError: A function without ``command``, or a class with policy keywords.
        ValueError: A taken or reserved id, a bad command kind or frame.
    """

    def deco(obj: T) -> T:
        if isinstance(obj, type):
            if command is not None or spec is not None:
                raise TypeError(f"register('{controller_id}'): command and spec are for "
                                f"policy functions; {obj.__name__} is a class")
            _registrar(_REGISTRY, "controller", controller_id)(obj)
        else:
            cls = _policy().callable_policy_class(obj, command, spec, frame, batched)
            _registrar(_REGISTRY, "controller", controller_id)(cls)
        return obj

    return deco


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


def _policy() -> Any:
    """The policy module (:mod:`dfcoa_opt.control.policy.controller`), imported by name like the built-ins.

    Named, not imported by an ``import`` statement, so that the registry (which
    every run executes) does not make it part of every run's code fingerprint.
    """
    return importlib.import_module(POLICY_MODULE)


def is_policy(controller_id: str) -> bool:
    """Whether ``controller_id`` (``+filter`` too) names a policy file (``policy:PATH``)."""
    return _parts(controller_id)[0].startswith(POLICY_PREFIX)


def data_digest(controller_id: str) -> str:
    """SHA-256 of the data a run of ``controller_id`` reads: a policy's spec and weights.

    For a controller or filter from a plugin file, that file's bytes
    (:func:`dfcoa_opt.core.plugins.plugin_digest`); empty for every other id.
    The results store adds it to the run's identity, so a changed policy or
    plugin file re-simulates its runs
    (:func:`dfcoa_opt.control.policy.controller.policy_digest`).
    """
    if not is_policy(controller_id):
        _load_all()
        digests = [plugins.plugin_digest(getattr(table.get(part), "__module__", ""))
                   for part, table in zip(_parts(controller_id), (_REGISTRY, _FILTERS),
                                          strict=True) if part is not None]
        return " ".join(d for d in digests if d)
    return str(_policy().policy_digest(_parts(controller_id)[0][len(POLICY_PREFIX):]))


def _load_all() -> None:
    """Import the built-in controllers, the entry points and ``DFCOA_PLUGINS`` (once).

    Raises:
        DfcoaError: An entry point whose class is registered under another id
            (``@register("a")`` with the entry point named ``b`` would list it
            twice), or a plugin of ``DFCOA_PLUGINS`` that cannot be imported.
    """
    global _loaded
    if _loaded:
        return
    _loaded = True
    for mod in BUILTIN_MODULES:
        importlib.import_module(mod)
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        cls = ep.load()
        ids = [key for key, c in _REGISTRY.items() if c is cls]
        if ids and ep.name not in ids:
            raise DfcoaError(f"entry point '{ep.name}' of group {ENTRY_POINT_GROUP} loads "
                             f"{getattr(cls, '__name__', cls)}, which @register names "
                             f"'{ids[0]}': name the entry point '{ids[0]}'")
        if ep.name not in _REGISTRY:
            _REGISTRY[ep.name] = cls
            cls.name = ep.name
    plugins.load_plugins(plugins.from_env(), plugins.ENV_VAR)


def known_to_workers(controller_id: str) -> bool:
    """Whether a fresh process finds ``controller_id`` (and its filter) in the registry.

    True for classes of :data:`BUILTIN_MODULES`, of the entry-point group and
    of plugins (:mod:`dfcoa_opt.core.plugins`, which workers load too), and
    for policy files (``policy:PATH``; workers share the working folder); a
    class registered with :func:`register` in a notebook or a script (a
    callable policy too) is known only to the process that ran it, so a sweep's
    worker processes cannot build it.
    """
    _load_all()
    points = {ep.name for ep in entry_points(group=ENTRY_POINT_GROUP)}
    for part, table in zip(_parts(controller_id), (_REGISTRY, _FILTERS), strict=True):
        if part is None or part in points or (table is _REGISTRY
                                              and part.startswith(POLICY_PREFIX)):
            continue
        module = getattr(table.get(part), "__module__", "")
        if not (any(module == m or module.startswith(m + ".") for m in BUILTIN_MODULES)
                or plugins.is_plugin_module(module)):
            return False
    return True


def available() -> list[str]:
    """Sorted ids of all registered controllers (built-in and entry points).

    Policy files (``policy:PATH``) are not listed: any path names one.
    """
    _load_all()
    return sorted(_REGISTRY)


def controller_class(controller_id: str) -> type:
    """The class registered under ``controller_id`` (the controller part of ``a+filter``).

    For ``policy:PATH``, a class made for that file, which is read and checked
    (:func:`dfcoa_opt.control.policy.controller.file_policy_class`).

    Raises:
        UnknownNameError: Unknown controller or filter, with a "did you mean" hint.
        ScenarioError: A policy file that does not fit, naming the file.
    """
    _load_all()
    base, filt = _parts(controller_id)
    if filt is not None and filt not in _FILTERS:
        raise UnknownNameError(
            f"unknown safety filter '{filt}' in '{controller_id}'{did_you_mean(filt, _FILTERS)}; "
            f"available filters: {', '.join(sorted(_FILTERS))}")
    if base.startswith(POLICY_PREFIX):
        return _policy().file_policy_class(base)
    try:
        return _REGISTRY[base]
    except KeyError:
        raise UnknownNameError(
            f"unknown controller '{base}'{did_you_mean(base, _REGISTRY)}; "
            f"available: {', '.join(sorted(_REGISTRY))} (dfcoa list controllers; a "
            f"controller in a file: --plugin FILE.py)") from None


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


def controller_tunables(controller_id: str) -> list[Tunable]:
    """What ``dfcoa tune`` searches for an id: its parts' ``param(tune=...)`` fields.

    Each key is the dotted override of a scenario or sweep file,
    ``controllers.<part>.<field>`` (``controllers.dfcoa.vfh.target_weight``);
    ``"a+filter"`` has the controller's and then the filter's. A policy file has
    none (its parameters are in its spec).

    Raises:
        UnknownNameError: Unknown controller or filter (:func:`controller_class`).
    """
    base, filt = _parts(controller_id)
    parts = [p for p in (base, filt) if p is not None and not p.startswith(POLICY_PREFIX)]
    out = []
    for part, cls in zip(parts, component_classes(controller_id), strict=False):
        out += [replace(t, key=f"controllers.{part}.{t.key}") for t in tunables(cls.Params)]
    return out


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


def check_overrides(controllers: Mapping[str, Mapping[str, Any]], source: str,
                    team_size: int | None = None) -> None:
    """Validate every ``[controllers.<id>]`` table of a file.

    Args:
        controllers: The tables, by controller or filter id.
        source: File name for messages.
        team_size: The scenario's ``team.n``: every ``param(robot_index=True)`` field
            must name one of its robots. None skips that check.

    Raises:
        ScenarioError: Unknown controller id or a bad key; a table of a policy
            file (its parameters are in its spec).
    """
    _load_all()
    for cid, table in controllers.items():
        if cid.startswith(POLICY_PREFIX):
            raise ScenarioError(source, f"controllers.{cid}", "a policy file takes no "
                                "parameters here: they are in its JSON spec")
        cls = _REGISTRY.get(cid, _FILTERS.get(cid))
        if cls is None:
            raise ScenarioError(source, f"controllers.{cid}", "unknown controller or filter"
                                + did_you_mean(cid, [*_REGISTRY, *_FILTERS]))
        params = build(cls.Params, dict(table), source, f"controllers.{cid}")
        if team_size is not None:
            check_robot_indices(params, team_size, source, f"controllers.{cid}")
