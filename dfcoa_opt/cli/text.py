"""What the ``dfcoa`` command prints: a run's summary and the list of controllers.

Text only: nothing here computes a metric or runs a simulation (it is left out
of the results store's code fingerprint, as the CLI is).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from typing import Any

from dfcoa_opt.metrics.outcome import outcome_text
from dfcoa_opt.metrics.units import with_unit

#: The metrics ``dfcoa run`` prints (every one is in the ``.json`` and with ``--json``).
RUN_METRICS = ("fce_rms", "time_to_goal", "min_inter_robot_distance", "min_obstacle_clearance",
               "path_length_mean", "collisions", "wheel_speed_peak", "wheel_speed_ratio",
               "wheel_accel_peak", "wheel_accel_ratio", "saturated_pct", "robotarium_ok")

_ROLE = re.compile(r":[a-z]+(?::[a-z]+)?:`(~?)([^`]+)`")  # :func:`~a.b.c`, :py:class:`X`
_CODE = re.compile(r"``([^`]*)``|`([^`]*)`")  # ``code`` (reST), `code` (Markdown)


def robot_text(robots: Mapping[str, Any] | None) -> str:
    """The robots of a run as the summary names them: ``unicycle, turtlebot3_burger, actuated``.

    Args:
        robots: The log's ``meta["robots"]`` (model, profile, dynamics, ...); None: "".
    """
    if not robots:
        return ""
    parts = [robots.get("model"), robots.get("profile") or "no profile", robots.get("dynamics")]
    return ", ".join(str(p) for p in parts if p)


def run_summary(title: str, summary: Mapping[str, Any], simulated: float, wall: float,
                files: Mapping[str, str], detail: bool = True, robots: str = "",
                collided: str = "") -> str:
    """What ``dfcoa run`` prints for one run: outcome, times, key metrics with units, files.

    Args:
        title: ``"scenario / controller / seed s"``.
        summary: :func:`dfcoa_opt.metrics.summary` of the run.
        simulated: Simulated time, s.
        wall: Wall time of the simulation, s.
        files: What was written, label -> path (``log``, ``metrics``, ``plot``, ...).
        detail: Print :data:`RUN_METRICS` (False: the outcome line and the files).
        robots: The robots (:func:`robot_text`), in brackets after the title.
        collided: Who touched what at the first contact (``"robot 0 and robot 2"``),
            after a collision's time, as the figures' titles say it.

    Returns:
        The lines, without a final newline.
    """
    if robots:
        title = f"{title} ({robots})"
    outcome = outcome_text(summary["outcome"], summary["first_contact_time"],
                           summary["deadlock_time"], collided)
    reached = "reached goal" if summary["reached"] else "did not reach goal"
    lines = [f"{title}: {outcome} ({reached}); {simulated:.1f} s simulated "
             f"({wall:.2f} s wall)"]
    if detail:
        lines += [f"  {k:26s} {with_unit(summary[k], k)}" for k in RUN_METRICS
                  if summary.get(k) is not None]  # (the Robotarium's: a gritsbot's only)
        lines.append(f"  ({len(summary)} metrics with their units in the .json; "
                     "definitions: docs/metrics.md)")
    width = max((len(k) for k in files), default=0) + 1
    lines += [f"  {k + ':':{width}s} {path}" for k, path in files.items()]
    return "\n".join(lines)


def plain(text: str) -> str:
    """``text`` without reST roles and code marks.

    ``:class:`~a.B``` becomes ``B``, ``:func:`a.f``` ``a.f``, and a name in single
    or double backticks the name alone.
    """
    text = _ROLE.sub(lambda m: m.group(2).rsplit(".", 1)[-1] if m.group(1) else m.group(2), text)
    return _CODE.sub(lambda m: m.group(1) if m.group(1) is not None else m.group(2), text)


def first_line(obj: Any) -> str:
    """The first line of ``obj``'s docstring as plain text (``""`` without one)."""
    doc = (getattr(obj, "__doc__", None) or "").strip().splitlines()
    return plain(doc[0].strip()) if doc else ""


def controller_list() -> str:
    """``dfcoa list controllers``: one line per id, then the safety filters and policy files."""
    from dfcoa_opt.control.registry import available, available_filters, controller_class

    ids = available()
    width = max((len(c) for c in ids), default=0) + 1
    lines = [f"{cid:{width}s}{first_line(controller_class(cid))}".rstrip() for cid in ids]
    filters = available_filters()
    if filters:
        lines += ["", f"Safety filters: {', '.join(filters)}. Add one to any controller as "
                      f"<controller>+<filter>, e.g. goto_slot+{filters[0]}."]
    lines.append("A policy file runs as policy:PATH (docs/policies.md), with a filter too: "
                 "policy:PATH+<filter>.")
    return "\n".join(lines)
