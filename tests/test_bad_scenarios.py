"""The bad-scenario corpus: each file fails with one line naming file, key and problem."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from dfcoa_opt.core.errors import ScenarioError
from dfcoa_opt.scenario.loader import load_scenario, scenario_from_dict

CORPUS = Path(__file__).parent / "data" / "bad_scenarios"
FILES = sorted(CORPUS.glob("*.toml"))


def expected_fragment(path: Path) -> str:
    side = path.with_suffix(".expect")
    if side.exists():
        return side.read_text().strip()
    first = path.read_text().splitlines()[0]
    assert first.startswith("# expect: "), f"{path.name} lacks its '# expect:' line"
    return first[len("# expect: "):].strip()


def test_corpus_is_large_enough():
    assert len(FILES) >= 25


@pytest.mark.parametrize("path", FILES, ids=[p.stem for p in FILES])
def test_bad_scenario_message(path: Path):
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    msg = str(info.value)
    assert "\n" not in msg
    assert msg.startswith(str(path)), msg
    assert expected_fragment(path) in msg, msg


@pytest.mark.parametrize("path", FILES[:6], ids=[p.stem for p in FILES[:6]])
def test_cli_exit_code_2_without_traceback(path: Path):
    proc = subprocess.run([sys.executable, "-m", "dfcoa_opt", "run", str(path), "--json"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert proc.stdout == ""
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    assert str(path) in lines[0] and expected_fragment(path) in lines[0]


@pytest.mark.parametrize("path", FILES, ids=[p.stem for p in FILES])
def test_cli_run_exits_2_with_one_line(path: Path, capsys):
    """``dfcoa run`` (in-process, every file): exit 2, nothing on stdout, one stderr line."""
    from dfcoa_opt.cli import main

    assert main(["run", str(path), "--json"]) == 2
    out, err = capsys.readouterr()
    assert out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert str(path) in lines[0] and expected_fragment(path) in lines[0], lines[0]


def test_missing_file_is_one_line():
    with pytest.raises(ScenarioError, match="file not found"):
        load_scenario(CORPUS / "no_such_file.toml")


@pytest.mark.parametrize("path", FILES, ids=[p.stem for p in FILES])
def test_bench_rejects_a_sweep_over_the_bad_scenario(path: Path, tmp_path, capsys):
    """``dfcoa bench``: exit 2 and one line naming the scenario file and its problem."""
    from dfcoa_opt.cli import main

    sweep = tmp_path / "sweep.toml"
    sweep.write_text(f'name = "bad"\nscenarios = ["{path}"]\ncontrollers = ["goto_slot"]\n'
                     "seeds = 1\n")
    assert main(["bench", str(sweep), "--out", str(tmp_path / "out"), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert str(path) in err[0] and expected_fragment(path) in err[0], err[0]
    assert not (tmp_path / "out" / "rows").exists()  # rejected before any run


def test_bench_rejects_a_sweep_naming_an_unknown_controller(tmp_path, capsys):
    from dfcoa_opt.cli import main

    scen = Path(__file__).resolve().parents[1] / "scenarios" / "example_empty.toml"
    sweep = tmp_path / "sweep.toml"
    sweep.write_text(f'name = "bad"\nscenarios = ["{scen}"]\ncontrollers = ["goto_slott"]\n')
    assert main(["bench", str(sweep), "--out", str(tmp_path / "out"), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(sweep) in err[0]
    assert "controllers[0]: unknown controller 'goto_slott' (did you mean 'goto_slot'?)" in err[0]


NEAR_MISS = {"world": {"size": [10.0, 10.0]}, "team": {"n": 4},
             "leader": {"start": [2.0, 5.0], "goal": [8.0, 5.0]}}


@pytest.mark.parametrize("edit", [
    {"world": {"size": [10.0, 10.0], "dynamic_obstacles": [
        {"radius": 0.3, "speed": 0.0, "waypoints": [[5.0, 8.0]], "start_time": 0.0}]}},
    {"t_max": 10.0, "world": {"size": [10.0, 10.0], "dynamic_obstacles": [
        {"radius": 0.3, "speed": 0.5, "waypoints": [[5.0, 8.0], [6.0, 8.0]],
         "start_time": 12.0}]}},  # starts after t_max: allowed (a shortened run)
    {"sensors": {"lidar": {"range_min": 3.999, "range_max": 4.0}}},
    {"formation": {"shape": "polar", "offsets": [[1.0, 0.0], [1.0, 1.6], [1.0, 3.1],
                                                  [1.0, 4.7]]}},
    {"formation": {"shape": "grid", "columns": 2}},
    {"leader": {"start": [2.0, 5.0], "goal": [8.0, 5.0], "waypoints": [[5.0, 7.0]]}},
], ids=["parked_disc", "disc_starting_after_t_max", "lidar_range", "polar_offsets",
        "grid_columns", "straight_waypoints"])
def test_the_values_next_to_the_new_rules_still_load(edit: dict):
    """The legal neighbours of the corpus's newer cases load.

    Next to ``parked_disc_start_time``, ``lidar_range_min_above_max``,
    ``formation_*_ignored`` and ``leader_waypoints_ignored``.
    """
    scenario_from_dict({**NEAR_MISS, **edit})
