"""The clearance_astar leader planner: room for the formation where the map allows."""

from __future__ import annotations

import numpy as np
import pytest

from dfcoa_opt.planning.astar import AStarParams, plan
from dfcoa_opt.planning.clearance import ClearanceParams, clearance_path
from dfcoa_opt.planning.postprocess import min_clearance, path_length
from dfcoa_opt.world.grid import OccupancyGrid
from dfcoa_opt.world.shapes import Circle, Rectangle

SIZE = (20.0, 10.0)


def _grid(*shapes) -> OccupancyGrid:
    return OccupancyGrid.from_shapes(SIZE, 10.0, shapes)


def test_runs_down_the_middle_of_a_corridor() -> None:
    grid = _grid(Rectangle((5.0, 0.0), (15.0, 4.0)), Rectangle((5.0, 6.0), (15.0, 10.0)))
    path = clearance_path(grid, (1.0, 8.0), (19.0, 8.0))
    xs = np.linspace(6.0, 14.0, 50)
    ys = np.interp(xs, path[:, 0], path[:, 1])  # the path is monotone in x here
    assert np.all(np.diff(path[:, 0]) >= 0)
    assert np.max(np.abs(ys - 5.0)) <= 0.05 + 1e-9
    assert min_clearance(grid, path) >= 0.9  # 1 m, less the cell centres' half cell


def test_passes_a_door_narrower_than_the_wanted_clearance() -> None:
    grid = _grid(Rectangle((9.9, 0.0), (10.1, 4.6)), Rectangle((10.1 - 0.2, 5.4), (10.1, 10.0)))
    path = clearance_path(grid, (2.0, 8.0), (18.0, 2.0))
    assert len(path) and np.allclose(path[0], (2.0, 8.0)) and np.allclose(path[-1], (18.0, 2.0))
    y_door = np.interp(10.0, path[:, 0], path[:, 1])
    assert abs(y_door - 5.0) <= 0.1  # the middle of the 0.8 m doorway
    assert min_clearance(grid, path) >= 0.3 - 0.05
    closed = _grid(Rectangle((9.9, 0.0), (10.1, 4.8)), Rectangle((9.9, 5.2), (10.1, 10.0)))
    assert len(clearance_path(closed, (2.0, 8.0), (18.0, 2.0))) == 0  # 0.4 m < 2 x 0.3 m


def test_keeps_away_from_an_obstacle_where_plain_astar_grazes_it() -> None:
    grid = _grid(Circle((10.0, 5.5), 1.0))
    ours = clearance_path(grid, (2.0, 5.0), (18.0, 5.0), ClearanceParams(clearance=1.5))
    plain = plan(grid, (2.0, 5.0), (18.0, 5.0), AStarParams(inflate=0.3)).path
    assert min_clearance(grid, plain) < 0.5
    assert min_clearance(grid, ours) >= 1.4
    assert path_length(ours) < 1.3 * path_length(plain)


def test_shortcuts_keep_the_clearance_of_what_they_replace() -> None:
    rng = np.random.default_rng(2)
    shapes = [Circle((float(x), float(y)), float(r)) for x, y, r in
              zip(rng.uniform(4, 16, 12), rng.uniform(1, 9, 12), rng.uniform(0.3, 0.8, 12),
                  strict=True)]
    grid = _grid(*shapes)
    for clearance in (0.8, 1.5):
        long = clearance_path(grid, (1.0, 5.0), (19.0, 5.0),
                              ClearanceParams(clearance=clearance, shorten=False))
        short = clearance_path(grid, (1.0, 5.0), (19.0, 5.0),
                               ClearanceParams(clearance=clearance))
        assert len(short) < len(long)
        assert path_length(short) <= path_length(long) + 1e-9
        assert min_clearance(grid, short) >= min(min_clearance(grid, long), clearance) - 0.1


def test_bad_options() -> None:
    from dfcoa_opt.core.errors import ScenarioError
    from dfcoa_opt.core.params import build

    with pytest.raises(ScenarioError, match=r"clearance: \(0\.2 m\) must exceed inflate"):
        build(ClearanceParams, {"clearance": 0.2}, "f.toml", "leader.planner_options")
