"""The controller registry's API: ids -> controllers, built with validated parameters.

A controller class has a ``Params`` frozen dataclass (fields made with
:func:`dfcoa_opt.core.params.param`) and is constructed as ``cls(params)``. Register
it with ``@register("my_id")`` in an imported module, and -- from a package --
name it in the entry-point group ``dfcoa_opt.controllers``, where the built-in
controllers are declared too (the tables are
:data:`dfcoa_opt.core.registry.CONTROLLERS` and :data:`~dfcoa_opt.core.registry.FILTERS`)::

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
from typing import Any, TypeVar

from dfcoa_opt.control.base import Filtered
from dfcoa_opt.core import plugins
from dfcoa_opt.core.errors import UnknownNameError, did_you_mean
from dfcoa_opt.core.params import Tunable, build, tunables
from dfcoa_opt.core.registry import CONTROLLERS, FILTERS, POLICY_PREFIX, check_tables

#: The module that makes classes of policy files and callables; imported by name, so that
#: the registry (which every run executes) does not make it part of every run's code
#: fingerprint.
POLICY_MODULE = "dfcoa_opt.control.policy"
#: The entry-point group of controllers (:data:`dfcoa_opt.core.registry.CONTROLLERS`).
ENTRY_POINT_GROUP = CONTROLLERS.group
C = TypeVar("C", bound=type)
T = TypeVar("T")

__all__ = ["CONTROLLERS", "ENTRY_POINT_GROUP", "FILTERS", "POLICY_PREFIX", "available",
           "available_filters", "build_controller", "check_tables", "component_classes",
           "controller_class", "controller_tunables", "data_digest", "is_policy",
           "known_to_workers", "make_controller", "register", "register_filter"]


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
            CONTROLLERS.register(controller_id)(obj)
        else:
            cls = _policy().callable_policy_class(obj, command, spec, frame, batched)
            CONTROLLERS.register(controller_id)(cls)
        return obj

    return deco


def register_filter(filter_id: str) -> Callable[[C], C]:
    """Class decorator registering a safety filter under ``filter_id``."""
    return FILTERS.register(filter_id)


def available_filters() -> list[str]:
    """Sorted ids of all registered safety filters."""
    return FILTERS.names()


def _parts(controller_id: str) -> tuple[str, str | None]:
    """``("dfcoa", "orca")`` for ``"dfcoa+orca"``; ``(id, None)`` without a filter."""
    base, sep, filt = controller_id.partition("+")
    return base, (filt if sep else None)


def _policy() -> Any:
    """The policy package (:mod:`dfcoa_opt.control.policy`), imported by name."""
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
    (:func:`dfcoa_opt.control.policy.file.policy_digest`).
    """
    if not is_policy(controller_id):
        digests = [plugins.plugin_digest(getattr(table.find(part), "__module__", ""))
                   for part, table in zip(_parts(controller_id), (CONTROLLERS, FILTERS),
                                          strict=True) if part is not None]
        return " ".join(d for d in digests if d)
    return str(_policy().policy_digest(_parts(controller_id)[0][len(POLICY_PREFIX):]))


def known_to_workers(controller_id: str) -> bool:
    """Whether a fresh process finds ``controller_id`` (and its filter) in the registry.

    True for the classes of the entry-point groups (the built-ins among them)
    and of plugins (:mod:`dfcoa_opt.core.plugins`, which workers load too), and
    for policy files (``policy:PATH``; workers share the working folder); a
    class registered with :func:`register` in a notebook or a script (a
    callable policy too) is known only to the process that ran it, so a sweep's
    worker processes cannot build it.
    """
    base, filt = _parts(controller_id)
    return ((base.startswith(POLICY_PREFIX) or CONTROLLERS.known_to_workers(base))
            and (filt is None or FILTERS.known_to_workers(filt)))


def available() -> list[str]:
    """Sorted ids of all registered controllers (built-in and entry points).

    Policy files (``policy:PATH``) are not listed: any path names one.
    """
    return CONTROLLERS.names()


def controller_class(controller_id: str) -> type:
    """The class registered under ``controller_id`` (the controller part of ``a+filter``).

    For ``policy:PATH``, a class made for that file, which is read and checked
    (:func:`dfcoa_opt.control.policy.controller.file_policy_class`).

    Raises:
        UnknownNameError: Unknown controller or filter, with a "did you mean" hint.
        ScenarioError: A policy file that does not fit, naming the file.
    """
    base, filt = _parts(controller_id)
    if filt is not None and FILTERS.find(filt) is None:
        raise UnknownNameError(
            f"unknown safety filter '{filt}' in '{controller_id}'"
            f"{did_you_mean(filt, FILTERS.names())}; "
            f"available filters: {', '.join(FILTERS.names())}")
    if base.startswith(POLICY_PREFIX):
        return _policy().file_policy_class(base)
    if CONTROLLERS.find(base) is None and FILTERS.find(base) is not None:
        raise UnknownNameError(
            f"unknown controller '{base}'{did_you_mean(base, CONTROLLERS.names())}: "
            f"'{base}' is a safety filter, which wraps a controller: e.g. 'goto_slot+{base}' "
            f"or 'dfcoa+{base}' (dfcoa list controllers)")
    return CONTROLLERS.get(base)


def component_classes(controller_id: str) -> list[type]:
    """The classes behind an id: the controller's, and the filter's of ``"a+filter"``.

    Raises:
        UnknownNameError: Unknown controller or filter (:func:`controller_class`).
    """
    classes = [controller_class(controller_id)]
    filt = _parts(controller_id)[1]
    if filt is not None:
        classes.append(FILTERS.get(filt))
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
    fcls = FILTERS.get(filt)
    return Filtered(ctrl, fcls(build(fcls.Params, dict(tables.get(filt, {})), source,
                                     f"controllers.{filt}")))


#: The former name of :func:`dfcoa_opt.core.registry.check_tables`.
check_overrides = check_tables
