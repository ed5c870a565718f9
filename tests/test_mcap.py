"""write_mcap: a rosbag2 MCAP file read back with rosbags' own reader.

The run (dfcoa on example_obstacles: LiDAR, three static shapes, one moving
disc, contacts) is written once; every check decodes the file with
``rosbags.rosbag2.Reader`` and the type store's CDR deserialiser, which this
toolkit did not write, and compares with the log and the world.
"""

from __future__ import annotations

import math
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore

from dfcoa_opt.cli import main
from dfcoa_opt.core.errors import DfcoaError
from dfcoa_opt.metrics.outcome import contact_steps
from dfcoa_opt.scenario.loader import load_scenario
from dfcoa_opt.sim.batch import BatchSimulator
from dfcoa_opt.sim.log import RunLog
from dfcoa_opt.sim.simulator import batch_controllers
from dfcoa_opt.viz.mcap import ROS_DISTRO, write_mcap

SCENARIO = Path(__file__).resolve().parents[1] / "scenarios" / "example_obstacles.toml"


def _run(record: bool, seeds=(0,), **over):
    sc = load_scenario(SCENARIO, seeds[0], over or None)
    logs = BatchSimulator(sc, batch_controllers("dfcoa", sc, len(seeds)), list(seeds),
                          record_scans=record).run_all()
    return sc, logs


@pytest.fixture(scope="module")
def bag(tmp_path_factory):
    """The run, its scenario, and every message of its file by topic: (stamp ns, message)."""
    sc, (log,) = _run(True)
    path = write_mcap(log, tmp_path_factory.mktemp("mcap") / "run.mcap", sc.world)
    store = get_typestore(getattr(Stores, ROS_DISTRO))
    topics: dict[str, list] = defaultdict(list)
    order = []
    with Reader(path) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        for conn, stamp, raw in reader.messages():
            topics[conn.topic].append((stamp, store.deserialize_cdr(raw, conn.msgtype)))
            order.append(stamp)
    return sc, log, topics, types, order


def _yaw(q) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y ** 2 + q.z ** 2))


def _wrap(a):
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def test_every_topic_is_there_with_its_count(bag):
    sc, log, topics, types, _ = bag
    t, n = log.n_steps, log.n_robots
    want = {"/tf": t, "/leader/pose": t, "/formation/slots": t, "/map": 1, "/leader/path": 1,
            "/contacts": int(contact_steps(log).sum())}
    want.update({f"/robot_{i}/odom": t for i in range(n)})
    want.update({f"/robot_{i}/scan": t for i in range(n)})
    assert {k: len(v) for k, v in topics.items() if k != "/obstacles"} == want
    assert len(topics["/obstacles"]) == 1 + t  # static shapes once, the moving disc each step
    assert types["/robot_0/scan"] == "sensor_msgs/msg/LaserScan"
    assert types["/obstacles"] == "visualization_msgs/msg/MarkerArray"
    assert want["/contacts"] > 0


def test_stamps_are_sim_time_and_increase(bag):
    _, log, topics, _, order = bag
    assert np.all(np.diff(order) >= 0)
    want = np.round(log.t * 1e9).astype(np.int64)
    for topic in ("/tf", "/robot_2/odom", "/robot_4/scan", "/formation/slots"):
        stamps = np.array([s for s, _ in topics[topic]])
        assert np.all(np.diff(stamps) > 0), topic
        np.testing.assert_array_equal(stamps, want)
        head = np.array([m.header.stamp.sec * 10**9 + m.header.stamp.nanosec
                         for _, m in topics[topic]] if topic != "/tf" else
                        [m.transforms[0].header.stamp.sec * 10**9
                         + m.transforms[0].header.stamp.nanosec for _, m in topics[topic]])
        np.testing.assert_array_equal(head, want)


def test_poses_equal_the_log(bag):
    _, log, topics, _, _ = bag
    tf = topics["/tf"]
    xy = np.array([[(tr.transform.translation.x, tr.transform.translation.y)
                    for tr in m.transforms] for _, m in tf])
    yaw = np.array([[_yaw(tr.transform.rotation) for tr in m.transforms] for _, m in tf])
    np.testing.assert_array_equal(xy, log.pose[..., :2])
    np.testing.assert_allclose(_wrap(yaw - log.pose[..., 2]), 0.0, atol=1e-12)
    assert [tr.child_frame_id for tr in tf[0][1].transforms] == [
        f"robot_{i}/base_link" for i in range(log.n_robots)]
    odom = [m for _, m in topics["/robot_3/odom"]]
    np.testing.assert_array_equal([(m.pose.pose.position.x, m.pose.pose.position.y)
                                   for m in odom], log.pose[:, 3, :2])
    c, s = np.cos(log.pose[:, 3, 2]), np.sin(log.pose[:, 3, 2])
    vx, vy = log.velocity[:, 3, 0], log.velocity[:, 3, 1]
    body = np.column_stack((c * vx + s * vy, -s * vx + c * vy))
    np.testing.assert_allclose([(m.twist.twist.linear.x, m.twist.twist.linear.y) for m in odom],
                               body, atol=1e-12)
    np.testing.assert_array_equal([m.twist.twist.angular.z for m in odom], log.twist[:, 3, 1])
    lead = [m.pose for _, m in topics["/leader/pose"]]
    np.testing.assert_array_equal([(p.position.x, p.position.y) for p in lead], log.leader[:, :2])
    slots = np.array([[(p.position.x, p.position.y) for p in m.poses]
                      for _, m in topics["/formation/slots"]])
    np.testing.assert_array_equal(slots, log.slots)
    path = topics["/leader/path"][0][1]
    np.testing.assert_array_equal([(p.pose.position.x, p.pose.position.y) for p in path.poses],
                                  log.meta["leader_path"])


def test_scans_equal_the_logged_scans(bag):
    _, log, topics, _, _ = bag
    for i in (0, 4):
        scans = [m for _, m in topics[f"/robot_{i}/scan"]]
        got = np.array([m.ranges for m in scans])
        assert got.dtype == np.float32
        np.testing.assert_array_equal(got, log.scan[:, i].astype(np.float32))
        m, lay = scans[0], log.meta["scan"]
        assert m.header.frame_id == f"robot_{i}/base_link"
        assert (m.angle_min, m.angle_increment) == pytest.approx(
            (lay["angle_min"], lay["angle_increment"]), rel=1e-6)
        assert len(m.ranges) == 120
        assert m.angle_max == pytest.approx(m.angle_min + 119 * m.angle_increment, rel=1e-6)
        assert m.range_max == pytest.approx(6.0)
    assert np.isinf(log.scan).any()  # no-return beams survive as +inf


def test_grid_equals_the_world_map(bag):
    sc, _, topics, _, _ = bag
    grid = topics["/map"][0][1]
    g = sc.world.grid
    assert (grid.info.height, grid.info.width) == g.occupied.shape
    assert grid.info.resolution == pytest.approx(g.cell_size, rel=1e-7)
    assert (grid.info.origin.position.x, grid.info.origin.position.y) == g.origin
    data = np.asarray(grid.data).reshape(grid.info.height, grid.info.width)
    np.testing.assert_array_equal(data, np.where(g.occupied, 100, 0))
    assert g.occupied.any() and not g.occupied.all()


def test_obstacles_and_contacts(bag):
    sc, log, topics, _, _ = bag
    static = topics["/obstacles"][0][1].markers
    assert [m.ns for m in static] == ["static"] * len(sc.world.shapes) == ["static"] * 3
    circle = static[2]  # world.obstacles[2]: circle at (20, 4), radius 0.8
    assert (circle.pose.position.x, circle.pose.position.y, circle.scale.x) == (20.0, 4.0, 1.6)
    rect = static[0]  # [8, 0] - [10, 6.2], closed outline
    assert [(p.x, p.y) for p in rect.points] == [(8, 0), (10, 0), (10, 6.2), (8, 6.2), (8, 0)]
    moving = np.array([[(m.pose.position.x, m.pose.position.y) for m in a.markers]
                       for _, a in topics["/obstacles"][1:]])
    np.testing.assert_array_equal(moving, log.dyn_pos)
    stamps = np.array([s for s, _ in topics["/contacts"]])
    np.testing.assert_array_equal(stamps, np.round(log.t[contact_steps(log)] * 1e9))
    assert all(len(a.markers) >= 1 for _, a in topics["/contacts"])


def test_recording_scans_leaves_the_run_and_batch_equals_single():
    _, plain = _run(False, (0, 3), t_max=15.0)
    _, rec = _run(True, (0, 3), t_max=15.0)
    _, (alone,) = _run(True, (3,), t_max=15.0)
    np.testing.assert_array_equal(rec[1].scan, alone.scan)
    assert rec[1].scan.shape == (rec[1].n_steps, 5, 120)
    for a, b in zip(plain, rec, strict=True):
        assert a.scan is None and b.scan is not None
        assert a.digest() == b.digest()  # the digest leaves the recorded scans out
        for name, arr in a.arrays().items():
            if name != "filter_time":
                np.testing.assert_array_equal(arr, b.arrays()[name], err_msg=name)


def test_scan_survives_save_and_load(tmp_path):
    _, (log,) = _run(True, t_max=3.0)
    back = RunLog.load(log.save(tmp_path / "r.npz"))
    np.testing.assert_array_equal(back.scan, log.scan)
    np.testing.assert_array_equal(back.pose, log.pose)
    _, (plain,) = _run(False, t_max=3.0)
    assert RunLog.load(plain.save(tmp_path / "p.npz")).scan is None


def test_without_rosbags_one_clear_error(monkeypatch, tmp_path):
    import builtins

    real = builtins.__import__

    def no_rosbags(name, *args, **kwargs):
        if name.startswith("rosbags"):
            raise ImportError(name)
        return real(name, *args, **kwargs)

    _, (log,) = _run(False, t_max=1.0)
    monkeypatch.setattr(builtins, "__import__", no_rosbags)
    with pytest.raises(DfcoaError, match=r"'ros' extra"):
        write_mcap(log, tmp_path / "x.mcap")
    assert not list(tmp_path.iterdir())
    # the CLI says so before it simulates: no log written either
    assert main(["run", str(SCENARIO), "--out", str(tmp_path), "--mcap",
                 str(tmp_path / "x.mcap")]) == 2
    assert not list(tmp_path.iterdir())


def test_cli_writes_the_file_and_checks_the_name(tmp_path, capsys):
    out = tmp_path / "o" / "run.mcap"
    assert main(["run", str(SCENARIO), "--controller", "dfcoa", "--set", "t_max=4.0",
                 "--out", str(tmp_path), "--mcap", str(out)]) == 0
    assert "mcap:" in capsys.readouterr().out
    with Reader(out) as reader:
        got = {c.topic: c.msgcount for c in reader.connections}
    assert got["/robot_0/scan"] == got["/tf"] == 41
    assert not [p for p in out.parent.iterdir() if p.name != "run.mcap"]  # no temporary left
    assert main(["run", str(SCENARIO), "--mcap", str(tmp_path / "run.bag")]) == 2
    err = capsys.readouterr().err.strip()
    assert "must end in .mcap" in err and "\n" not in err
    assert main(["run", str(SCENARIO), "--seeds", "0-1", "--mcap", str(out)]) == 2


def test_bench_writes_one_file_per_drawn_run(tmp_path, capsys):
    from dfcoa_opt.bench.report.document import load_rows
    from dfcoa_opt.bench.report.mcap_runs import drawn_rows
    from dfcoa_opt.bench.results.logs import read_log

    tiny = Path(__file__).parent / "data" / "bench" / "tiny.toml"
    sweep = tmp_path / "sweep.toml"
    sweep.write_text(f'scenarios = [{str(tiny)!r}]\ncontrollers = ["goto_slot", "dfcoa"]\n'
                     "seeds = 2\n")
    out = tmp_path / "res"
    assert main(["bench", str(sweep), "--out", str(out), "--executor", "serial",
                 "--no-progress"]) == 0
    assert not (out / "mcap").exists()  # off by default
    assert main(["bench", str(sweep), "--out", str(out), "--executor", "serial",
                 "--no-progress", "--mcap"]) == 0
    assert "mcap: 2 files" in capsys.readouterr().out
    rows = load_rows(out)
    drawn = drawn_rows(rows)
    assert sorted((r["controller"], r["seed"]) for r in drawn) == [("dfcoa", 0), ("goto_slot", 0)]
    for row in drawn:
        log = read_log(out, row)
        with Reader(out / "mcap" / f"{row['key']}.mcap") as reader:
            counts = {c.topic: c.msgcount for c in reader.connections}
            tf = [m for c, _, raw in reader.messages()
                  for m in [get_typestore(getattr(Stores, ROS_DISTRO)).deserialize_cdr(
                      raw, c.msgtype)] if c.topic == "/tf"]
        xy = np.array([[(tr.transform.translation.x, tr.transform.translation.y)
                        for tr in m.transforms] for m in tf])
        np.testing.assert_array_equal(xy, log.pose[..., :2])  # the row's run, bit for bit
        assert ("/robot_0/scan" in counts) == (row["controller"] == "dfcoa")  # goto_slot: no LiDAR


def test_foxglove_layout_names_every_topic_and_is_committed(bag):
    import json

    from dfcoa_opt.viz.mcap import foxglove_layout

    committed = Path(__file__).resolve().parents[1] / "docs" / "foxglove_layout.json"
    assert json.loads(committed.read_text()) == foxglove_layout(10)  # regenerate: docs/ros.md
    layout = foxglove_layout(5)
    shown = set(layout["configById"]["3D!dfcoa"]["topics"])
    plotted = {p["value"].split(".")[0] for p in layout["configById"]["Plot!dfcoa"]["paths"]}
    _, _, topics, _, _ = bag
    assert set(topics) - {"/tf"} == shown | plotted


def test_api_run_to_mcap(tmp_path):
    import dfcoa_opt as d

    r = d.run(d.load(SCENARIO, t_max=2.0), "dfcoa", seed=1, record_scans=True)
    path = r.to_mcap(tmp_path / "sub" / "a.mcap")
    with Reader(path) as reader:
        got = {c.topic: c.msgcount for c in reader.connections}
    assert got["/robot_1/scan"] == r.log.n_steps == 21 and got["/map"] == 1


def test_ros_map_example_end_to_end(tmp_path, capsys):
    """The documented command: a map_server map in, an MCAP file out, its /map the YAML's map."""
    root = Path(__file__).resolve().parents[1]
    out = tmp_path / "out" / "run.mcap"
    assert main(["run", str(root / "scenarios" / "ros_map.toml"), "--controller", "dfcoa",
                 "--mcap", str(out), "--out", str(tmp_path / "out")]) == 0
    assert "success" in capsys.readouterr().out
    from dfcoa_opt.world.map_server import load_map_yaml

    yaml_grid = load_map_yaml(root / "scenarios" / "maps" / "lab.yaml")
    store = get_typestore(getattr(Stores, ROS_DISTRO))
    with Reader(out) as reader:
        (conn,) = [c for c in reader.connections if c.topic == "/map"]
        (grid,) = [store.deserialize_cdr(raw, c.msgtype) for c, _, raw in reader.messages([conn])]
    assert (grid.info.origin.position.x, grid.info.origin.position.y) == (-1.0, -2.0)
    assert grid.info.resolution == pytest.approx(0.05)
    data = np.asarray(grid.data).reshape(grid.info.height, grid.info.width)
    np.testing.assert_array_equal(data == 100, yaml_grid.occupied)  # no shapes: the map alone
