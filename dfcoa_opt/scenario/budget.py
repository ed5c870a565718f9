"""What a run may ask for: sizes, a bound on its instants, and one check of its estimated memory.

Sizes first: every position and length of a file within :data:`MAX_EXTENT` m
of the origin (:func:`check_extents`), and a map of at most :data:`MAX_CELLS`
cells (:func:`check_cells`; a map file is held to it from its header).

A legal-looking scenario can ask for more than any machine has: ``t_max =
1e9`` is ten billion instants of log, ``sensors.lidar.beams = 1e9`` a
billion-beam scan, ``dfcoa run --seeds 0-100000`` a batch of a hundred
thousand runs. :func:`check_budget` estimates a run's (or a batch's) memory
before anything is allocated, from the keys that drive it, and refuses more
than :data:`MAX_RUN_BYTES` with one line that gives the estimate and the key
to change. The estimate counts what grows with the keys: the log (per instant,
robot and moving disc), the leader's track and the discs' tracks, the grid
(:data:`CELL_BYTES` a cell, measured), the LiDAR's per-step work, the MCL
particles, and the recorded scans; the interpreter and the libraries (about
300 MB) come on top.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from dfcoa_opt.core.errors import ScenarioError

if TYPE_CHECKING:
    from dfcoa_opt.scenario.schema import ScenarioSpec

#: Largest estimated memory of a run or a batch of runs, bytes (2 GiB).
MAX_RUN_BYTES = 2 * 2**30
#: Most instants of a run, ``t_max / dt + 1``: 10^7 is 11.6 days at dt = 0.1 s.
MAX_STEPS = 10**7
#: Log bytes per instant and robot: pose, estimate, velocity, twist, command, slot,
#: clearance, filter status, slack and time, steering (:class:`~dfcoa_opt.sim.log.RunLog`),
#: and the slot of the leader's track.
ROBOT_STEP_BYTES = 24 + 24 + 16 + 16 + 24 + 16 + 8 + 1 + 8 + 8 + 8 + 16
#: Log bytes per instant: time, leader state, closest pair, four contact counters, and the
#: leader's track.
STEP_BYTES = 8 + 40 + 8 + 16 + 40
#: Bytes per instant and moving disc: its logged position and its track (position, velocity).
DISC_STEP_BYTES = 16 + 32
#: Bytes per grid cell once a world is built and run: the occupancy, its distance and
#: clearance fields, the LiDAR's and the planners' tables (46 B measured on 1e6 and 9e6
#: cells with dfcoa, rounded up).
CELL_BYTES = 64
#: Bytes per beam and robot of one step's LiDAR work (angles, hits, ranges, temporaries).
BEAM_BYTES = 64
#: Bytes per MCL particle and robot (pose, weight, the likelihood's temporaries).
PARTICLE_BYTES = 128


def steps_of(spec: ScenarioSpec) -> float:
    """A run's instants, ``t_max / dt + 1`` (a float: it may be absurd)."""
    return spec.t_max / spec.dt + 1.0


def estimate(spec: ScenarioSpec, cells: float = 0.0, runs: int = 1,
             record_scans: bool = False) -> dict[str, float]:
    """Estimated bytes of ``runs`` runs of ``spec`` at once, by the key that drives each part.

    Args:
        spec: The scenario.
        cells: Cells of its grid (0 when they are checked elsewhere).
        runs: Runs stepped as one batch (each has its log; the grid is shared).
        record_scans: Whether the runs keep their scans (``record_scans``).

    Returns:
        ``{key: bytes}``: ``t_max`` (the logs and tracks), ``world.size`` (the grid),
        ``sensors.lidar.beams`` (the LiDAR), ``localization`` (MCL's particles).
    """
    n, m = spec.team.n, len(spec.world.dynamic_obstacles)
    steps = steps_of(spec)
    beams = spec.sensors.lidar.beams if spec.sensors.lidar.enabled else 0
    per_step = n * ROBOT_STEP_BYTES + STEP_BYTES + m * DISC_STEP_BYTES
    out = {"t_max": runs * steps * per_step,
           "world.size": cells * CELL_BYTES,
           "sensors.lidar.beams": runs * n * beams * (BEAM_BYTES + (steps * 8 if record_scans
                                                                    else 0))}
    if spec.localization.mode == "mcl":
        most = (spec.localization.options or {}).get("particle_limits", (0, 5000))[-1]
        out["localization"] = runs * n * float(most) * PARTICLE_BYTES
    return out


def check_budget(spec: ScenarioSpec, source: str, cells: float = 0.0, runs: int = 1,
                 record_scans: bool = False) -> None:
    """Refuse a run (or a batch) whose instants or estimated memory exceed the bounds.

    Args:
        spec: The scenario.
        source: Name used in error messages.
        cells: Cells of its grid (0 when they are checked elsewhere).
        runs: Runs stepped as one batch.
        record_scans: Whether the runs keep their scans.

    Raises:
        ScenarioError: More than :data:`MAX_STEPS` instants (key ``t_max``), or more
            than :data:`MAX_RUN_BYTES` estimated, naming the key whose part is largest.
    """
    steps = steps_of(spec)
    if not steps <= MAX_STEPS:
        raise ScenarioError(source, "t_max", f"t_max / dt = {spec.t_max:g} / {spec.dt:g} s is "
                                             f"{steps:.3g} instants, more than the "
                                             f"{MAX_STEPS:.0e} this toolkit accepts; lower "
                                             "t_max or raise dt")
    parts = estimate(spec, cells, runs, record_scans)
    total = math.fsum(parts.values())
    if total <= MAX_RUN_BYTES:
        return
    key = max(parts, key=lambda k: parts[k])
    what = f" for {runs} runs stepped as one batch (run fewer at once)" if runs > 1 else ""
    raise ScenarioError(source, key, f"the run needs an estimated {total / 2**30:.3g} GiB"
                                     f"{what}, {parts[key] / 2**30:.3g} GiB of it from this "
                                     f"key, more than the {MAX_RUN_BYTES / 2**30:g} GiB this "
                                     "toolkit allows a run (docs/robustness.md)")


def check_extents(spec: ScenarioSpec, offsets: np.ndarray, source: str) -> None:
    """Every length and position of the file lies within :data:`MAX_EXTENT` of the origin.

    Far-away values are mistakes (a missing decimal point, a unit slip), and
    squaring them would overflow inside the geometry.

    Raises:
        ScenarioError: Names the first key with a value beyond the limit.
    """
    items: list[tuple[str, Any]] = [("leader.start", spec.leader.start),
                                    ("leader.goal", spec.leader.goal),
                                    ("team.poses", [p[:2] for p in spec.team.poses]),
                                    ("formation", offsets)]
    for i, o in enumerate(spec.world.obstacles):
        items += [(f"world.obstacles[{i}].{name}", getattr(o, name))
                  for name in ("center", "radius", "min", "max", "vertices")]
    for i, d in enumerate(spec.world.dynamic_obstacles):
        items += [(f"world.dynamic_obstacles[{i}].radius", d.radius),
                  (f"world.dynamic_obstacles[{i}].waypoints", d.waypoints)]
    for key, value in items:
        values = np.asarray(value if value is not None else (), dtype=float)
        if not np.all(np.abs(values) <= MAX_EXTENT):
            shown = value if key != "formation" else "the slot offsets"
            raise ScenarioError(source, key, f"{shown} reach beyond the {MAX_EXTENT:g} m "
                                             f"this toolkit accepts")


#: Largest map, in cells: what fits in a run's memory budget (2 GiB at
#: :data:`CELL_BYTES` a cell: 33,554,432 cells, e.g. 579 m x 579 m at
#: 10 cells/m). A map file is held to it from its header, ``world.size`` by the budget.
MAX_CELLS = MAX_RUN_BYTES // CELL_BYTES
#: Largest coordinate of the map's corners, m.
MAX_EXTENT = 1e6


def check_cells(size: tuple[float, float], resolution: float, source: str) -> None:
    """Refuse a ``world.size`` whose grid would not fit in memory, before allocating it.

    Raises:
        ScenarioError: More than :data:`MAX_CELLS` cells.
    """
    cells = [s * resolution for s in size]
    total = math.prod(max(1.0, c) for c in cells)
    if not total <= MAX_CELLS:
        raise ScenarioError(source, "world.size", f"{size[0]:g} x {size[1]:g} m at "
                            f"{resolution:g} cells/m is {cells[0]:.3g} x {cells[1]:.3g} cells, "
                            f"more than the {MAX_CELLS:.0e} this toolkit accepts")
