"""``world.map_yaml``: ROS map_server maps (YAML + PGM/PNG), read as nav2 reads them.

The maps are written by the test's own map_server writer (:func:`write_map`) from
an ASCII map with '#' occupied, '.' free and '?' unknown, choosing for each mode
the pixels map_server reads back as intended. Each is checked cell by cell
against the same map given as ``world.map_ascii`` (unknown as '#': the toolkit
counts it occupied).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from dfcoa_opt.core.errors import ScenarioError
from dfcoa_opt.scenario.loader import load_scenario, scenario_from_dict
from dfcoa_opt.world.flat_yaml import parse_flat_yaml
from dfcoa_opt.world.map_server import (
    grey_and_alpha,
    load_map_yaml,
    map_server_values,
    read_map_yaml,
)

ROOT = Path(__file__).resolve().parents[1]

#: 20 x 12 cells, top row first: walls, two blocks, a wall stub and two unknown patches.
MAP = """\
####################
#..................#
#..##.......??.....#
#..##.......??.....#
#..................#
#..................#
#..................#
#......#...........#
#......#.....##....#
#..??..#.....##....#
#..................#
####################"""
RES = 0.25                 # m/cell in the YAML; 4 cells/m in the toolkit
ORIGIN = (-1.5, 2.0)       # m, the map's lower-left corner
START = (ORIGIN[0] + 2.5 * RES, ORIGIN[1] + 6.5 * RES)    # centre of cell (row 6, col 2)
GOAL = (ORIGIN[0] + 16.5 * RES, ORIGIN[1] + 6.5 * RES)    # centre of cell (row 6, col 16)


# ------------------------------------------------------------------- the writer
def _pixels(ascii_map: str, mode: str, negate: bool, channels: str) -> np.ndarray:
    """8-bit pixels (top row first) that map_server reads back as ``ascii_map``.

    trinary/scale: occupied black, free near-white (map_saver's 0 and 254), swapped
    with ``negate``; unknown: alpha 0 when the image has alpha, else a mid grey (-1 in
    trinary, 1..99 in scale: occupied either way). raw: the values 100, 0 and 255 (-1).
    """
    rows = ascii_map.splitlines()
    occ = np.array([[c == "#" for c in r] for r in rows])
    unk = np.array([[c == "?" for c in r] for r in rows])
    if mode == "raw":
        grey = np.where(occ, 100, np.where(unk, 255, 0))
    else:
        black_is_occupied = not negate
        grey = np.where(occ, 0 if black_is_occupied else 255, 254 if black_is_occupied else 1)
        grey = np.where(unk, 128, grey)
    grey = grey.astype(np.uint8)
    alpha = np.where(unk, 0, 255).astype(np.uint8)
    if channels == "L":
        return grey
    if channels == "LA":
        return np.dstack([grey, alpha])
    if channels == "RGB":
        return np.dstack([grey] * 3)
    return np.dstack([grey] * 3 + [alpha])


def write_image(path: Path, pixels: np.ndarray, fmt: str) -> None:
    """Write ``pixels`` as a binary PGM (P5), a plain PGM (P2) or a PNG."""
    h, w = pixels.shape[:2]
    if fmt == "pgm":
        path.write_bytes(b"P5\n%d %d\n255\n" % (w, h) + pixels.astype(np.uint8).tobytes())
    elif fmt == "p2":
        body = "\n".join(" ".join(str(v) for v in row) for row in pixels)
        path.write_text(f"P2\n# plain PGM\n{w} {h}\n255\n{body}\n")
    else:  # Pillow picks L, LA, RGB or RGBA from the shape
        Image.fromarray(np.ascontiguousarray(pixels, dtype=np.uint8)).save(path)


def write_yaml(path: Path, image: str, *, resolution: object = RES,
               origin: object = (*ORIGIN, 0.0), negate: object = 0, mode: str | None = None,
               occupied_thresh: object = 0.65, free_thresh: object = 0.196,
               extra: str = "", drop: tuple[str, ...] = ()) -> Path:
    """A map_server YAML as nav2's map_saver writes it (``drop`` leaves keys out)."""
    fields = {"image": image, "mode": mode, "resolution": resolution,
              "origin": f"[{', '.join(str(v) for v in origin)}]"
              if isinstance(origin, tuple) else origin,
              "negate": negate, "occupied_thresh": occupied_thresh, "free_thresh": free_thresh}
    lines = [f"{k}: {v}" for k, v in fields.items() if v is not None and k not in drop]
    path.write_text("# written by the test\n" + "\n".join(lines) + "\n" + extra)
    return path


def write_map(folder: Path, ascii_map: str = MAP, *, fmt: str = "pgm", mode: str = "trinary",
              negate: bool = False, channels: str = "L", yaml: dict | None = None) -> Path:
    """A map_server map of ``ascii_map`` in ``folder``: its YAML path.

    ``yaml`` overrides fields of the YAML as written (:func:`write_yaml`'s keywords).
    """
    ext = "png" if fmt == "png" else "pgm"
    write_image(folder / f"map.{ext}", _pixels(ascii_map, mode, negate, channels), fmt)
    fields = {"mode": mode, "negate": int(negate), **(yaml or {})}
    return write_yaml(folder / "map.yaml", f"map.{ext}", **fields)


def scenario(world: dict) -> dict:
    """A one-robot scenario on ``world`` from START to GOAL."""
    return {"world": world, "robots": {"radius": 0.2}, "team": {"n": 1},
            "formation": {"shape": "line", "spacing": 0.5},
            "leader": {"start": list(START), "goal": list(GOAL)},
            "sensors": {"lidar": {"enabled": False}}}


def ascii_scenario(tmp_path: Path):
    """The reference: ``MAP`` as ``world.map_ascii``, unknown written as occupied."""
    world = {"map_ascii": MAP.replace("?", "#"), "resolution": 1 / RES, "origin": list(ORIGIN)}
    return scenario_from_dict(scenario(world), "ref.toml", tmp_path)


# ------------------------------------------------------- occupancy, cell by cell
CASES = [("pgm", "trinary", False, "L"), ("pgm", "trinary", True, "L"),
         ("pgm", "scale", False, "L"), ("pgm", "raw", False, "L"), ("p2", "trinary", False, "L"),
         ("png", "trinary", False, "L"), ("png", "trinary", True, "LA"),
         ("png", "scale", False, "RGB"), ("png", "scale", True, "RGBA"),
         ("png", "trinary", False, "RGBA"), ("png", "raw", True, "L")]


@pytest.mark.parametrize("fmt, mode, negate, channels", CASES,
                         ids=["-".join(map(str, c)) for c in CASES])
def test_the_map_reads_cell_by_cell_as_the_same_ascii_map(tmp_path, fmt, mode, negate, channels):
    write_map(tmp_path, fmt=fmt, mode=mode, negate=negate, channels=channels)
    sc = scenario_from_dict(scenario({"map_yaml": "map.yaml"}), "s.toml", tmp_path)
    ref = ascii_scenario(tmp_path)
    grid = sc.world.raster
    assert grid is not None and grid.shape == (12, 20)
    np.testing.assert_array_equal(grid.occupied, ref.world.raster.occupied)
    np.testing.assert_array_equal(sc.world.grid.occupied, ref.world.grid.occupied)
    assert grid.occupied[2, 3] and grid.occupied[8, 12]  # the unknown patches are occupied
    assert grid.resolution == ref.world.raster.resolution == 4.0


def test_the_origin_and_resolution_place_the_map_in_the_world(tmp_path):
    write_map(tmp_path)
    grid = scenario_from_dict(scenario({"map_yaml": "map.yaml"}), "s.toml", tmp_path).world.grid
    assert grid.origin == ORIGIN
    assert grid.extent == pytest.approx((-1.5, -1.5 + 20 * RES, 2.0, 2.0 + 12 * RES))
    # the block at image rows 2-3 (from the top), cols 3-4: cells (8..9, 3..4) from the bottom
    centre = (ORIGIN[0] + 3.5 * RES, ORIGIN[1] + 8.5 * RES)       # (-0.625, 4.125) m
    row, col = grid.world_to_cell(centre)
    assert (int(row), int(col)) == (8, 3) and grid.occupied[8, 3]
    assert grid.is_occupied_at([(-0.51, 4.01), (-0.76, 4.125), (-0.625, 3.99)]).tolist() == [
        True, False, False]   # inside the block; one cell west of it; one cell below it
    np.testing.assert_allclose(grid.cell_centers()[8, 3], centre)


def test_paths_are_relative_to_the_scenario_and_to_the_yaml(tmp_path):
    (tmp_path / "maps" / "img").mkdir(parents=True)
    write_image(tmp_path / "maps" / "img" / "m.pgm", _pixels(MAP, "trinary", False, "L"), "pgm")
    write_yaml(tmp_path / "maps" / "a.yaml", "img/m.pgm")
    write_yaml(tmp_path / "maps" / "b.yaml", str(tmp_path / "maps" / "img" / "m.pgm"))
    ref = ascii_scenario(tmp_path).world.raster.occupied
    for name in ("a", "b"):
        sc = scenario_from_dict(scenario({"map_yaml": f"maps/{name}.yaml"}), "s.toml", tmp_path)
        np.testing.assert_array_equal(sc.world.raster.occupied, ref)


def test_a_size_matching_the_map_is_allowed(tmp_path):
    write_map(tmp_path)
    sc = scenario_from_dict(scenario({"map_yaml": "map.yaml", "size": [5.0, 3.0]}), "s.toml",
                            tmp_path)
    assert sc.world.grid.size == pytest.approx((5.0, 3.0))


def test_the_shipped_example_map():
    sc = load_scenario(ROOT / "scenarios" / "ros_map.toml")
    grid = sc.world.raster
    assert grid.origin == (-1.0, -2.0) and grid.resolution == pytest.approx(20.0)
    assert grid.extent == pytest.approx((-1.0, 11.0, -2.0, 6.0))
    occupied = grid.is_occupied_at([(2.4, -1.2), (5.0, 4.0), (5.0, 2.0), (0.8, 1.0), (-0.95, 0)])
    assert occupied.tolist() == [True, True, False, False, True]  # unknown, wall, door, free, wall


# ------------------------------------------------------ the values nav2 publishes
def test_trinary_values_at_the_thresholds():
    # occ = 1 - p/255: p = 89 -> 0.65098 (>= 0.65: 100), p = 90 -> 0.64706 (-1),
    # p = 205 -> 0.196078 (> 0.196: -1), p = 206 -> 0.192157 (0)
    px = np.array([[0, 89, 90, 205, 206, 254, 255]], np.uint8)
    assert map_server_values(px, "trinary", False, 0.65, 0.196).tolist() == [
        [100, 100, -1, -1, 0, 0, 0]]
    # negate: occ = p/255, so white is occupied: p = 89 -> 0.349 and 90 -> 0.353 (-1),
    # p = 205 -> 0.804 (100)
    assert map_server_values(px, "trinary", True, 0.65, 0.196).tolist() == [
        [0, -1, -1, 100, 100, 100, 100]]


def test_a_value_equal_to_a_threshold_counts_as_past_it():
    # nav2 (Jazzy and later): occupied when occ >= occupied_thresh, free when occ <= free_thresh
    px = np.array([[0, 255]], np.uint8)                   # occ exactly 1.0 and 0.0
    assert map_server_values(px, "trinary", False, 1.0, 0.0).tolist() == [[100, 0]]
    # in float32, as nav2: p = 204 gives occ = 1 - 0.8f = 0.19999998807907104 exactly
    occ = float(np.float32(1) - np.float32(204) / np.float32(255))
    assert occ == 0.19999998807907104
    px = np.array([[204]], np.uint8)
    assert map_server_values(px, "trinary", False, 0.65, occ).tolist() == [[0]]
    assert map_server_values(px, "trinary", False, 0.65, 0.1999998).tolist() == [[-1]]
    assert map_server_values(px, "trinary", False, occ, 0.1).tolist() == [[100]]


def test_scale_values_between_the_thresholds():
    # thresholds 0.25 / 0.65: value = round(100 (occ - 0.25) / 0.4), half away from zero
    # p = 191: occ 0.25098 -> 0.245 -> 0 (published free although above free_thresh)
    # p = 180: 0.294118 -> 11.03 -> 11; p = 128: 0.498039 -> 62.01 -> 62
    # p = 92: 0.639216 -> 97.30 -> 97; p = 90: 0.647059 -> 99.26 -> 99; p = 89: 100
    px = np.array([[200, 191, 180, 128, 92, 90, 89]], np.uint8)
    assert map_server_values(px, "scale", False, 0.65, 0.25).tolist() == [
        [0, 0, 11, 62, 97, 99, 100]]


def test_alpha_makes_a_pixel_unknown_except_in_raw_mode():
    la = np.array([[[0, 255], [0, 254], [254, 0], [128, 255]]], np.uint8)
    assert map_server_values(la, "trinary", False, 0.65, 0.196).tolist() == [[100, -1, -1, -1]]
    assert map_server_values(la, "scale", False, 0.65, 0.25).tolist() == [[100, -1, -1, 62]]
    raw = np.array([[[0, 0], [50, 0], [100, 255], [101, 255], [255, 255]]], np.uint8)
    assert map_server_values(raw, "raw", True, 0.65, 0.25).tolist() == [[0, 50, 100, -1, -1]]


def test_colour_pixels_use_the_rec601_luma():
    rgb = np.array([[[255, 0, 0], [0, 255, 0], [0, 0, 255], [128, 128, 128]]], np.uint8)
    grey, alpha = grey_and_alpha(rgb)
    assert grey.tolist() == [[76, 149, 29, 128]] and alpha is None  # 306/601/117 of 1024


# --------------------------------------------------------------- the YAML reader
def test_the_flat_yaml_reader_reads_the_map_server_subset():
    text = ("---\n# comment\nimage: \"my map #1.pgm\"  # trailing\nmode: Trinary\n\n"
            "resolution: 5e-2\norigin: [ -1, 2.5 , 0 ]\nnegate: false\nfree_thresh: '0.2'\n"
            "occupied_thresh: .65\n")
    assert parse_flat_yaml(text, "m.yaml") == {
        "image": "my map #1.pgm", "mode": "Trinary", "resolution": 0.05, "origin": [-1, 2.5, 0],
        "negate": False, "free_thresh": "0.2", "occupied_thresh": 0.65}


def test_a_quoted_number_reads_as_a_number_and_mode_ignores_case(tmp_path):
    write_map(tmp_path, yaml={"resolution": '"0.25"', "free_thresh": "'0.196'", "negate": '"0"'})
    text = (tmp_path / "map.yaml").read_text().replace("mode: trinary", "mode: TRINARY")
    (tmp_path / "map.yaml").write_text(text)
    meta = read_map_yaml(tmp_path / "map.yaml")
    assert (meta.resolution, meta.free_thresh, meta.negate, meta.mode) == (
        0.25, 0.196, False, "trinary")


def test_mode_defaults_to_trinary(tmp_path):
    write_image(tmp_path / "m.pgm", _pixels(MAP, "trinary", False, "L"), "pgm")
    meta = read_map_yaml(write_yaml(tmp_path / "m.yaml", "m.pgm"))
    assert meta.mode == "trinary" and meta.origin == ORIGIN and meta.image == tmp_path / "m.pgm"


# ------------------------------------------------------------------------ errors
def _error(call) -> str:
    with pytest.raises(ScenarioError) as info:
        call()
    msg = str(info.value)
    assert "\n" not in msg, msg
    return msg


YAML_ERRORS = [
    ({"drop": ("image",)}, "image", "is required"),
    ({"drop": ("free_thresh",)}, "free_thresh", "is required"),
    ({"drop": ("negate",)}, "negate", "is required"),
    ({"drop": ("origin",)}, "origin", "is required"),
    ({"free_thresh": 0.7, "occupied_thresh": 0.6}, "free_thresh", "must be below"),
    ({"free_thresh": 0.65}, "free_thresh", "must be below"),
    ({"occupied_thresh": 1.5}, "occupied_thresh", "in [0, 1]"),
    ({"free_thresh": -0.1}, "free_thresh", "in [0, 1]"),
    ({"free_thresh": ".nan"}, "free_thresh", "in [0, 1]"),
    ({"occupied_thresh": "high"}, "occupied_thresh", "must be a number"),
    ({"resolution": 0}, "resolution", "> 0"),
    ({"resolution": -0.05}, "resolution", "> 0"),
    ({"resolution": ".inf"}, "resolution", "finite"),
    ({"resolution": "[0.05]"}, "resolution", "must be a number"),
    ({"mode": "binary"}, "mode", "unknown mode 'binary'"),
    ({"origin": "[1.0, 2.0]"}, "origin", "3 numbers"),
    ({"origin": "3.0"}, "origin", "3 numbers"),
    ({"origin": "[1.0, .inf, 0.0]"}, "origin", "finite"),
    ({"origin": "[1.0, x, 0.0]"}, "origin", "must be a number"),
    ({"origin": "[1.0, 2.0, 0.5]"}, "origin", "rotated maps are not supported"),
    ({"negate": 2}, "negate", "must be 0, 1, true or false"),
    ({"negate": "yes"}, "negate", "must be 0, 1, true or false"),
    ({"extra": "unknown_thresh: 0.5\n"}, "unknown_thresh", "unknown map_server key"),
    ({"extra": "frame: {id: map}\n"}, "frame", "unsupported YAML"),
    ({"extra": "resolution: 0.1\n"}, "resolution", "duplicate key"),
    ({"extra": "origin2:\n  x: 1\n"}, "origin2", "nested maps are not supported"),
    ({"extra": "  indented: 1\n"}, "line 8", "nested values"),
    ({"extra": "- 1\n"}, "line 8", "nested values"),
    ({"extra": "---\nimage: b.pgm\n"}, "line 8", "one YAML document"),
    ({"extra": "notes: |\n"}, "notes", "unsupported YAML"),
    ({"extra": "just text\n"}, "line 8", "expected 'key: value'"),
    ({"extra": "x: 'open\n"}, "line 8", "unterminated quoted string"),
    ({"extra": "x: [1, 2\n"}, "x", "unterminated list"),
    ({"extra": "x: a: b\n"}, "x", "unexpected ':'"),
]


@pytest.mark.parametrize("fields, key, fragment", YAML_ERRORS,
                         ids=[f"{k}-{f[:20]}" for _, k, f in YAML_ERRORS])
def test_a_bad_yaml_field_is_one_line_naming_the_file_and_the_key(tmp_path, fields, key,
                                                                   fragment):
    write_map(tmp_path, yaml={"mode": None, **fields})
    yaml = tmp_path / "map.yaml"
    msg = _error(lambda: scenario_from_dict(scenario({"map_yaml": "map.yaml"}), "s.toml",
                                            tmp_path))
    assert msg.startswith(f"{yaml}: {key}: "), msg
    assert fragment in msg, msg


def test_image_errors_name_the_yaml_file_and_the_image_key(tmp_path):
    yaml = write_yaml(tmp_path / "m.yaml", "missing.pgm")
    msg = _error(lambda: load_map_yaml(yaml))
    assert msg.startswith(f"{yaml}: image: ") and "missing.pgm' not found" in msg
    (tmp_path / "garbage.pgm").write_bytes(b"not an image at all")
    msg = _error(lambda: load_map_yaml(write_yaml(yaml, "garbage.pgm")))
    assert msg.startswith(f"{yaml}: image: cannot read image") and "garbage.pgm" in msg
    empty = write_yaml(tmp_path / "empty.yaml", "''")
    assert _error(lambda: read_map_yaml(empty)).startswith(f"{empty}: image: must be a file name")
    Image.new("I;16", (4, 4)).save(tmp_path / "deep.png")
    msg = _error(lambda: load_map_yaml(write_yaml(yaml, "deep.png")))
    assert msg.startswith(f"{yaml}: image: ") and "8-bit" in msg


@pytest.mark.parametrize("width, height", [(11000, 10000), (20000, 20000)])
def test_a_huge_image_is_refused_from_its_header_before_decoding(tmp_path, width, height):
    # a header alone: the pixels are never read (1.1e8 cells: over our limit; 4e8: Pillow's too)
    (tmp_path / "big.pgm").write_bytes(b"P5\n%d %d\n255\n" % (width, height))
    write_yaml(tmp_path / "m.yaml", "big.pgm")
    msg = _error(lambda: scenario_from_dict(scenario({"map_yaml": "m.yaml"}), "s.toml",
                                            tmp_path))
    assert msg.startswith(f"{tmp_path / 'm.yaml'}: image: ") and "accepts" in msg, msg
    write_map(tmp_path)
    assert "more than the 1e+02 cells" in _error(lambda: load_map_yaml(tmp_path / "map.yaml",
                                                                       max_cells=100))


SCENARIO_ERRORS = [
    ({"map_yaml": "nope.yaml"}, "world.map_yaml", "nope.yaml' not found"),
    ({"map_yaml": "map.yaml", "map_ascii": "..\n.."}, "world.map_yaml",
     "give map_yaml or map_ascii, not both"),
    ({"map_yaml": "map.yaml", "map_image": "x.png"}, "world.map_yaml",
     "give map_yaml or map_image, not both"),
    ({"map_yaml": "map.yaml", "resolution": 4.0}, "world.resolution", "is set by the map YAML"),
    ({"map_yaml": "map.yaml", "resolution": 10.0}, "world.resolution", "is set by the map YAML"),
    ({"map_yaml": "map.yaml", "origin": [0.0, 0.0]}, "world.origin", "is set by the map YAML"),
    ({"map_yaml": "map.yaml", "image_threshold": 0.5}, "world.image_threshold",
     "does not apply to a map YAML"),
    ({"map_yaml": "map.yaml", "size": [6.0, 3.0]}, "world.size", "does not match the map"),
]


@pytest.mark.parametrize("world, key, fragment", SCENARIO_ERRORS,
                         ids=[f"{k}-{f[:16]}" for _, k, f in SCENARIO_ERRORS])
def test_scenario_keys_that_clash_with_the_map_yaml(tmp_path, world, key, fragment):
    write_map(tmp_path)
    msg = _error(lambda: scenario_from_dict(scenario(world), "s.toml", tmp_path))
    assert msg.startswith(f"s.toml: {key}: ") and fragment in msg, msg


def test_a_map_beyond_the_extent_limit_names_the_map_yaml(tmp_path):
    write_map(tmp_path, yaml={"origin": (2e6, 0.0, 0.0)})
    msg = _error(lambda: scenario_from_dict(scenario({"map_yaml": "map.yaml"}), "s.toml",
                                            tmp_path))
    assert msg.startswith("s.toml: world.map_yaml: the map spans"), msg


def test_dfcoa_run_on_a_bad_map_yaml_exits_2_with_one_line(tmp_path, capsys):
    from dfcoa_opt.cli import main

    write_map(tmp_path, yaml={"origin": (-1.5, 2.0, math.pi / 2)})
    toml = tmp_path / "bad.toml"
    toml.write_text('[world]\nmap_yaml = "map.yaml"\n[team]\nn = 1\n[formation]\nshape = "line"'
                    f"\n[leader]\nstart = {list(START)}\ngoal = {list(GOAL)}\n")
    assert main(["run", str(toml), "--json", "--out", str(tmp_path / "out")]) == 2
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert out == "" and len(lines) == 1, err
    assert f"{tmp_path / 'map.yaml'}: origin: yaw 1.5708 rad: rotated" in lines[0], lines[0]
    assert "Traceback" not in err
