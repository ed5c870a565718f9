"""Policies as controllers: a network in a data file (``policy:PATH``), or a Python callable.

A policy maps each robot's observation vector (:func:`dfcoa_opt.control.features.flatten`,
what learning environments build) to one action row. A *policy file* is a JSON spec
naming an ``.npz`` of weights, data and never code (:mod:`dfcoa_opt.control.policy.file`
reads and checks it). A *callable* ``fn(x (R, D)) -> (R, 2)`` is registered with
``dfcoa_opt.register("my_pol", command=...)`` (:func:`callable_policy_class`). Both are
batched: one call per step for every row of every run; the network's kernel sums in a
fixed order per row, so a batch is its runs alone, bit for bit. ``docs/policies.md``.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.control.base import BatchedController, Observation
from dfcoa_opt.control.features import ObservationSpec, flatten
from dfcoa_opt.control.policy.file import (
    PREFIX,
    Frame,
    LoadedPolicy,
    load_policy,
)
from dfcoa_opt.core.errors import ControllerError, UnknownNameError
from dfcoa_opt.core.geometry import rotate
from dfcoa_opt.world.robots.models import CommandKind

__all__ = ["FilePolicy", "PolicyController", "callable_policy_class", "file_policy_class"]

FloatArray = NDArray[np.float64]


class PolicyController(BatchedController):
    """Base of the policy controllers: the observation vectors in, commands out.

    Attributes:
        command: Kind of the action rows.
        frame: ``body``: a velocity or acceleration row is in the robot's frame
            (x forward, y left) and is rotated by its heading; ``world``: as is.
        spec: The observation vector.
        uses_scan: Whether the vector holds LiDAR beams.
    """

    command: CommandKind = "velocity"
    frame: Frame = "world"
    spec: ObservationSpec = ObservationSpec()
    uses_scan = True

    @dataclass(frozen=True)
    class Params:
        """No parameters: a policy's are in its file (or its function)."""

    def __init__(self, params: Any = None) -> None:
        self.p = params if params is not None else self.Params()

    def forward(self, x: FloatArray) -> Any:
        """Actions ``(R, 2)`` (command units, :attr:`frame`) for inputs ``(R, D)``."""
        raise NotImplementedError

    def act(self, obs: Observation) -> FloatArray:
        """Row i from robot i's observation vector only."""
        y = np.asarray(self.forward(flatten(obs, self.spec)), dtype=float)
        if y.shape != (obs.n, 2):
            raise ControllerError(f"policy '{getattr(self, 'name', type(self).__name__)}' "
                                  f"returned shape {y.shape} for {obs.n} rows, expected "
                                  f"({obs.n}, 2)")
        if self.command == "unicycle" or self.frame == "world":
            return y
        return rotate(y, obs.pose[:, 2])


class FilePolicy(PolicyController):
    """A policy file's network (one subclass per file: :func:`file_policy_class`)."""

    policy: LoadedPolicy

    def forward(self, x: FloatArray) -> FloatArray:
        """The network of the file (:meth:`LoadedPolicy.forward`)."""
        return self.policy.forward(x)


_CLASSES: dict[tuple[str, str], tuple[list[tuple[int, ...]], type[FilePolicy]]] = {}


def _stamps(files: tuple[Path, ...]) -> list[tuple[int, ...]]:
    """Modification time (ns), size (bytes) and inode of each file: what marks a change."""
    return [(st.st_mtime_ns, st.st_size, st.st_ino) for st in (f.stat() for f in files)]


def file_policy_class(controller_id: str) -> type[FilePolicy]:
    """The controller class of ``policy:PATH``, its file loaded and checked.

    A relative PATH is relative to the working folder. The class is kept while
    both files keep their size and modification time; a changed file is read again.

    Raises:
        UnknownNameError: No PATH.
        ScenarioError: A file that does not fit (:func:`load_policy`).
    """
    path = controller_id[len(PREFIX):]
    if not path:
        raise UnknownNameError(f"controller id '{controller_id}' names no policy file; "
                               "use policy:PATH (a JSON spec)")
    key = (controller_id, os.path.abspath(path))
    hit = _CLASSES.get(key)
    try:
        if hit is not None and _stamps(hit[1].policy.files) == hit[0]:
            return hit[1]
    except OSError:
        pass
    loaded = load_policy(path)
    cls = type("FilePolicy", (FilePolicy,), {
        "__module__": __name__, "__doc__": f"Policy file {path}.", "name": controller_id,
        "policy": loaded, "command": loaded.spec.command,
        "frame": loaded.spec.frame or "body",
        "spec": loaded.spec.observation, "uses_scan": loaded.spec.observation.beams > 0})
    _CLASSES[key] = (_stamps(loaded.files), cls)
    return cls


def callable_policy_class(fn: Callable[[FloatArray], Any], command: CommandKind | None,
                          spec: ObservationSpec | None = None, frame: Frame = "world",
                          batched: bool = True) -> type[PolicyController]:
    """A controller class calling ``fn`` (what ``dfcoa_opt.register(id, command=...)`` makes).

    Args:
        fn: ``fn(x)``: ``x`` ``(R, D)`` float64, one observation vector per row
            (every row of every run of a batch); returns ``(R, 2)`` actions in
            the command's units (a CPU ``torch`` tensor will do).
        command: ``unicycle``, ``velocity`` or ``acceleration``.
        spec: The observation vector (default ``ObservationSpec()``).
        frame: ``world`` (as the environments apply actions) or ``body`` (x
            forward, y left; rotated by each robot's heading).
        batched: False: one object per run, ``fn`` sees one run's rows (for an
            ``fn`` whose row results depend on how many rows it gets).

    Raises:
        TypeError: ``fn`` is not callable, no ``command``, a ``spec`` not an ObservationSpec.
        ValueError: An unknown command kind or frame.
    """
    if not callable(fn):
        raise TypeError(f"a policy must be callable, got {type(fn).__name__}")
    if command is None:
        raise TypeError("a policy function needs command='unicycle' | 'velocity' | "
                        "'acceleration'")
    spec = ObservationSpec() if spec is None else spec
    if not isinstance(spec, ObservationSpec):
        raise TypeError(f"spec must be an ObservationSpec, got {type(spec).__name__}")
    if command not in ("unicycle", "velocity", "acceleration"):
        raise ValueError(f"command must be unicycle, velocity or acceleration, got {command!r}")
    if frame not in ("body", "world"):
        raise ValueError(f"frame must be 'world' or 'body', got {frame!r}")
    return type("CallablePolicy", (PolicyController,), {
        "__module__": getattr(fn, "__module__", None) or "__main__",
        "__doc__": (getattr(fn, "__doc__", None) or f"Policy {fn!r}."),
        "forward": staticmethod(fn), "command": command, "frame": frame, "spec": spec,
        "uses_scan": spec.beams > 0, "batched": bool(batched)})
