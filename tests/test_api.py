"""The Python facade (dfcoa_opt.load / run / controllers / register, Run)."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from matplotlib.figure import Figure

import dfcoa_opt as d
from dfcoa_opt.core.errors import DfcoaError, ScenarioError, UnknownNameError
from dfcoa_opt.scenario.loader import load_scenario
from dfcoa_opt.sim.simulator import run_scenario

ROOT = Path(__file__).resolve().parents[1]
EMPTY = ROOT / "scenarios" / "example_empty.toml"


def test_the_readme_line_runs_dfcoa_on_s1_to_success():
    s = d.load(ROOT / "scenarios" / "dfcoa_s1.toml")
    assert d.run(s, "dfcoa").metrics["outcome"] == "success"


def test_load_takes_dotted_and_keyword_overrides_and_names_a_bad_key():
    s = d.load(EMPTY, seed=7, overrides={"leader.speed": 0.2}, t_max=12.5)
    assert (s.spec.seed, s.spec.leader.speed, s.spec.t_max) == (7, 0.2, 12.5)
    assert d.load(EMPTY, leader__speed=0.25).spec.leader.speed == 0.25
    with pytest.raises(ScenarioError, match=r"example_empty\.toml: robots\.radios: unknown key"):
        d.load(EMPTY, robots__radios=0.3)


def test_run_is_the_command_line_run_bit_for_bit_and_seeded():
    s = load_scenario(EMPTY)
    a, b = d.run(s, "goto_slot", seed=3), d.run(EMPTY, "goto_slot", seed=3)
    assert a.log.digest() == b.log.digest() == run_scenario(s, "goto_slot", 3).digest()
    assert a.log.meta["seed"] == 3
    noisy = d.load(EMPTY, overrides={"sensors.lidar.noise_std": 0.05})
    assert d.run(noisy, "dfcoa", seed=1).log.digest() != d.run(noisy, "dfcoa", seed=2).log.digest()


def test_metrics_use_the_scenario_settings():
    r = d.run(EMPTY, "goto_slot")
    assert r.metrics["outcome"] == "success" and r.metrics["reached"]
    assert set(r.metrics) >= {"fce_rms", "fse_rms", "time_to_goal", "min_inter_robot_distance"}


class Hold:
    """Stands still: zero velocity for every robot."""

    command = "velocity"
    uses_scan = False

    @dataclass(frozen=True)
    class Params:
        pass

    def __init__(self, params: Params) -> None:
        self.p = params

    def reset(self, scenario, rng) -> None:
        pass

    def act(self, obs):
        return np.zeros((len(obs.pose), 2))


@pytest.fixture
def hold_registered(monkeypatch):
    """``Hold`` registered as ``api_test_hold`` for one test (the registry is restored)."""
    from dfcoa_opt.control import registry

    registry.available()  # load the built-ins before the copy
    monkeypatch.setattr(registry.CONTROLLERS, "_table", dict(registry.CONTROLLERS._table))
    assert d.register("api_test_hold")(Hold) is Hold


def test_registered_controllers_are_listed_and_run_by_id_or_object(hold_registered):
    assert {"dfcoa", "reshape", "api_test_hold"} <= set(d.controllers())
    s = d.load(EMPTY, t_max=3.0)
    by_id, by_object = d.run(s, "api_test_hold"), d.run(s, Hold(Hold.Params()))
    assert by_id.log.digest() == by_object.log.digest()
    np.testing.assert_array_equal(by_id.log.pose[-1], by_id.log.pose[0])
    with pytest.raises(UnknownNameError, match="did you mean 'dfcoa'"):
        d.run(s, "dfcao")
    with pytest.raises(DfcoaError, match="registry id or an object with act"):
        d.run(s, 42)


def test_plot_and_animate_return_figures_and_write_files(tmp_path):
    r = d.run(d.load(EMPTY, t_max=2.0), "goto_slot")
    fig = r.plot(tmp_path / "a" / "run.png")
    assert isinstance(fig, Figure) and fig.axes[0].get_title().startswith("example_empty")
    assert (tmp_path / "a" / "run.png").read_bytes()[:4] == b"\x89PNG"
    gif = tmp_path / "run.gif"
    assert isinstance(r.animate(gif, max_frames=5), Figure)
    assert gif.read_bytes()[:3] == b"GIF"
    with pytest.raises(DfcoaError, match="must end in .gif"):
        r.animate(tmp_path / "run.mp4")


def test_the_package_ships_its_type_information():
    assert (Path(d.__file__).parent / "py.typed").is_file()
    assert set(d.__all__) >= {"load", "run", "controllers", "register", "Run"}


def _demo_sweep(folder: Path, **kw) -> d.Results:
    spec = {"scenarios": [str(EMPTY)], "controllers": ["goto_slot", "api_test_hold"],
            "seeds": 2, "baseline": "goto_slot"}
    with pytest.warns(UserWarning, match="api_test_hold registered in this process only"):
        return d.sweep(spec, folder, jobs=2, overrides={"t_max": 4.0}, **kw)


def test_sweep_from_a_dict_gives_rows_logs_a_table_and_a_report(tmp_path, hold_registered,
                                                                monkeypatch):
    res = _demo_sweep(tmp_path / "res")
    got = sorted((r["variant"], r["seed"], r["status"]) for r in res.rows)
    assert got == [("api_test_hold", 0, "ok"), ("api_test_hold", 1, "ok"),
                   ("goto_slot", 0, "ok"), ("goto_slot", 1, "ok")]
    hold = [r for r in res.rows if r["variant"] == "api_test_hold"]
    assert all(r["outcome"] == "deadlock" or r["outcome"] == "timeout" for r in hold)
    log = res.log("example_empty", "goto_slot", 1)
    direct = d.run(d.load(EMPTY, t_max=4.0), "goto_slot", seed=1).log
    assert log.digest() == direct.digest()  # a sweep's run is the facade's run
    assert res.table() == res.rows  # without pandas: the list itself
    fake = type("pandas", (), {"DataFrame": staticmethod(lambda rows: ("frame", len(rows)))})
    monkeypatch.setitem(__import__("sys").modules, "pandas", fake)
    assert res.table() == ("frame", 4)
    files = res.report()
    assert files[0].name == "report.md" and "api_test_hold" in files[0].read_text()
    with pytest.raises(DfcoaError, match="no logged run example_empty / dfcoa / seed 0"):
        res.log("example_empty", "dfcoa", 0)
    again = _demo_sweep(tmp_path / "res")  # resumes: every row is reused
    assert [r["digest"] for r in again.rows] == [r["digest"] for r in res.rows]


def test_only_controllers_registered_here_keep_a_sweep_in_this_process(hold_registered):
    from dfcoa_opt.control.registry import known_to_workers

    assert known_to_workers("dfcoa") and known_to_workers("goto_slot+cbf")
    assert not known_to_workers("api_test_hold") and not known_to_workers("api_test_hold+cbf")


def test_each_dict_sweep_gets_its_own_default_folder(tmp_path, monkeypatch):
    """Two different dict sweeps never share a folder (nor rows); the same one resumes."""
    monkeypatch.chdir(tmp_path)
    one = {"scenarios": [str(EMPTY)], "controllers": ["goto_slot"], "seeds": 1}
    two = {**one, "seeds": 2}
    first = d.sweep(one, jobs=1, overrides={"t_max": 3.0})
    second = d.sweep(two, jobs=1, overrides={"t_max": 3.0})
    assert first.folder != second.folder
    assert re.fullmatch(r"results/sweep-[0-9a-f]{8}", first.folder.as_posix())
    assert [r["seed"] for r in first.rows] == [0]
    assert [r["seed"] for r in second.rows] == [0, 1]
    assert len(list((first.folder / "rows").glob("*.json"))) == 1  # nothing of the second
    other = d.sweep(one, jobs=1, overrides={"t_max": 2.0})  # the same dict, other settings
    assert other.folder not in (first.folder, second.folder)
    again = d.sweep(one, jobs=1, overrides={"t_max": 3.0})  # the same sweep: its folder, resumed
    assert again.folder == first.folder
    assert [r["digest"] for r in again.rows] == [r["digest"] for r in first.rows]
    named = d.sweep({**one, "name": "mine"}, jobs=1, overrides={"t_max": 3.0})
    assert named.folder.name.startswith("mine-")


def test_a_bad_sweep_dict_is_one_line_naming_the_key(tmp_path):
    with pytest.raises(ScenarioError, match=r"<dict>: seeds"):
        d.sweep({"scenarios": [str(EMPTY)], "controllers": ["goto_slot"], "seeds": 0},
                tmp_path)


def test_trajectories_are_records_with_named_fields():
    r = d.run(d.load(EMPTY, t_max=2.0), "goto_slot")
    traj = r.log.trajectories()
    n, steps = r.log.n_robots, r.log.n_steps
    assert traj.shape == (n * steps,) and traj.dtype.names == r.log.TRAJECTORY_FIELDS
    two = traj[traj["robot"] == 2]
    np.testing.assert_array_equal(two["x"], r.log.pose[:, 2, 0])
    np.testing.assert_array_equal(two["slot_y"], r.log.slots[:, 2, 1])
    np.testing.assert_array_equal(two["t"], r.log.t)
    np.testing.assert_array_equal(traj["clearance"][:n], r.log.clearance[0])


def test_runlog_is_exported_from_the_package(tmp_path):
    """The README reads a saved log with ``RunLog.load``: ``from dfcoa_opt import RunLog``."""
    from dfcoa_opt import RunLog
    from dfcoa_opt.sim.log import RunLog as Defined

    assert RunLog is Defined and "RunLog" in d.__all__
    run = d.run(d.load(ROOT / "scenarios" / "example_empty.toml", t_max=1.0), "goto_slot", seed=0)
    run.log.save(tmp_path / "r.npz")
    assert RunLog.load(tmp_path / "r.npz").digest() == run.log.digest()
