"""Generated worlds ([world.generate]): families, redraws, seeds, batches, splits."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import dfcoa_opt as d
from dfcoa_opt.core.errors import ScenarioError
from dfcoa_opt.planning.astar import search
from dfcoa_opt.scenario.loader import load_scenario, read_toml, scenario_from_dict
from dfcoa_opt.sim.batch import BatchSimulator
from dfcoa_opt.sim.simulator import batch_controllers
from dfcoa_opt.world import generate as gen
from dfcoa_opt.world.generate.cellular import CellularParams, neighbours, smooth
from dfcoa_opt.world.generate.corridors import CorridorsParams
from dfcoa_opt.world.generate.crowd import MIN_CROSSING_ANGLE, CrowdParams
from dfcoa_opt.world.generate.rects import mask_rectangles
from dfcoa_opt.world.generate.rooms import RoomsParams
from dfcoa_opt.world.shapes import Rectangle

HELDOUT = Path(__file__).resolve().parents[1] / "scenarios" / "heldout"
FAMILIES = ("cellular", "rooms", "corridors", "crowd")
LAYOUT = gen.Layout(extent=(0.0, 30.0, 0.0, 16.0), start=(3.0, 8.0), goal=(27.0, 8.0),
                    start_clear=2.7, goal_clear=2.7)
#: The width of the heldout files' 5-robot V with the bodies, m.
V_WIDTH = 2.66


# ------------------------------------------------------------------ rectangles
def test_mask_rectangles_cover_exactly_the_true_cells() -> None:
    rng = np.random.default_rng(5)
    for _ in range(20):
        mask = rng.random((13, 17)) < 0.4
        xs = np.cumsum(rng.uniform(0.1, 1.0, 18))
        ys = np.cumsum(rng.uniform(0.1, 1.0, 14))
        rects = mask_rectangles(mask, xs, ys)
        cx, cy = np.meshgrid((xs[:-1] + xs[1:]) / 2, (ys[:-1] + ys[1:]) / 2)
        centres = np.column_stack((cx.ravel(), cy.ravel()))
        hits = np.zeros(len(centres), dtype=int)
        for r in rects:
            hits += r.contains(centres)
        assert np.array_equal(hits.reshape(mask.shape), mask.astype(int))  # covered once
        area = sum((r.max[0] - r.min[0]) * (r.max[1] - r.min[1]) for r in rects)
        cell_area = np.outer(np.diff(ys), np.diff(xs))
        assert area == pytest.approx(float(cell_area[mask].sum()))


def test_mask_rectangles_merge_a_block_into_one() -> None:
    mask = np.zeros((4, 5), dtype=bool)
    mask[1:3, 1:4] = True
    assert mask_rectangles(mask, np.arange(6.0), np.arange(5.0)) == (
        Rectangle((1.0, 1.0), (4.0, 3.0)),)


# ------------------------------------------------------------------ cellular automaton
def test_four_five_rule_by_hand() -> None:
    occ = np.array([[1, 1, 0, 0],
                    [1, 0, 0, 0],
                    [1, 1, 0, 1],
                    [0, 0, 0, 0]], dtype=bool)
    n = neighbours(occ)
    assert n[1, 1] == 5 and n[0, 0] == 2 and n[2, 3] == 0 and n[3, 3] == 1
    out = smooth(occ, np.zeros_like(occ))
    # (1, 1): 5 occupied neighbours -> occupied; (1, 0): occupied with 4 -> stays;
    # (0, 0): occupied with 2 -> cleared; (2, 3): isolated -> cleared
    assert out[1, 1] and out[1, 0] and not out[0, 0] and not out[2, 3]
    keep = np.zeros_like(occ)
    keep[1, 1] = True
    assert not smooth(occ, keep)[1, 1]


def test_cellular_statistics_match_parameters() -> None:
    p = CellularParams(cell=0.5, fill=(0.3, 0.45), smoothing=(1, 3))
    fills, passes = [], []
    for seed in range(100):
        facts = gen.generate("cellular", p, gen.world_rng(seed), LAYOUT).facts
        fills.append(facts["fill"])
        passes.append(facts["smoothing"])
        assert facts["final_fill"] <= facts["initial_fill"] + 0.2
    assert min(fills) >= 0.3 and max(fills) <= 0.45
    assert set(passes) == {1, 2, 3}
    # without smoothing, the realised fill is the drawn probability (binomial per world)
    raw = CellularParams(cell=0.5, fill=(0.2, 0.2), smoothing=(0, 0))
    realised = [gen.generate("cellular", raw, gen.world_rng(s), LAYOUT).facts["final_fill"]
                for s in range(100)]
    cells = (18.6 / 0.5) * (16 / 0.5)  # about the band's cells
    assert abs(np.mean(realised) - 0.2) < 4 * np.sqrt(0.2 * 0.8 / (cells * 100))


# ------------------------------------------------------------------ rooms
def _wall_gaps(shapes, x: float, y1: float) -> list[float]:
    """The free stretches of the wall at ``x`` (its doorways), bottom to top."""
    spans = sorted((s.min[1], s.max[1]) for s in shapes if s.min[0] < x < s.max[0])
    edges = [0.0, *(v for span in spans for v in span), y1]
    return [b - a for a, b in zip(edges[::2], edges[1::2], strict=True) if b - a > 1e-12]


def test_rooms_statistics_match_parameters() -> None:
    p = RoomsParams(rooms=(3, 5), door_width=(1.0, 3.6), doors=(1, 2), door_gap=0.5)
    widths: list[float] = []
    for seed in range(100):
        g = gen.generate("rooms", p, gen.world_rng(seed), LAYOUT)
        f = g.facts
        assert 3 <= f["rooms"] <= 5 and len(f["walls"]) == f["rooms"] - 1
        lo, hi = LAYOUT.span()
        assert all(lo <= x <= hi for x in f["walls"])
        per_wall = [_wall_gaps(g.shapes, x, 16.0) for x in f["walls"]]
        assert all(1 <= len(gaps) <= 2 for gaps in per_wall)
        assert np.allclose(sorted(w for gaps in per_wall for w in gaps), sorted(f["door_widths"]))
        widths += f["door_widths"]
    assert min(widths) >= 1.0 and max(widths) <= 3.6
    narrower = np.mean(np.array(widths) < V_WIDTH)
    assert 0.4 < narrower < 0.8  # some narrower than the formation, some wider


# ------------------------------------------------------------------ corridors
def test_corridor_statistics_match_parameters() -> None:
    p = CorridorsParams(width=(1.2, 3.2), turns=(4, 8))
    turns = set()
    for seed in range(100):
        g = gen.generate("corridors", p, gen.world_rng(seed), LAYOUT)
        f = g.facts
        assert all(1.2 <= w <= 3.2 for w in f["widths"])
        assert f["turns"] % 2 == 0 and 4 <= f["turns"] <= 8
        turns.add(f["turns"])
        line = np.array(f["centre_line"])
        assert line[:, 1].min() >= 0.5 + 1.6 - 1e-9 or f["turns"] == 0
        assert np.all(line[:, 1] <= 16 - 0.5 - 1.6 + 1e-9) or f["turns"] == 0
        for q in line:  # the centre line is free: no wall contains a corner of it
            assert not any(s.contains(q[None])[0] for s in g.shapes)
    assert turns == {4, 6, 8}


# ------------------------------------------------------------------ crowd
def test_crowd_statistics_match_parameters() -> None:
    p = CrowdParams(count=7, speed=(0.2, 0.5), radius=(0.2, 0.35), start_delay=30.0)
    for seed in range(100):
        g = gen.generate("crowd", p, gen.world_rng(seed), LAYOUT)
        assert len(g.discs) == 7 and g.facts["count"] == 7 and not g.shapes
        for disc in g.discs:
            assert 0.2 <= disc.speed <= 0.5 and 0.2 <= disc.radius <= 0.35
            assert 0.0 <= disc.start_time <= 30.0 and disc.end == "bounce"
            a, b = np.array(disc.waypoints)
            # the track crosses the start-goal line (y = 8) between the free discs ...
            t = (8.0 - a[1]) / (b[1] - a[1])
            x = a[0] + t * (b[0] - a[0])
            assert 0.0 <= t <= 1.0 and 3.0 + 2.7 - 1e-9 <= x <= 27.0 - 2.7 + 1e-9
            # ... at least 30 degrees off it, and waits at the end farther from the start
            angle = np.arctan2(abs(b[1] - a[1]), abs(b[0] - a[0]))
            assert angle >= MIN_CROSSING_ANGLE - 1e-9
            assert np.hypot(*(a - (3, 8))) >= np.hypot(*(b - (3, 8)))


# ------------------------------------------------------------------ loading
@pytest.mark.parametrize("family", FAMILIES)
def test_generated_worlds_are_connected(family: str) -> None:
    for seed in range(20000, 20006):
        sc = load_scenario(HELDOUT / f"{family}.toml", seed)
        assert sc.world.facts is not None and sc.seed_dependent
        assert gen.passage_exists(sc.world.grid, sc.spec.leader.start, sc.spec.leader.goal,
                                  sc.spec.robots.radius + 0.05)
        # an independent check: grid A* on the map grown by a robot radius
        grown = sc.world.grid.inflate(sc.spec.robots.radius)
        start = tuple(int(v) for v in grown.world_to_cell(np.array(sc.spec.leader.start)))
        goal = tuple(int(v) for v in grown.world_to_cell(np.array(sc.spec.leader.goal)))
        assert search(grown.occupied, start, goal).found
        assert np.allclose(sc.leader_path[0], sc.spec.leader.start)
        assert np.allclose(sc.leader_path[-1], sc.spec.leader.goal)


def _data(family: str) -> dict:
    data = read_toml(HELDOUT / f"{family}.toml")
    data["name"] = family
    return data


def test_same_seed_same_world_in_a_batch_and_alone() -> None:
    sc = load_scenario(HELDOUT / "crowd.toml", 20000, {"t_max": 8.0})
    seeds = [20003, 20001, 20007]
    sim = BatchSimulator(sc, batch_controllers("goto_slot", sc, len(seeds)), seeds)
    for seed, batched in zip(seeds, sim.scenarios, strict=True):
        alone = load_scenario(HELDOUT / "crowd.toml", seed, {"t_max": 8.0})
        assert batched.world.shapes == alone.world.shapes
        assert batched.world.dynamic.discs == alone.world.dynamic.discs
        assert np.array_equal(batched.leader_path, alone.leader_path)
    logs = sim.run_all()
    for seed, log in zip(seeds, logs, strict=True):  # each run its run alone, bit for bit
        alone = d.run(load_scenario(HELDOUT / "crowd.toml", seed, {"t_max": 8.0}), "goto_slot")
        assert log.digest() == alone.log.digest()
        assert not np.array_equal(log.dyn_pos, logs[0].dyn_pos) or seed == seeds[0]


def test_same_seed_same_world_everywhere() -> None:
    a = load_scenario(HELDOUT / "rooms.toml", 20011)
    b = scenario_from_dict({**_data("rooms"), "seed": 20011}, "x", HELDOUT)
    assert a.world.shapes == b.world.shapes and a.world.facts == b.world.facts
    assert load_scenario(HELDOUT / "rooms.toml", 20012).world.shapes != a.world.shapes
    fixed = {**_data("rooms"), "world": {**_data("rooms")["world"],
                                         "generate": {**_data("rooms")["world"]["generate"],
                                                      "seed": 7}}}
    one = scenario_from_dict({**fixed, "seed": 1}, "x", HELDOUT)
    two = scenario_from_dict({**fixed, "seed": 2}, "x", HELDOUT)
    assert one.world.shapes == two.world.shapes and not one.seed_dependent


# ------------------------------------------------------------------ errors
def _with(file: str, **generate) -> dict:
    data = _data(file)
    data["world"] = {**data["world"], "generate": {**data["world"]["generate"], **generate}}
    return data


def test_no_passage_stops_with_one_line_after_the_tries() -> None:
    data = _with("rooms", tries=3, options={"door_width": [0.2, 0.3]})
    with pytest.raises(ScenarioError, match=r"world\.generate: family 'rooms' drew no world "
                                            r"with a passage 0\.5 m wide .* in 3 draws") as e:
        scenario_from_dict(data, "f.toml", HELDOUT)
    assert "\n" not in str(e.value)


@pytest.mark.parametrize(("generate", "match"), [
    ({"family": "room"}, r"world\.generate\.family: unknown world family 'room' \(did you "
                         r"mean 'rooms'\?\)"),
    ({"options": {"door_widht": [1.0, 2.0]}}, r"world\.generate\.options\.door_widht: unknown "
                                              r"key \(did you mean 'door_width'\?\)"),
    ({"options": {"door_width": [3.0, 2.0]}}, r"world\.generate\.options\.door_width: \[3, 2\]"),
    ({"options": {"rooms": [1, 3]}}, r"world\.generate\.options\.rooms\[0\]: must be >= 2"),
    ({"tries": 0}, r"world\.generate\.tries: must be >= 1"),
])
def test_bad_generate_tables(generate: dict, match: str) -> None:
    with pytest.raises(ScenarioError, match=match):
        scenario_from_dict(_with("rooms", **generate), "f.toml", HELDOUT)


@pytest.mark.parametrize("family", FAMILIES)
def test_dfcoa_run_plots_a_generated_world(family: str, tmp_path: Path) -> None:
    from dfcoa_opt.cli import main

    data = _data(family)
    text = (HELDOUT / f"{family}.toml").read_text()
    short = tmp_path / f"{family}.toml"
    short.write_text(text.replace(f"t_max = {data['t_max']}", "t_max = 2.0"))
    assert main(["run", str(short), "--seed", "20001", "--controller", "reshape", "--plot",
                 "--out", str(tmp_path)]) == 0
    assert (tmp_path / f"{family}-reshape-s20001.png").stat().st_size > 10_000
