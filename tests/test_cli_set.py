"""``--set KEY=VALUE``: one VALUE parser for run, bench and figures; ``dfcoa run --set``."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

from dfcoa_opt.cli import _overrides, main, parse_set_value
from dfcoa_opt.core.errors import DfcoaError
from dfcoa_opt.sim.log import RunLog

ROOT = Path(__file__).resolve().parents[1]
EMPTY = str(ROOT / "scenarios" / "example_empty.toml")


@pytest.mark.parametrize("word", ["turtlebot3_burger", "line", "mcl", "_x", "a.b-c", "True"])
def test_bare_word_is_a_string(word):
    assert parse_set_value(word) == word


@pytest.mark.parametrize("text,value", [
    ("5", 5), ("5.0", 5.0), ("-2", -2), ("1e3", 1000.0), ("true", True), ("false", False),
    ("[1, 2]", [1, 2]), ('"quoted"', "quoted"), ('"a b"', "a b"), ("'x=y'", "x=y"),
    ("{a = 1}", {"a": 1}),
])
def test_toml_values_keep_their_meaning(text, value):
    got = parse_set_value(text)
    assert got == value and type(got) is type(value)


def test_inf_and_nan_stay_floats():
    assert parse_set_value("inf") == math.inf and math.isnan(parse_set_value("nan"))


@pytest.mark.parametrize("text", ["1.2.3", "a b", "", "-x", "[1, 2", "x=y", "3abc"])
def test_neither_toml_nor_bare_word_is_an_error(text):
    with pytest.raises(ValueError):
        parse_set_value(text)


def test_overrides_dict_and_errors():
    assert _overrides([]) is None
    assert _overrides(["t_max=0.5", "formation.shape=line", " seed = 3"]) == {
        "t_max": 0.5, "formation.shape": "line", "seed": 3}
    with pytest.raises(DfcoaError, match=r"--set: 't_max' is not KEY=VALUE"):
        _overrides(["t_max"])
    with pytest.raises(DfcoaError, match=r"--set: t_max: '1\.2\.3' is not a TOML value"):
        _overrides(["t_max=1.2.3"])


def _log(folder: Path, seed: int) -> RunLog:
    return RunLog.load(folder / f"example_empty-goto_slot-s{seed}.npz")


def test_run_set_changes_the_run(tmp_path, capsys):
    assert main(["run", EMPTY, "--out", str(tmp_path / "a"), "--set", "t_max=0.5"]) == 0
    out = capsys.readouterr().out
    assert "0.5 s simulated" in out  # the file says t_max = 80
    short = _log(tmp_path / "a", 1)
    assert short.t[-1] <= 0.5 + 1e-9 and len(short.t) <= 6
    # a bare word reaches a string key: the line formation starts the robots elsewhere
    assert main(["run", EMPTY, "--out", str(tmp_path / "b"), "--json", "--set", "t_max=0.5",
                 "--set", "formation.shape=line"]) == 0
    obj = json.loads(capsys.readouterr().out)
    assert obj["scenario"] == "example_empty" and obj["seed"] == 1
    line = _log(tmp_path / "b", 1)
    assert line.t[-1] <= 0.5 + 1e-9
    assert not np.allclose(line.pose[0], short.pose[0])


def test_run_set_reaches_every_seed(tmp_path, capsys):
    assert main(["run", EMPTY, "--out", str(tmp_path), "--json", "--seeds", "0-2",
                 "--set", "t_max=0.3"]) == 0
    objs = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert [o["seed"] for o in objs] == [0, 1, 2]
    for seed in (0, 1, 2):
        assert _log(tmp_path, seed).t[-1] <= 0.3 + 1e-9


@pytest.mark.parametrize("item,msg", [
    ("t_maxx=1.0", "t_maxx"),  # unknown key: named
    ("formation.shape=lien", "formation.shape"),  # a bare word, but not a shape
    ("t_max=abc", "t_max"),  # a bare word where a number goes
    ("t_max", "--set: 't_max' is not KEY=VALUE"),
    ("=5", "--set: '=5' is not KEY=VALUE"),
    ("t_max=1.2.3", "--set: t_max: '1.2.3' is not a TOML value or a bare word"),
])
def test_run_set_errors_exit_2_with_one_line(tmp_path, capsys, item, msg):
    assert main(["run", EMPTY, "--out", str(tmp_path), "--set", item]) == 2
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("dfcoa: error: ") and msg in err[0], err
    assert captured.out == "" and not list(tmp_path.iterdir())  # nothing ran


def test_run_help_shows_set(capsys):
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    assert "--set KEY=VALUE" in help_text and "a bare word is a string" in help_text


def test_figures_shares_the_parser(tmp_path, capsys):
    """A bare word reaches figures' scenarios as a string (and fails validation there)."""
    base = ["figures", "--out", str(tmp_path / "o"), "--cache", str(tmp_path / "c"),
            "--scenarios", str(ROOT / "scenarios"), "--executor", "serial"]
    assert main([*base, "--set", "t_max=abc"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "t_max: must be a number, got str 'abc'" in err[0], err
    assert main([*base, "--set", "t_max=1.2.3"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["dfcoa: error: --set: t_max: '1.2.3' is not a TOML value or a bare word "
                   "(quote other strings)"]
