import json
import subprocess
import sys
from pathlib import Path

import pytest

from dfcoa_opt.cli import main

ROOT = Path(__file__).resolve().parents[1]
REQUIRED = ("fce_rms fce_mean fce_max fce_x_rms fce_y_rms fse_rms fse_mean stability_pct vce_rms "
            "v_rms w_rms risk_mean risk_max min_inter_robot_distance min_obstacle_clearance "
            "collisions path_length_mean time_to_goal success filter_fallbacks outcome reached "
            "first_contact_time deadlock_time risk_raw_mean risk_raw_max").split()


def test_run_json_prints_exactly_one_object(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "dfcoa_opt", "run",
                           str(ROOT / "scenarios" / "example_empty.toml"), "--controller",
                           "goto_slot", "--json", "--seed", "5", "--out", str(tmp_path)],
                          capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    obj = json.loads(proc.stdout)  # the whole stdout is one JSON document
    assert set(obj) == {"scenario", "controller", "seed", "metrics", "units"}
    assert list(obj["units"]) == list(obj["metrics"])  # every metric has its unit
    assert obj["units"]["fce_rms"] == "m" and obj["units"]["time_to_goal"] == "s"
    written = json.loads((tmp_path / "example_empty-goto_slot-s5.json").read_text())
    assert written == obj
    assert obj["scenario"] == "example_empty" and obj["seed"] == 5
    assert all(k in obj["metrics"] for k in REQUIRED)
    assert obj["metrics"]["success"] is True and obj["metrics"]["reached"] is True
    assert obj["metrics"]["outcome"] == "success"
    assert obj["metrics"]["first_contact_time"] is None  # NaN -> null: no contact
    assert (tmp_path / "example_empty-goto_slot-s5.npz").exists()


def test_plot_and_animate(tmp_path, capsys):
    gif = tmp_path / "a.gif"
    code = main(["run", str(ROOT / "scenarios" / "example_empty.toml"), "--out", str(tmp_path),
                 "--plot", "--animate", str(gif)])
    assert code == 0
    png = tmp_path / "example_empty-goto_slot-s1.png"
    assert png.stat().st_size > 10_000
    assert gif.stat().st_size > 10_000
    out = capsys.readouterr().out
    assert "success (reached goal)" in out and " s simulated (" in out
    lines = [line.split() for line in out.splitlines() if line.strip()]
    # the key metrics with their units, and every file written
    assert any(w[0] == "fce_rms" and w[-1] == "m" for w in lines)
    assert any(w[0] == "time_to_goal" and w[-1] == "s" for w in lines)
    assert any(w[0] == "collisions" and w[1:] == ["0"] for w in lines)
    assert ["plot:", str(png)] in lines and ["animation:", str(gif)] in lines
    assert ["log:", str(tmp_path / "example_empty-goto_slot-s1.npz")] in lines
    assert ["metrics:", str(tmp_path / "example_empty-goto_slot-s1.json")] in lines
    assert "risk_raw" not in out  # the rest is in the .json


def test_run_summary_names_the_contact_time():
    from dfcoa_opt.cli.text import run_summary

    summary = {"outcome": "collision", "reached": False, "first_contact_time": 12.3,
               "deadlock_time": float("nan"), "fce_rms": 0.25, "time_to_goal": float("nan"),
               "min_inter_robot_distance": 0.31, "min_obstacle_clearance": -0.05,
               "path_length_mean": 8.0, "collisions": 2}
    text = run_summary("s / c / seed 0", summary, 30.0, 0.5, {"log": "x.npz"})
    first, *rest = text.splitlines()
    assert first == ("s / c / seed 0: collision at t = 12.30 s (did not reach goal); "
                     "30.0 s simulated (0.50 s wall)")
    assert "  time_to_goal               n/a" in rest
    assert "  min_obstacle_clearance     -0.05 m" in rest and rest[-1] == "  log: x.npz"
    short = run_summary("s", {**summary, "outcome": "deadlock", "deadlock_time": 4.0}, 9.0,
                        0.1, {}, detail=False)
    assert short == ("s: deadlock from t = 4.00 s (did not reach goal); 9.0 s simulated "
                     "(0.10 s wall)")


def test_list(capsys):
    assert main(["list", "controllers"]) == 0
    out = capsys.readouterr().out
    assert "goto_slot" in out and "`" not in out and ":func:" not in out
    assert "goto_slot            Velocity command u_i = kp (slot_i - p_i) + d/dt slot_i." in out
    assert "Safety filters: cbf, orca. Add one to any controller as <controller>+<filter>, " \
           "e.g. goto_slot+cbf." in out
    assert "policy:PATH" in out
    assert main(["list", "scenarios", "--dir", str(ROOT / "scenarios")]) == 0
    assert "example_empty.toml" in capsys.readouterr().out


@pytest.mark.parametrize("argv,msg", [
    (["run", "nope.toml"], "nope.toml: file not found"),
    (["run", str(ROOT / "scenarios" / "example_empty.toml"), "--set", "robots.v_mx=0.5"],
     "--set: robots.v_mx: unknown key (did you mean 'v_max'?)"),
    (["run", str(ROOT / "scenarios" / "example_empty.toml"), "--controller", "orca"],
     "'orca' is a safety filter, which wraps a controller: e.g. 'goto_slot+orca'"),
    (["run", str(ROOT / "scenarios" / "example_empty.toml"), "--seeds", "0-100000"],
     "--seeds: '0-100000' names more than 100,000 seeds"),
    (["run", str(ROOT / "scenarios" / "example_empty.toml"), "--controller", "goto_slat"],
     "did you mean 'goto_slot'"),
    (["list", "scenarios", "--dir", "/no/such/dir"], "scenario folder not found"),
])
def test_errors_exit_2_with_one_line(argv, msg, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and msg in err[0]


def test_console_script_installed():
    exe = Path(sys.executable).parent / "dfcoa"
    proc = subprocess.run([str(exe), "list", "controllers"], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0 and "goto_slot" in proc.stdout


def test_report_baseline_option_checks_the_name(tmp_path, capsys):
    from test_report import synthetic_rows, write_results

    folder = write_results(tmp_path / "res", synthetic_rows())
    assert main(["report", str(folder), "--baseline", "ctl_c"]) == 2
    assert "not a variant" in capsys.readouterr().err
    assert main(["report", str(folder), "--baseline", "ctl_b"]) == 0
    md = (folder / "report" / "report.md").read_text()
    assert "Baseline of the paired comparisons: `ctl_b`." in md and "### Ranking" in md


def test_run_summary_names_the_robots_and_who_collided(tmp_path, capsys):
    """The Burger on the crossing: its profile and dynamics in the header, every wheel ratio,
    and the first contact's parties after its time, as the figures' titles say it."""
    argv = ["run", str(ROOT / "scenarios" / "bench" / "crossing.toml"), "--controller",
            "goto_slot", "--set", "robots.profile=turtlebot3_burger", "--set",
            "robots.dynamics=actuated", "--set", "t_max=25", "--out", str(tmp_path)]
    assert main(argv) == 0
    first, *rest = capsys.readouterr().out.splitlines()
    assert "(unicycle, turtlebot3_burger, actuated)" in first
    assert "collision at t = " in first and "(robot 0 and moving obstacle 0)" in first
    assert any(line.startswith("  wheel_accel_ratio ") for line in rest)


def test_bench_prints_each_distinct_error_once_with_its_count(tmp_path, capsys):
    bad = tmp_path / "bad.py"
    bad.write_text("import numpy as np\nimport dfcoa_opt as d\n"
                   "from dataclasses import dataclass\n\n"
                   "@d.register('nan_out')\nclass NanOut:\n    command = 'velocity'\n"
                   "    @dataclass(frozen=True)\n    class Params:\n        pass\n"
                   "    def __init__(self, p):\n        pass\n"
                   "    def reset(self, scenario, rng):\n        pass\n"
                   "    def act(self, obs):\n        return np.full((obs.n, 2), np.nan)\n")
    sweep = tmp_path / "s.toml"
    sweep.write_text(f'scenarios = ["{(ROOT / "scenarios" / "example_empty.toml").as_posix()}"]'
                     '\ncontrollers = ["nan_out", "goto_slot"]\nseeds = 3\nplugins = ["bad.py"]\n'
                     '[grid]\nt_max = [0.5]\n')
    assert main(["bench", str(sweep), "--out", str(tmp_path / "r"), "--no-progress",
                 "--jobs", "1"]) == 0
    lines = capsys.readouterr().out.splitlines()
    failed = [ln for ln in lines if ln.startswith("  failed (")]
    assert any("ran 6 (3 failed)" in ln for ln in lines)
    assert len(failed) == 1 and failed[0].startswith("  failed (3 runs): ")
    assert "NaN/inf" in failed[0]
