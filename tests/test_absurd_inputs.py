"""Legal-looking but absurd inputs: each is one line and exit 2 (or a run that fails cleanly).

Each case is one a mutation fuzzer found to end in a traceback, a memory
blow-up or a silent wrong run. They go through ``dfcoa run`` (in process,
``dfcoa_opt.cli.main``): the answer must come before any large allocation,
so a regression shows as a MemoryError or a traceback here.
"""

from __future__ import annotations

import resource
from pathlib import Path

import numpy as np
import pytest

import dfcoa_opt as d
from dfcoa_opt.cli import main
from dfcoa_opt.core.errors import DfcoaError, RunFailed
from dfcoa_opt.scenario import budget
from dfcoa_opt.scenario.budget import MAX_CELLS
from dfcoa_opt.sim.simulator import Simulator
from dfcoa_opt.world.robots.models import make_model

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "scenarios" / "example_obstacles.toml"


def _refused(capsys, args, key: str, words: str) -> None:
    """``dfcoa run`` exits 2 with one line naming the file and ``key``, containing ``words``."""
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    assert main(["run", *args]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("dfcoa: error: "), err
    assert f": {key}: " in err and words in err, err
    grown = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - rss
    assert grown < 300_000, f"peak memory grew by {grown / 1e3:.0f} MB"  # kB: refused early


@pytest.mark.parametrize(("sets", "key", "words"), [
    (["comms.latency=1e308"], "comms.latency", "must lie within +-1e+09"),
    (["comms.latency=1e6"], "comms.latency", "exceeds t_max"),
    (["comms.leader_latency=1e9"], "comms.leader_latency", "exceeds t_max"),
    (["t_max=1e308"], "t_max", "must lie within +-1e+09"),
    (["leader.speed=1e300"], "leader.speed", "must lie within +-1e+09"),
    (["formation.spacing=1e10"], "formation.spacing", "must lie within +-1e+09"),
    (["sensors.pose_noise_std=1e300"], "sensors.pose_noise_std", "must lie within +-1e+09"),
    (["metrics.fste_window=1e300"], "metrics.fste_window", "must lie within +-1e+09"),
    (["robots.radius=5e-324"], "robots.radius", "must be >= 1e-09"),
    (["controllers.virtual_spring.beta=1e-300"], "controllers.virtual_spring.beta",
     "must be >= 1e-09"),
    (["controllers.dfcoa.vfh.min_turning_radius=1.3e154"],
     "controllers.dfcoa.vfh.min_turning_radius", "must lie within +-1e+09"),
    (["world.obstacles=[{type='circle', center=[5.0, 5.0], radius=1e-15}]"],
     "world.obstacles[0].radius", "must be >= 0.001"),
    (["controllers.orca_nav.ivo_max_segment=1e-6"], "controllers.orca_nav.ivo_max_segment",
     "must be >= 0.05"),
    (["controllers.reshape.replan_period=1e-7"], "controllers.reshape.replan_period",
     "must be >= 0.01"),
    (["controllers.cbf.max_obstacles=10000000"], "controllers.cbf.max_obstacles",
     "must be <= 1000"),
    (["controllers.lf_vo.leader_index=5"], "controllers.lf_vo.leader_index",
     "is robot 5, but the team has 5 robot(s) (0..4; team.n)"),
    (["controllers.virtual_spring.leader_index=9"], "controllers.virtual_spring.leader_index",
     "is robot 9, but the team has 5 robot(s)"),
    (["t_max=1e9"], "t_max", "instants"),
    (["dt=1e-300", "t_max=1e-300"], "dt", ">= 1e-06"),
    (["sensors.lidar.beams=1000000000"], "sensors.lidar.beams", "<= 100000"),
    (["controllers.reshape.rotations=1000000000"], "controllers.reshape.rotations", "<= 1000"),
    (["world.size=[1000.0, 999.0]"], "world.size", "GiB"),
    (["t_max=900000.0", "team.n=50"], "t_max", "GiB"),
])
def test_refused_before_any_allocation(capsys, sets, key, words):
    args = [str(SCENARIO)]
    for s in sets:
        args += ["--set", s]
    _refused(capsys, args, key, words)


def test_a_batch_too_big_is_refused(capsys):
    _refused(capsys, [str(SCENARIO), "--seeds", "0-99999"], "t_max", "100000 runs")


def test_load_raises_dfcoa_error_not_overflow():
    with pytest.raises(DfcoaError, match="comms.latency"):
        d.load(SCENARIO, comms__latency=1e308)


def test_estimate_grows_with_each_key():
    """The estimate is what the keys drive: twice the steps, twice the log."""
    s = d.load(SCENARIO).spec
    one = budget.estimate(s)
    long = budget.estimate(d.load(SCENARIO, t_max=240.1).spec)  # (t_max / dt + 1) doubles
    assert long["t_max"] == pytest.approx(2 * one["t_max"])
    assert budget.estimate(s, runs=3)["t_max"] == pytest.approx(3 * one["t_max"])
    rec = budget.estimate(s, record_scans=True)["sensors.lidar.beams"]
    assert rec - one["sensors.lidar.beams"] == pytest.approx(budget.steps_of(s) * 5 * 120 * 8)
    assert budget.estimate(s, cells=1e6)["world.size"] == 1e6 * budget.CELL_BYTES


def test_a_huge_map_image_is_refused_from_its_header(tmp_path, capsys):
    from PIL import Image

    side = int(MAX_CELLS ** 0.5) + 1
    Image.new("1", (side, side), 1).save(tmp_path / "big.png")
    text = SCENARIO.read_text().replace("size = [24.0, 14.0]", 'map_image = "big.png"')
    (tmp_path / "s.toml").write_text(text)
    _refused(capsys, [str(tmp_path / "s.toml")], "world.map_image", "pixels")


def test_long_file_names_are_one_line(tmp_path, capsys):
    text = SCENARIO.read_text().replace("size = [24.0, 14.0]", f'map_image = "{"x" * 300}.png"')
    (tmp_path / "s.toml").write_text(text)
    _refused(capsys, [str(tmp_path / "s.toml")], "world.map_image", "not found")


def test_disturbance_values_are_bounded(tmp_path, capsys):
    (tmp_path / "s.toml").write_text(SCENARIO.read_text() + (
        '\n[[disturbances]]\nrobot = 0\nt_start = 1.0\nt_end = 2.0\nvalue = [1e308, 1e308]\n'))
    _refused(capsys, [str(tmp_path / "s.toml")], "disturbances[0].value[0]", "<= 10000")


def test_a_state_beyond_float_range_fails_the_run():
    """A pose that is no longer finite stops the run with RunFailed, never a silent result."""
    s = d.load(SCENARIO, t_max=3.0)
    sim = Simulator(s, _goto(s), 0)
    step = sim.model.step

    def poisoned(*args, **kwargs):
        out = step(*args, **kwargs)
        out.pose[3, 1] = np.nan
        return out

    sim.model.step = poisoned
    with pytest.raises(RunFailed, match=r"robot 3's pose is not finite after t = 0 s \(seed 0\)"):
        sim.run()


def _goto(s):
    from dfcoa_opt.control.registry import build_controller

    return build_controller("goto_slot", s.spec.controllers, s.source)


def test_control_characters_stay_on_one_line(capsys):
    assert main(["run", str(SCENARIO), "--controller", "goto\nslot"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "'goto\\nslot'" in err


def test_a_missing_policy_names_the_scenario_and_key(tmp_path, capsys):
    (tmp_path / "s.toml").write_text(SCENARIO.read_text() + '\n[controllers.learned]\n'
                                     'policy = "0.5"\n')
    _refused(capsys, [str(tmp_path / "s.toml"), "--controller", "learned"],
             "controllers.learned.policy", "'0.5' not found")


def test_a_long_scenario_name_runs_under_a_shortened_file_name(tmp_path, capsys):
    """A 250-character name is legitimate: the run's files get a stable, shorter stem."""
    from dfcoa_opt.bench.sweep import NAME_MAX

    (tmp_path / "s.toml").write_text(f'name = "{"n" * 250}"\n' + SCENARIO.read_text())
    out = tmp_path / "out"
    args = ["run", str(tmp_path / "s.toml"), "--set", "t_max=2.0", "--out", str(out)]
    assert main(args) == 0
    first = sorted(p.name for p in out.iterdir())
    assert len(first) == 2 and all(len(name) <= NAME_MAX + 5 for name in first), first
    assert main(args) == 0 and sorted(p.name for p in out.iterdir()) == first  # stable
    capsys.readouterr()


def test_counts_show_their_bounds_in_the_key_reference():
    from dfcoa_opt.scenario.reference import schema_markdown

    text = schema_markdown()
    assert "| `sensors.lidar.beams` |" in text
    row = next(line for line in text.splitlines() if line.startswith("| `sensors.lidar.beams`"))
    assert "Range: >= 1, <= 100000." in row


@pytest.mark.filterwarnings("error::RuntimeWarning")
@pytest.mark.parametrize("controller", ["virtual_spring", "virtual_spring_basic", "lf_vo"])
def test_a_team_of_one_runs(controller):
    """The leader-robot controllers with nobody to follow them (virtual_spring took an
    argmax over an empty neighbour axis at the first step)."""
    run = d.run(d.load(SCENARIO, **{"team.n": 1, "t_max": 4.0}), controller, seed=0)
    assert np.isfinite(run.log.pose).all() and run.log.pose.shape[1] == 1
    assert np.hypot(*(run.log.pose[-1, 0, :2] - run.log.pose[0, 0, :2])) > 0.3  # it moves


@pytest.mark.filterwarnings("error::RuntimeWarning")
@pytest.mark.parametrize("model", ["single_integrator", "double_integrator"])
def test_largest_speed_limits_with_a_zero_command(model):
    """v_max and a_max of 1e9 with a robot commanded to stay: the speed clip divided the
    limit by 1e-300 for every robot (overflow warning) before it chose not to clip."""
    s = d.load(SCENARIO, **{"robots.model": model, "robots.v_max": 1e9, "robots.a_max": 1e9})
    robot = make_model(s.spec.robots)
    zero = np.zeros((3, 3))
    np.testing.assert_array_equal(robot.saturate(zero), zero)
    fast = np.array([[3e9, 4e9, 0.0]])
    np.testing.assert_allclose(robot.saturate(fast)[0, :2], [0.6e9, 0.8e9])
