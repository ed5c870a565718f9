"""Geometry checked where it is wrong: simple polygons, robot starts, via points, obstacles.

Each refusal is one line naming the source and the key (``dfcoa run`` exits 2);
the simple-polygon test is compared with shapely's on random polygons.
"""

from __future__ import annotations

import copy
import math
from pathlib import Path

import numpy as np
import pytest
import shapely

from dfcoa_opt.core.errors import ScenarioError
from dfcoa_opt.core.polygons import (
    is_simple_polygon,
    polygon_defect,
    segments_cross,
    segments_intersect,
)
from dfcoa_opt.scenario.loader import scenario_from_dict
from dfcoa_opt.world.shapes import Circle, Polygon, Rectangle

SRC = "<start-geometry>"
#: A 20 x 10 m field, four robots in a line abreast 1 m apart, r = 0.2 m.
BASE = {"world": {"size": [20.0, 10.0]}, "robots": {"radius": 0.2}, "team": {"n": 4},
        "formation": {"shape": "line", "spacing": 1.0},
        "leader": {"start": [3.0, 5.0], "goal": [17.0, 5.0]}, "t_max": 2.0}
#: The fuzzer's crossing figure: positive signed area, yet two edges cross.
CROSSING = [[14.0, 8.0], [17.0, 8.0], [14.0, 14.0], [17.0, 14.0], [15.5, 16.0]]


def scenario(**changes: dict) -> dict:
    """``BASE`` with whole sections merged in (``team={...}`` updates ``[team]``)."""
    data = copy.deepcopy(BASE)
    for section, values in changes.items():
        data[section] = {**data.get(section, {}), **values}
    return data


def explicit(*xy: tuple[float, float], **team: object) -> dict:
    return scenario(team={"n": len(xy), "placement": "explicit",
                          "poses": [[x, y, 0.0] for x, y in xy], **team})


def refused(data: dict, key: str, *words: str) -> str:
    """The one-line message of ``data``'s refusal, checked for source, key and words."""
    with pytest.raises(ScenarioError) as info:
        scenario_from_dict(data, SRC)
    msg = str(info.value)
    assert "\n" not in msg and "\r" not in msg, msg
    assert msg.startswith(f"{SRC}: {key}: "), msg
    for w in words:
        assert w in msg, msg
    return msg


# -------------------------------------------------------------------- simple polygons


def test_a_crossing_polygon_with_positive_area_is_refused_naming_its_vertices():
    area = 0.5 * sum(x0 * y1 - x1 * y0 for (x0, y0), (x1, y1)
                     in zip(CROSSING, CROSSING[1:] + CROSSING[:1], strict=True))
    assert area > 0  # the old check (the sign of the area) let it through
    data = scenario(world={"size": [20.0, 20.0], "obstacles": [
        {"type": "circle", "center": [8.0, 15.0], "radius": 1.0},
        {"type": "polygon", "vertices": CROSSING}]})
    refused(data, "world.obstacles[1].vertices", "polygon is not simple", "edge 1 (17, 8)-(14, 14)",
            "cross at (14.8182, 12.3636)")


@pytest.mark.parametrize(("vertices", "words"), [
    ([[5, 1], [7, 1], [7, 1], [7, 3], [5, 3]], "vertices 1 and 2 are the same point (7, 1)"),
    ([[5, 1], [7, 1], [7, 3], [5, 3], [5, 1]], "vertices 4 and 0 are the same point (5, 1)"),
    ([[5, 1], [7, 1], [6, 2], [7, 3], [5, 3], [6, 2]], "vertices 2 and 5 are the same point"),
    ([[5, 1], [8, 1], [8, 3], [6, 1], [5, 3]], "touch"),  # vertex 3 on edge 0
    ([[5, 1], [7, 1], [6, 1], [6, 3]], "fold back"),  # a spike along edge 0
])
def test_repeated_vertices_touching_and_folding_edges_are_refused(vertices, words):
    data = scenario(world={"obstacles": [{"type": "polygon", "vertices": vertices}]})
    refused(data, "world.obstacles[0].vertices", "polygon is not simple", words)


def test_simple_polygons_still_load_and_clockwise_keeps_its_message():
    ok = [[5.0, 1.0], [7.0, 1.0], [7.0, 2.0], [7.0, 3.0], [5.0, 3.0]]  # a vertex mid-edge
    scenario_from_dict(scenario(world={"obstacles": [{"type": "polygon", "vertices": ok}]}))
    refused(scenario(world={"obstacles": [{"type": "polygon", "vertices": ok[::-1]}]}),
            "world.obstacles[0]", "counter-clockwise")


def test_the_polygon_class_refuses_what_is_not_simple_and_producers_make_simple_ones():
    with pytest.raises(ValueError, match="not simple"):
        Polygon(tuple(map(tuple, CROSSING)))
    for c in (Circle((0.0, 0.0), 1e-3), Circle((1e5, -3e5), 0.05), Circle((2.0, 3.0), 50.0)):
        for n in (3, 8, 32, 100):
            assert is_simple_polygon(c.to_polygon(n).as_array())
    assert is_simple_polygon(Rectangle((1e6 - 1e-6, 0.0), (1e6, 1e-9)).to_polygon().as_array())


def _random_polygons(rng: np.random.Generator, count: int) -> list[np.ndarray]:
    """Random point rings (mostly crossing), integer rings (touching, collinear,
    repeated vertices), star-shaped rings (simple) and stars with two vertices swapped."""
    out = []
    for k in range(count):
        v = int(rng.integers(3, 12)) if k % 5 else int(rng.integers(65, 140))  # both paths
        kind = k % 4
        if kind == 0:
            p = rng.uniform(-5.0, 5.0, (v, 2))
        elif kind == 1:
            p = rng.integers(0, 4 if v < 20 else 12, (v, 2)).astype(float)
        else:
            ang = np.sort(rng.uniform(0.0, 2 * np.pi, v))
            p = rng.uniform(0.5, 2.0, v)[:, None] * np.stack((np.cos(ang), np.sin(ang)), 1)
            if kind == 3:
                i, j = rng.choice(v, 2, replace=False)
                p[[i, j]] = p[[j, i]]
        out.append(p)
    return out


def test_segment_tests_agree_with_shapely_on_grid_segments():
    """segments_intersect is shapely's intersects, segments_cross its crosses (a proper
    crossing: touching, a T and a collinear overlap do not count), on integer-grid segments
    where every degenerate case occurs and the orientation tests are exact."""
    rng = np.random.default_rng(11)
    p = rng.integers(0, 5, (3000, 4, 2)).astype(float)
    p = p[np.any(p[:, 0] != p[:, 1], axis=1) & np.any(p[:, 2] != p[:, 3], axis=1)]
    meet = segments_intersect(p[:, 0], p[:, 1], p[:, 2], p[:, 3])
    cross = segments_cross(p[:, 0], p[:, 1], p[:, 2], p[:, 3])
    for k, (a, b, c, d) in enumerate(p):
        one, two = shapely.LineString([a, b]), shapely.LineString([c, d])
        assert meet[k] == one.intersects(two), (a, b, c, d)
        assert cross[k] == one.crosses(two), (a, b, c, d)
    assert 100 < cross.sum() < meet.sum() < len(p) - 100  # every case occurs


def test_the_simple_polygon_test_agrees_with_shapely_on_random_polygons():
    """shapely (GEOS, robust predicates) is the outside oracle: a ring is simple when
    ``LinearRing.is_simple`` and no vertex repeats the one before it (GEOS skips those)."""
    polys = _random_polygons(np.random.default_rng(20261129), 600)
    verdicts = []
    for p in polys:
        repeats = bool(np.any(np.all(p == np.roll(p, -1, axis=0), axis=1)))
        expected = shapely.LinearRing(p).is_simple and not repeats
        assert is_simple_polygon(p) == expected, p.tolist()
        assert is_simple_polygon(p[::-1]) == expected  # orientation does not matter
        verdicts.append(expected)
        d = polygon_defect(p)
        if d is not None:  # the pair named really meets (or is a zero-length edge)
            i, j = d
            e = [shapely.LineString([p[k], p[(k + 1) % len(p)]]) for k in (i, j)]
            assert i == j or e[0].intersects(e[1])
    assert 100 < sum(verdicts) < 500  # both answers well represented


# ------------------------------------------------------------------------ robot starts


def test_a_formation_spacing_that_puts_robots_outside_the_map_is_refused():
    """The fuzzer's ``--set formation.spacing=100000.0``: it ran to a timeout or a success."""
    refused(scenario(formation={"spacing": 100000.0}), "formation.spacing",
            "robots 0, 1, 2 and 3 would start outside the map [0, 20] x [0, 10] m",
            "robot 0 at (3, 150005)", "the slots reach 150000 m from leader.start (3, 5)")
    # the leader beside the map's edge: the slots reach 1.5 m, across y = 0
    refused(scenario(leader={"start": [3.0, 1.0], "goal": [17.0, 1.0]}), "formation.spacing",
            "robot 3 would start outside the map", "robot 3 at (3, -0.5)")


@pytest.mark.parametrize(("section", "key"), [
    ({"formation": {"shape": "v", "spacing": 0.3}}, "formation.spacing"),
    ({"formation": {"shape": "grid", "spacing": 0.35}}, "formation.spacing"),
    ({"formation": {"shape": "rectangle", "width": 0.3, "length": 2.0}}, "formation"),
    ({"formation": {"shape": "offsets", "offsets": [[0, 0], [0, 1], [0.1, 0.3], [0, 2]]}},
     "formation.offsets"),
])
def test_formation_slots_that_overlap_are_refused_naming_the_key_that_sets_them(section, key):
    msg = refused(scenario(**section), key, "would start overlapping",
                  "closer than 2 x robots.radius = 0.4 m", "team.allow_start_contact = true")
    assert "robots 0 and" in msg or "robots 1 and" in msg


def test_explicit_poses_that_overlap_are_refused_naming_the_later_robot():
    refused(explicit((2.0, 2.0), (4.0, 2.0), (2.3, 2.0)), "team.poses[2]",
            "robots 0 and 2 would start overlapping", "(2, 2) and (2.3, 2)", "0.3 m apart",
            "closer than 2 x robots.radius = 0.4 m")
    refused(explicit((2.0, 2.0), (2.0, 2.0)), "team.poses[1]", "0 m apart")  # one point


def test_robots_exactly_touching_are_not_overlapping():
    """The simulator's rule is ``distance < 2 r``; 0.5 m apart with r = 0.25 m is contact-free."""
    data = explicit((2.0, 2.0), (2.5, 2.0), (3.0, 2.0))
    data["robots"] = {"radius": 0.25}
    scenario_from_dict(data, SRC)
    data["robots"] = {"radius": 0.2500001}
    refused(data, "team.poses[1]", "robots 0 and 1")


def test_an_explicit_pose_outside_the_map_is_refused():
    refused(explicit((2.0, 2.0), (25.0, 2.0)), "team.poses[1]",
            "(25, 2) is outside the map [0, 20] x [0, 10] m")


def test_allow_start_contact_lets_a_contact_start_load_and_run():
    from dfcoa_opt.api import run

    data = explicit((2.0, 2.0), (2.3, 2.0), (5.0, 2.0))
    refused(data, "team.poses[1]", "overlapping")
    data["team"]["allow_start_contact"] = True
    sc = scenario_from_dict(data, SRC)
    log = run(sc, "goto_slot").log
    assert log.robot_contacts[0] == 1  # the overlap is there at t = 0, and counted
    slots = scenario(formation={"spacing": 0.3}, team={"allow_start_contact": True})
    assert scenario_from_dict(slots, SRC).initial_pose.shape == (4, 3)


def test_allow_start_contact_never_allows_a_start_outside_the_map():
    refused(scenario(formation={"spacing": 100000.0}, team={"allow_start_contact": True}),
            "formation.spacing", "outside the map")
    data = explicit((2.0, 2.0), (2.0, -1.0), allow_start_contact=True)
    refused(data, "team.poses[1]", "outside the map")


# ------------------------------------------------------------ via points and obstacles


def test_leader_waypoints_inside_an_obstacle_or_outside_the_map_are_refused():
    wall = {"obstacles": [{"type": "rectangle", "min": [9.0, 0.0], "max": [11.0, 3.0]}]}
    data = scenario(world=wall, leader={"planner": "straight", "waypoints": [[6.0, 5.0],
                                                                              [10.0, 2.0]]})
    refused(data, "leader.waypoints[1]", "(10, 2) is inside an obstacle")
    data["leader"]["waypoints"] = [[10.0, 12.0]]
    refused(data, "leader.waypoints[0]", "(10, 12) is outside the map [0, 20] x [0, 10] m")
    data["leader"]["waypoints"] = [[10.0, 6.0]]
    scenario_from_dict(data, SRC)


@pytest.mark.parametrize(("obstacle", "words"), [
    ({"type": "circle", "center": [-3.0, 5.0], "radius": 1.0}, "the circle spans [-4, -2]"),
    ({"type": "circle", "center": [21.0, 11.0], "radius": 1.4}, "the circle"),  # box overlaps
    ({"type": "rectangle", "min": [100.0, 0.0], "max": [101.0, 1.0]}, "the rectangle"),
    ({"type": "polygon", "vertices": [[20.5, 9.0], [22.0, 9.0], [19.5, 11.5]]}, "the polygon"),
])
def test_an_obstacle_wholly_outside_the_map_is_refused(obstacle, words):
    keep = {"type": "circle", "center": [10.0, 8.5], "radius": 0.5}
    data = scenario(world={"obstacles": [keep, keep, keep, obstacle]})
    refused(data, "world.obstacles[3]", words, "wholly outside the map [0, 20] x [0, 10] m")


@pytest.mark.parametrize("obstacle", [
    {"type": "circle", "center": [21.0, 11.0], "radius": math.sqrt(2.0)},  # touches the corner
    {"type": "rectangle", "min": [-1.0, 0.0], "max": [0.0, 10.0]},  # a wall flush with x = 0
    {"type": "polygon", "vertices": [[19.0, 11.0], [21.0, 9.0], [21.0, 11.0]]},  # cuts a corner
    {"type": "polygon", "vertices": [[-5.0, -5.0], [25.0, -5.0], [25.0, 0.5], [-5.0, 0.5]]},
])
def test_an_obstacle_touching_or_overlapping_the_map_is_kept(obstacle):
    scenario_from_dict(scenario(world={"obstacles": [obstacle]}), SRC)


# ------------------------------------------------------------------------------ the CLI


def test_dfcoa_run_exits_2_with_one_line_naming_the_file_and_key(tmp_path: Path, capsys):
    from dfcoa_opt.cli import main

    path = tmp_path / "tight.toml"
    path.write_text('t_max = 2.0\n[world]\nsize = [20.0, 10.0]\n[team]\nn = 3\n'
                    '[formation]\nshape = "line"\nspacing = 0.25\n'
                    '[leader]\nstart = [3.0, 5.0]\ngoal = [17.0, 5.0]\n')
    assert main(["run", str(path)]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1, err
    assert f"{path}: formation.spacing: robots 0 and 1 would start overlapping" in err, err
