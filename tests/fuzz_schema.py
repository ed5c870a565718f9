"""The loader fuzz tests' cost model and the schema's key names.

- :func:`too_costly` tells legal but slow examples (huge maps, teams, clutter
  fields, A* windows) from absurd ones, which must fail fast.
- ``SCHEMA_KEYS``, ``NAMES``, ``TABLE_PATHS`` and ``ARRAY_PATHS`` are read from
  the schema dataclasses and every registered controller, filter, planner and
  estimator, so the strategies (:mod:`tests.fuzz_strategies`) reach deep keys.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any, Literal, get_args, get_origin, get_type_hints

from dfcoa_opt.control.registry import available, available_filters, controller_class
from dfcoa_opt.planning.improved_astar import ImprovedAStarParams
from dfcoa_opt.planning.registry import planner_names
from dfcoa_opt.scenario.schema import ScenarioSpec
from dfcoa_opt.sim.localization import estimator_names
from dfcoa_opt.sim.localization.mcl import MonteCarloLocalization

ROOT = Path(__file__).resolve().parents[1]

# ----------------------------------------------------------------- cost model
CELL_CAP = 250_000  # grid cells (bench/large_100.toml: 240,000; 9e6 cells: 1.5 s)
N_CAP = 1_000_000  # robots (10**7 on a line: 0.3 s; 10**8: > 4 GiB)
DISC_CAP = 2_000  # expected clutter discs
DISC_CELLS_CAP = 5e7  # expected clutter discs x grid cells (rasterisation)
WINDOW_CAP = 60.0  # improved-A* window, cells (60: 0.5 s on dfcoa_s2; 200: 7.6 s)
FAST_FAIL = 1e13  # numpy refuses allocations this large at once


def num(x: Any) -> float | None:
    """``x`` as a float when it is a (non-bool) number, else None; huge ints give inf."""
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        return None
    try:
        return float(x)
    except OverflowError:
        return math.inf if x > 0 else -math.inf


def _table(data: Any, key: str) -> dict[str, Any]:
    value = data.get(key) if isinstance(data, dict) else None
    return value if isinstance(value, dict) else {}


def _costly(value: float | None, cap: float) -> bool:
    """In the skipped band: above the cap but not absurd enough to fail at once."""
    return value is not None and cap < value < FAST_FAIL


def _grid_cells(world: dict[str, Any], res: float) -> tuple[float, float] | None:
    """Estimated ``(columns, rows)`` of the grid the loader would build, or None."""
    ascii_map = world.get("map_ascii")
    if isinstance(ascii_map, str):
        lines = ascii_map.strip("\n").split("\n")
        return float(max(len(ln) for ln in lines)), float(len(lines))
    size = world.get("size")
    if isinstance(size, list) and len(size) == 2:
        w, h = (num(s) for s in size)
        if w is not None and h is not None and w > 0 and h > 0:
            return max(1.0, w * res), max(1.0, h * res)
    return None


def too_costly(data: Any) -> bool:
    """Whether loading ``data`` could legally build a world too large for a fuzz example.

    See the module docstring; a conservative estimate read from the raw dict
    (whatever its types), not a check of validity.
    """
    world = _table(data, "world")
    res = num(world.get("resolution", 10.0))
    res = res if res is not None and res > 0.0 else 10.0
    grid = _grid_cells(world, res)
    cells = grid[0] * grid[1] if grid is not None else None
    if _costly(cells, CELL_CAP):
        return True
    if _costly(num(_table(data, "team").get("n")), N_CAP):
        return True
    window = num(_table(_table(data, "leader"), "planner_options").get("window"))
    if window is not None and _costly(window * res, WINDOW_CAP):
        return True
    clutter = _table(world, "clutter")
    density = num(clutter.get("density"))
    r_min = num(clutter.get("radius_min", 0.2))
    if density is None or not density > 0.0 or r_min is None or not r_min > 0.0:
        return False
    region = clutter.get("region")
    nums = [num(v) for v in region] if isinstance(region, list) else []
    if len(nums) == 4 and None not in nums:
        x0, y0, x1, y1 = nums  # type: ignore[misc]
        width, height = x1 - x0, y1 - y0
    elif grid is not None:
        width, height = grid[0] / res, grid[1] / res  # the grid's extent
    else:
        width = height = 0.0
    if not (math.isfinite(width) and math.isfinite(height)):
        return False  # numpy refuses the draw range at once
    discs = density * abs(width * height) / math.pi / r_min / r_min  # may be inf
    return discs > DISC_CAP or discs * (cells or CELL_CAP) > DISC_CELLS_CAP


# ----------------------------------------------------------------- schema names
def _walk_schema(cls: type, prefix: str, keys: set[str], names: set[str],
                 tables: set[str], arrays: set[str]) -> None:
    """Collect field names, literal choices and table paths of a dataclass tree."""
    for f in dataclasses.fields(cls):
        keys.add(f.name)
        tp = get_type_hints(cls)[f.name]
        path = f"{prefix}.{f.name}" if prefix else f.name
        for arg in (tp, *get_args(tp), *(a for b in get_args(tp) for a in get_args(b))):
            if get_origin(arg) is Literal:
                names.update(str(c) for c in get_args(arg))
        if dataclasses.is_dataclass(tp):
            tables.add(path)
            _walk_schema(tp, path, keys, names, tables, arrays)
        elif get_origin(tp) is tuple and get_args(tp) and dataclasses.is_dataclass(
                get_args(tp)[0]):
            arrays.add(path)
            _walk_schema(get_args(tp)[0], path, keys, names, tables, arrays)
        elif get_origin(tp) is dict:
            tables.add(path)


def _filter_params() -> dict[str, type]:
    from dfcoa_opt.control import registry

    return {fid: registry.FILTERS.get(fid).Params for fid in available_filters()}


CONTROLLER_PARAMS: dict[str, type] = {cid: controller_class(cid).Params for cid in available()}
CONTROLLER_PARAMS.update(_filter_params())
PLANNER_PARAMS = ImprovedAStarParams  # a superset of the astar options
ESTIMATOR_PARAMS = MonteCarloLocalization.Params

_keys: set[str] = set()
_names: set[str] = {*CONTROLLER_PARAMS, *planner_names(), *estimator_names()}
_tables: set[str] = set()
_arrays: set[str] = set()
_walk_schema(ScenarioSpec, "", _keys, _names, _tables, _arrays)
for _cls in (*CONTROLLER_PARAMS.values(), PLANNER_PARAMS, ESTIMATOR_PARAMS):
    _walk_schema(_cls, "", _keys, _names, set(), set())
_tables.update(f"controllers.{cid}" for cid in CONTROLLER_PARAMS)
SCHEMA_KEYS = sorted(_keys)
NAMES = sorted(_names)
TABLE_PATHS = sorted(_tables)
ARRAY_PATHS = sorted(_arrays)
