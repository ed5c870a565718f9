"""One registry class for every kind of extension, and the catalogues a scenario file names.

Controllers, safety filters, pose estimators, leader planners, world families
and figure recipes are each a :class:`Registry`: ids -> objects, filled by a
decorator in the module that defines them, with a "did you mean" hint for an
unknown id. Each kind has one entry-point group, and the built-in ones are
declared in ``pyproject.toml`` through the same group a third-party package
uses, so no registry names a module::

    [project.entry-points."dfcoa_opt.controllers"]
    my_id = "my_pkg.my_module:MyController"

Loading is lazy: asking for one id imports only the module its entry point
names; listing the ids imports them all, then the plugins of ``DFCOA_PLUGINS``
(:mod:`dfcoa_opt.core.plugins`). An entry point whose module registers its
object under another id is an error (the object would be listed twice).

The catalogues of a scenario file's names live here, below the scenario layer
that checks them: :data:`CONTROLLERS`, :data:`FILTERS` (both read by
:func:`check_tables`) and :data:`ESTIMATORS`. Planners
(:mod:`dfcoa_opt.planning.registry`), world families
(:mod:`dfcoa_opt.world.generate`) and recipes (:mod:`dfcoa_opt.bench.recipes`)
keep theirs beside the code that uses them.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping
from importlib.metadata import EntryPoint, entry_points
from typing import Any, Generic, TypeVar

from dfcoa_opt.core import plugins
from dfcoa_opt.core.errors import DfcoaError, ScenarioError, UnknownNameError, did_you_mean
from dfcoa_opt.core.params import build, build_options, check_robot_indices

T = TypeVar("T")

#: Controller ids ``policy:PATH`` name a policy file (``docs/policies.md``); no table lists them.
POLICY_PREFIX = "policy:"


@functools.cache
def _installed_points(group: str) -> tuple[EntryPoint, ...]:
    """The entry points of one group, of every installed distribution (read once per process)."""
    return tuple(entry_points(group=group))


class Registry(Generic[T]):
    """One kind of extension: ids -> objects.

    Args:
        kind: What the objects are, for messages (``"controller"``).
        group: The entry-point group of the kind (``"dfcoa_opt.controllers"``).
        hint: Appended to an unknown-id message after the list of ids.
        prepare: Called as ``prepare(id, obj)`` when an object is registered: it
            checks the object (raising ``TypeError`` or ``ValueError``) and may
            complete it (a controller class gets its ``name``).
    """

    def __init__(self, kind: str, group: str, hint: str = "",
                 prepare: Callable[[str, T], None] | None = None) -> None:
        self.kind = kind
        self.group = group
        self.hint = hint
        self.prepare = prepare
        self._table: dict[str, T] = {}
        self._loaded = False

    def __repr__(self) -> str:
        return f"Registry({self.kind!r}, {self.group!r})"

    def entry_points(self) -> list[EntryPoint]:
        """The installed entry points of this kind's group."""
        return list(_installed_points(self.group))

    def register(self, name: str) -> Callable[[T], T]:
        """Decorator registering an object under ``name``; it returns the object.

        Registering an equal object again (a module imported twice) keeps the first.

        Raises:
            ValueError: ``name`` is taken by another object.
        """

        def deco(obj: T) -> T:
            if name in self._table:
                if self._table[name] != obj:
                    raise ValueError(f"{self.kind} id {name!r} is already registered")
                return obj
            if self.prepare is not None:
                self.prepare(name, obj)
            self._table[name] = obj
            return obj

        return deco

    def _load_point(self, ep: EntryPoint) -> None:
        """Import one entry point; register its object under its name if its module did not.

        Raises:
            DfcoaError: Its module registers the object under another id, or a
                module entry point registers nothing under its name.
        """
        obj = ep.load()
        if ":" not in ep.value:  # a module: its import registers
            if ep.name not in self._table:
                raise DfcoaError(f"entry point '{ep.name}' of group {self.group} imports "
                                 f"{ep.value}, which registers no {self.kind} '{ep.name}'")
            return
        ids = [key for key, value in self._table.items() if value is obj]
        if ids and ep.name not in ids:
            raise DfcoaError(f"entry point '{ep.name}' of group {self.group} loads "
                             f"{getattr(obj, '__name__', obj)}, which @register names "
                             f"'{ids[0]}': name the entry point '{ids[0]}'")
        if ep.name not in self._table:
            self.register(ep.name)(obj)

    def load(self) -> None:
        """Import every entry point of the group, then the plugins of ``DFCOA_PLUGINS`` (once)."""
        if self._loaded:
            return
        self._loaded = True
        for ep in self.entry_points():
            self._load_point(ep)
        plugins.load_plugins(plugins.from_env(), plugins.ENV_VAR)

    def find(self, name: str) -> T | None:
        """The object registered as ``name``, importing only its entry point if it has one."""
        if name not in self._table:
            point = next((ep for ep in self.entry_points() if ep.name == name), None)
            if point is not None:
                self._load_point(point)
            else:
                self.load()
        return self._table.get(name)

    def get(self, name: str) -> T:
        """The object registered as ``name``.

        Raises:
            UnknownNameError: An unknown id, with a "did you mean" hint and the ids.
        """
        obj = self.find(name)
        if obj is None:
            self.load()
            if not self._table:
                raise UnknownNameError(
                    f"unknown {self.kind} '{name}': no {self.kind} is registered, since no "
                    f"package declares the entry-point group {self.group}; install dfcoa-opt "
                    "(pip install -e . in the checkout) rather than running it from its folder")
            raise UnknownNameError(f"unknown {self.kind} '{name}'"
                                   f"{did_you_mean(name, self._table)}; available: "
                                   f"{', '.join(sorted(self._table))}{self.hint}")
        return obj

    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and self.find(name) is not None

    def names(self) -> list[str]:
        """Every registered id, sorted (imports every entry point)."""
        self.load()
        return sorted(self._table)

    def items(self) -> dict[str, T]:
        """Every id -> its object, in registration order (imports every entry point)."""
        self.load()
        return dict(self._table)

    def options(self, name: str, table: Mapping[str, Any], source: str, key: str) -> Any:
        """A scenario's options table for ``name``, built against its ``Params`` dataclass.

        Args:
            name: The registered id.
            table: The options (``[leader.planner_options]``, ...).
            source: File name for messages.
            key: Dotted key of the table in the file.

        Returns:
            An instance of the object's ``Params`` (None when it has none and the
            table is empty).

        Raises:
            UnknownNameError: An unknown id.
            ScenarioError: Unknown or bad key (names ``<key>.<field>``).
        """
        return build_options(getattr(self.get(name), "Params", None), table, source, key,
                             f"{self.kind} '{name}'")

    def check_name(self, name: str, source: str, key: str) -> None:
        """A scenario's id of this kind, checked.

        Raises:
            ScenarioError: An unknown id (names ``key``), with a "did you mean" hint.
        """
        if name not in self:
            names = self.names()
            raise ScenarioError(source, key, f"unknown {self.kind} '{name}'"
                                f"{did_you_mean(name, names)}; available: {', '.join(names)}")

    def known_to_workers(self, name: str) -> bool:
        """Whether a fresh process finds ``name``: an entry point or a plugin's registers it.

        An object registered in a notebook or a script is known only to the
        process that ran it, so a sweep's worker processes cannot build it.
        """
        points = self.entry_points()
        if any(ep.name == name for ep in points):
            return True
        module = getattr(self.find(name), "__module__", "")
        return (any(module == ep.module for ep in points if ":" in ep.value)
                or plugins.is_plugin_module(module))

    def modules(self) -> list[str]:
        """The modules the group's entry points name (what a worker imports to know them)."""
        return list(dict.fromkeys(ep.module for ep in self.entry_points()))


def _controller(name: str, cls: Any) -> None:
    """A controller or filter class: ``Params`` required; its ``name`` set to its id."""
    if not hasattr(cls, "Params"):
        raise TypeError(f"{getattr(cls, '__name__', cls)} needs a Params dataclass")
    cls.name = name


def _controller_id(name: str, cls: Any) -> None:
    if name.startswith(POLICY_PREFIX) or "+" in name:
        raise ValueError(f"controller id {name!r}: '+' and the prefix {POLICY_PREFIX!r} "
                         "are reserved (filters, policy files)")
    _controller(name, cls)


#: Controller classes (:mod:`dfcoa_opt.control.registry` builds them).
CONTROLLERS: Registry[type] = Registry(
    "controller", "dfcoa_opt.controllers",
    " (dfcoa list controllers; a controller in a file: --plugin FILE.py)", _controller_id)
#: Safety-filter classes (``"<controller>+<filter>"``).
FILTERS: Registry[type] = Registry("safety filter", "dfcoa_opt.filters", prepare=_controller)
#: Pose estimators (``[localization] mode``; :mod:`dfcoa_opt.sim.localization`).
ESTIMATORS: Registry[type] = Registry("estimator", "dfcoa_opt.estimators")


def check_tables(controllers: Mapping[str, Mapping[str, Any]], source: str,
                 team_size: int | None = None) -> None:
    """Validate every ``[controllers.<id>]`` table of a file against its class's ``Params``.

    Args:
        controllers: The tables, by controller or filter id.
        source: File name for messages.
        team_size: The scenario's ``team.n``: every ``param(robot_index=True)`` field
            must name one of its robots. None skips that check.

    Raises:
        ScenarioError: Unknown controller id or a bad key; a table of a policy
            file (its parameters are in its spec).
    """
    for cid, table in controllers.items():
        if cid.startswith(POLICY_PREFIX):
            raise ScenarioError(source, f"controllers.{cid}", "a policy file takes no "
                                "parameters here: they are in its JSON spec")
        cls = CONTROLLERS.find(cid) or FILTERS.find(cid)
        if cls is None:
            raise ScenarioError(source, f"controllers.{cid}", "unknown controller or filter"
                                + did_you_mean(cid, [*CONTROLLERS.names(), *FILTERS.names()]))
        params = build(cls.Params, dict(table), source, f"controllers.{cid}")
        if team_size is not None:
            check_robot_indices(params, team_size, source, f"controllers.{cid}")
