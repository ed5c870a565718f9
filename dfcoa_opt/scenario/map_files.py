"""The grid of a scenario's map file: ``world.map_ascii``, ``map_image`` or ``map_yaml``.

Each problem is a one-line :class:`~dfcoa_opt.core.errors.ScenarioError` naming the
scenario file (or the map's YAML file) and the key; an image is held to
:data:`~dfcoa_opt.scenario.budget.MAX_CELLS` from its header, before its pixels are
decoded.
"""

from __future__ import annotations

import math
from pathlib import Path

from dfcoa_opt.core.atomic import file_exists
from dfcoa_opt.core.errors import ScenarioError
from dfcoa_opt.scenario.budget import MAX_CELLS
from dfcoa_opt.world.grid import OccupancyGrid
from dfcoa_opt.world.map_server import check_image, load_map_yaml
from dfcoa_opt.world.spec import WorldSpec


def grid_cells(ws: WorldSpec) -> float:
    """Cells of a ``world.size`` grid (0 with a map file: its size is checked as it loads)."""
    if ws.size is None or ws.map_ascii or ws.map_image or ws.map_yaml:
        return 0.0
    return math.prod(max(1.0, s * ws.resolution) for s in ws.size)


def map_file(ws: WorldSpec, source: str, base_dir: Path) -> OccupancyGrid | None:
    """The grid of ``map_ascii``, ``map_image`` or ``map_yaml``; None without a map file."""
    if ws.map_ascii is not None:
        try:
            return OccupancyGrid.from_ascii(ws.map_ascii, ws.resolution, ws.origin)
        except ValueError as exc:
            raise ScenarioError(source, "world.map_ascii", str(exc)) from None
    if ws.map_yaml is not None:  # ROS map_server's YAML + image (dfcoa_opt.world.map_server)
        yaml = base_dir / ws.map_yaml
        if not file_exists(yaml):
            raise ScenarioError(source, "world.map_yaml", f"map YAML file '{yaml}' not found")
        return load_map_yaml(yaml, MAX_CELLS)
    if ws.map_image is None:
        return None
    img = (base_dir / ws.map_image)
    check_image(img, source, "world.map_image", MAX_CELLS)
    try:
        return OccupancyGrid.from_image(img, ws.resolution, ws.image_threshold, ws.origin)
    except (OSError, ValueError, SyntaxError) as exc:
        raise ScenarioError(source, "world.map_image", f"cannot read image '{img}': "
                                                       f"{exc}") from None
