"""A run as a rosbag2 MCAP file: the topics Foxglove and RViz 2 show (docs/ros.md).

The file is written with ``rosbags`` (the ``ros`` extra), pure Python, no ROS
install: message definitions of ROS 2 Jazzy, CDR-serialised, every message
stamped with simulation time (``t = 0`` is 0 ns). :data:`TOPICS` lists what is
written; frames are ``map`` (the world frame) and ``robot_<i>/base_link``.
"""

from __future__ import annotations

import math
import os
import shutil
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from dfcoa_opt.core.errors import DfcoaError

if TYPE_CHECKING:
    from dfcoa_opt.scenario.scenario import World
    from dfcoa_opt.sim.log import RunLog

#: The ``rosbags`` type store whose message definitions the file carries.
ROS_DISTRO = "ROS2_JAZZY"
#: Topics written: name (``{i}``: robot index), message type, when, what.
TOPICS = (
    ("/tf", "tf2_msgs/msg/TFMessage", "every step",
     "map -> robot_<i>/base_link for every robot (true pose)"),
    ("/robot_{i}/odom", "nav_msgs/msg/Odometry", "every step",
     "true pose; twist in base_link: true velocity, turn rate applied from t"),
    ("/robot_{i}/scan", "sensor_msgs/msg/LaserScan", "every step, when the LiDAR runs",
     "the ranges the robot had (RunLog.scan), in robot_<i>/base_link"),
    ("/map", "nav_msgs/msg/OccupancyGrid", "once, t = 0",
     "the world's grid (map file plus rasterised shapes): 100 occupied, 0 free"),
    ("/leader/path", "nav_msgs/msg/Path", "once, t = 0", "the leader's planned path"),
    ("/leader/pose", "geometry_msgs/msg/PoseStamped", "every step", "the virtual leader"),
    ("/formation/slots", "geometry_msgs/msg/PoseArray", "every step",
     "each robot's formation slot, with the leader's heading"),
    ("/obstacles", "visualization_msgs/msg/MarkerArray", "t = 0; every step with moving discs",
     "static shapes once (ns 'static'), moving discs (ns 'moving')"),
    ("/contacts", "visualization_msgs/msg/MarkerArray", "at instants with a contact",
     "a red sphere where each contact touches (ns 'robot', 'obstacle', 'moving')"),
)
#: The world frame.
MAP_FRAME = "map"
#: Marker colours (r, g, b, a).
_GREY, _ORANGE, _RED = (0.4, 0.4, 0.4, 0.8), (1.0, 0.5, 0.0, 0.8), (1.0, 0.0, 0.0, 1.0)
#: Height of the obstacle markers, m (the world is 2-D).
_HEIGHT = 0.3


def robot_frame(i: int) -> str:
    """Robot ``i``'s body frame: ``robot_<i>/base_link``."""
    return f"robot_{i}/base_link"


def stamp_ns(t: float) -> int:
    """Simulation time ``t`` (s) as integer nanoseconds."""
    return int(round(t * 1e9))


def require_rosbags() -> None:
    """Check that the ``ros`` extra is installed (before a run whose file it must write).

    Raises:
        DfcoaError: ``rosbags`` cannot be imported, with the command that installs it.
    """
    try:
        import rosbags.rosbag2  # noqa: F401
    except ImportError:
        raise DfcoaError("writing MCAP needs the 'ros' extra: pip install "
                         "'dfcoa-opt[ros]' (rosbags)") from None


def write_mcap(log: RunLog, path: str | Path, world: World | None = None) -> Path:
    """Write a run as a rosbag2 MCAP file that Foxglove and RViz 2 open (docs/ros.md).

    Needs the ``ros`` extra (``rosbags``). :meth:`dfcoa_opt.api.Run.to_mcap`
    calls it with the run's world.

    Args:
        log: The run.
        path: The ``.mcap`` file to write (replaced atomically).
        world: The run's :class:`~dfcoa_opt.scenario.scenario.World`
            (``Scenario.world``): gives ``/map`` and the static obstacles;
            without it the file has neither.

    Returns:
        ``path``.

    Raises:
        DfcoaError: ``rosbags`` is not installed, or the file cannot be written.
    """
    require_rosbags()
    try:
        from rosbags.interfaces import (
            Qos,
            QosDurability,
            QosHistory,
            QosLiveliness,
            QosReliability,
            QosTime,
        )
        from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer
        from rosbags.typesys import Stores, get_typestore
    except ImportError:  # pragma: no cover - require_rosbags() said so
        raise DfcoaError("rosbags is installed but incomplete") from None
    path = Path(path)
    tmp = path.parent / f".{path.name}.{os.getpid()}.bag"
    shutil.rmtree(tmp, ignore_errors=True)
    never = QosTime(0, 0)
    latched = Qos(QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL,
                  never, never, QosLiveliness.AUTOMATIC, never, False)
    once = {"/map", "/leader/path"}
    msgs = _Messages(get_typestore(getattr(Stores, ROS_DISTRO)))
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        w = Writer(tmp, version=Writer.VERSION_LATEST, storage_plugin=StoragePlugin.MCAP)
        w.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)  # zstd chunks
        with w:
            w.set_custom_data("dfcoa.meta", _meta_text(log))
            conns: dict[str, Any] = {}
            for topic, msgtype, t, msg in _messages(log, world, msgs):
                if topic not in conns:
                    qos = [latched] if topic in once else []
                    conns[topic] = w.add_connection(topic, msgtype, typestore=msgs.store,
                                                    offered_qos_profiles=qos)
                w.write(conns[topic], stamp_ns(t), msgs.store.serialize_cdr(msg, msgtype))
        os.replace(tmp / f"{tmp.name}.mcap", path)
    except OSError as exc:
        raise DfcoaError(f"{path}: cannot write the MCAP file: {exc}") from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return path


def _meta_text(log: RunLog) -> str:
    """The run's meta as one JSON line (the bag's custom data ``dfcoa.meta``)."""
    import json

    return json.dumps({k: v for k, v in log.meta.items() if k != "leader_path"}, default=str)


class _Messages:
    """Builds the ROS messages of one type store."""

    def __init__(self, store: Any) -> None:
        self.store = store
        self.t = store.types

    def stamp(self, t: float) -> Any:
        ns = stamp_ns(t)
        return self.t["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)

    def header(self, t: float, frame: str) -> Any:
        return self.t["std_msgs/msg/Header"](stamp=self.stamp(t), frame_id=frame)

    def quaternion(self, yaw: float) -> Any:
        return self.t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2.0),
                                                      w=math.cos(yaw / 2.0))

    def point(self, x: float, y: float, z: float = 0.0) -> Any:
        return self.t["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=float(z))

    def vector(self, x: float, y: float, z: float = 0.0) -> Any:
        return self.t["geometry_msgs/msg/Vector3"](x=float(x), y=float(y), z=float(z))

    def pose(self, x: float, y: float, yaw: float = 0.0, z: float = 0.0) -> Any:
        return self.t["geometry_msgs/msg/Pose"](position=self.point(x, y, z),
                                                orientation=self.quaternion(float(yaw)))

    def transform(self, t: float, frame: str, x: float, y: float, yaw: float) -> Any:
        tf = self.t["geometry_msgs/msg/Transform"](translation=self.vector(x, y),
                                                   rotation=self.quaternion(float(yaw)))
        return self.t["geometry_msgs/msg/TransformStamped"](
            header=self.header(t, MAP_FRAME), child_frame_id=frame, transform=tf)

    def odometry(self, t: float, i: int, pose: np.ndarray, vel_body: np.ndarray,
                 omega: float) -> Any:
        cov = np.zeros(36)
        twist = self.t["geometry_msgs/msg/Twist"](linear=self.vector(*vel_body),
                                                  angular=self.vector(0.0, 0.0, omega))
        return self.t["nav_msgs/msg/Odometry"](
            header=self.header(t, MAP_FRAME), child_frame_id=robot_frame(i),
            pose=self.t["geometry_msgs/msg/PoseWithCovariance"](pose=self.pose(*pose),
                                                                covariance=cov),
            twist=self.t["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=cov))

    def scan(self, t: float, i: int, ranges: np.ndarray, layout: dict[str, float]) -> Any:
        a0, da = layout["angle_min"], layout["angle_increment"]
        return self.t["sensor_msgs/msg/LaserScan"](
            header=self.header(t, robot_frame(i)), angle_min=a0,
            angle_max=a0 + da * (len(ranges) - 1), angle_increment=da, time_increment=0.0,
            scan_time=layout["scan_time"], range_min=layout["range_min"],
            range_max=layout["range_max"],
            ranges=np.asarray(ranges, dtype=np.float32), intensities=np.zeros(0, np.float32))

    def pose_stamped(self, t: float, x: float, y: float, yaw: float) -> Any:
        return self.t["geometry_msgs/msg/PoseStamped"](header=self.header(t, MAP_FRAME),
                                                       pose=self.pose(x, y, yaw))

    def marker(self, t: float, ns: str, i: int, kind: str, pose: Any, scale: tuple[float, ...],
               color: tuple[float, ...], points: list[Any] | None = None,
               lifetime: float = 0.0) -> Any:
        m, ns_life = self.t["visualization_msgs/msg/Marker"], stamp_ns(lifetime)
        return m(header=self.header(t, MAP_FRAME), ns=ns, id=i, type=getattr(m, kind),
                 action=m.ADD, pose=pose, scale=self.vector(*scale),
                 color=self.t["std_msgs/msg/ColorRGBA"](r=color[0], g=color[1], b=color[2],
                                                        a=color[3]),
                 lifetime=self.t["builtin_interfaces/msg/Duration"](
                     sec=ns_life // 10**9, nanosec=ns_life % 10**9),
                 frame_locked=False, points=points or [], colors=[], texture_resource="",
                 texture=self.t["sensor_msgs/msg/CompressedImage"](
                     header=self.header(t, ""), format="", data=np.zeros(0, np.uint8)),
                 uv_coordinates=[], text="", mesh_resource="",
                 mesh_file=self.t["visualization_msgs/msg/MeshFile"](
                     filename="", data=np.zeros(0, np.uint8)),
                 mesh_use_embedded_materials=False)

    def markers(self, items: list[Any]) -> Any:
        return self.t["visualization_msgs/msg/MarkerArray"](markers=items)

    def grid(self, t: float, occupied: np.ndarray, cell: float, origin: tuple[float, float]
             ) -> Any:
        rows, cols = occupied.shape
        info = self.t["nav_msgs/msg/MapMetaData"](
            map_load_time=self.stamp(t), resolution=cell, width=cols, height=rows,
            origin=self.pose(*origin))
        return self.t["nav_msgs/msg/OccupancyGrid"](
            header=self.header(t, MAP_FRAME), info=info,
            data=np.where(occupied, 100, 0).astype(np.int8).ravel())


def _messages(log: RunLog, world: World | None, msgs: _Messages
              ) -> Iterator[tuple[str, str, float, Any]]:
    """Every message of the file in time order: ``(topic, type, t, message)``."""
    from dfcoa_opt.metrics.contacts import contacts_at
    from dfcoa_opt.metrics.outcome import contact_steps, leader_path

    t0, n, dt = float(log.t[0]), log.n_robots, float(log.meta.get("dt", 0.0))
    if world is not None:
        g = world.grid
        yield ("/map", "nav_msgs/msg/OccupancyGrid", t0,
               msgs.grid(t0, np.asarray(g.occupied), g.cell_size, g.origin))
    path = leader_path(log)
    yield ("/leader/path", "nav_msgs/msg/Path", t0, msgs.t["nav_msgs/msg/Path"](
        header=msgs.header(t0, MAP_FRAME),
        poses=[msgs.pose_stamped(t0, x, y, 0.0) for x, y in path]))
    if world is not None and world.shapes:
        yield ("/obstacles", "visualization_msgs/msg/MarkerArray", t0,
               msgs.markers([_shape_marker(msgs, t0, j, s) for j, s in enumerate(world.shapes)]))
    layout = log.meta.get("scan")
    hits = contact_steps(log)
    grid = world.grid if world is not None else None
    for k, t in enumerate(map(float, log.t)):
        pose, vel = log.pose[k], log.velocity[k]
        yield ("/tf", "tf2_msgs/msg/TFMessage", t, msgs.t["tf2_msgs/msg/TFMessage"](
            transforms=[msgs.transform(t, robot_frame(i), *pose[i]) for i in range(n)]))
        c, s = np.cos(pose[:, 2]), np.sin(pose[:, 2])
        body = np.column_stack((c * vel[:, 0] + s * vel[:, 1], -s * vel[:, 0] + c * vel[:, 1]))
        for i in range(n):
            yield (f"/robot_{i}/odom", "nav_msgs/msg/Odometry", t,
                   msgs.odometry(t, i, pose[i], body[i], float(log.twist[k, i, 1])))
            if log.scan is not None and layout is not None:
                yield (f"/robot_{i}/scan", "sensor_msgs/msg/LaserScan", t,
                       msgs.scan(t, i, log.scan[k, i], layout))
        lx, ly, lth = map(float, log.leader[k, :3])
        yield ("/leader/pose", "geometry_msgs/msg/PoseStamped", t,
               msgs.pose_stamped(t, lx, ly, lth))
        yield ("/formation/slots", "geometry_msgs/msg/PoseArray", t,
               msgs.t["geometry_msgs/msg/PoseArray"](
                   header=msgs.header(t, MAP_FRAME),
                   poses=[msgs.pose(x, y, lth) for x, y in log.slots[k]]))
        if len(log.dyn_radius):
            yield ("/obstacles", "visualization_msgs/msg/MarkerArray", t, msgs.markers([
                msgs.marker(t, "moving", j, "CYLINDER", msgs.pose(x, y, 0.0, _HEIGHT / 2),
                            (2 * r, 2 * r, _HEIGHT), _ORANGE, lifetime=2 * dt)
                for j, ((x, y), r) in enumerate(zip(log.dyn_pos[k], log.dyn_radius,
                                                     strict=True))]))
        if hits[k]:
            found = contacts_at(log, k, grid)
            yield ("/contacts", "visualization_msgs/msg/MarkerArray", t, msgs.markers([
                msgs.marker(t, c.kind, j, "SPHERE", msgs.pose(*c.point), (0.15, 0.15, 0.15),
                            _RED, lifetime=dt) for j, c in enumerate(found)]))


def _shape_marker(msgs: _Messages, t: float, j: int, shape: Any) -> Any:
    """A static shape as a marker: a cylinder (circle) or a closed outline (polygon)."""
    from dfcoa_opt.world.shapes import Circle

    if isinstance(shape, Circle):
        r = shape.radius
        return msgs.marker(t, "static", j, "CYLINDER", msgs.pose(*shape.center, 0.0, _HEIGHT / 2),
                           (2 * r, 2 * r, _HEIGHT), _GREY)
    v = shape.to_polygon().as_array()
    pts = [msgs.point(x, y) for x, y in np.vstack((v, v[:1]))]
    return msgs.marker(t, "static", j, "LINE_STRIP", msgs.pose(0.0, 0.0), (0.05, 0.0, 0.0), _GREY,
                       points=pts)


def foxglove_layout(n: int) -> dict[str, Any]:
    """A Foxglove layout for the files of runs of up to ``n`` robots (docs/ros.md).

    A 3D panel in the ``map`` frame shows the map, the robots' frames and
    scans, the slots, the leader's path and pose, the obstacles and the
    contacts; a plot beside it shows each robot's forward speed (``odom``).

    Args:
        n: Robots whose topics the layout names.

    Returns:
        The layout as JSON-ready data (Foxglove: Layouts -> Import from file).
    """
    scene = {"/map": {"visible": True, "colorMode": "map"},
             "/leader/path": {"visible": True, "lineWidth": 0.05, "gradient": ["#2a9d8fff"] * 2},
             "/leader/pose": {"visible": True, "type": "arrow", "arrowScale": [0.6, 0.12, 0.12],
                              "color": "#2a9d8fff"},
             "/formation/slots": {"visible": True, "type": "arrow",
                                  "arrowScale": [0.3, 0.06, 0.06], "color": "#e9c46aff"},
             "/obstacles": {"visible": True}, "/contacts": {"visible": True}}
    scene.update({f"/robot_{i}/scan": {"visible": True, "colorMode": "flat",
                                       "flatColor": "#d1495bff", "pointSize": 3}
                  for i in range(n)})
    three_d = {"cameraState": {"perspective": False, "distance": 30.0, "phi": 0.0,
                               "thetaOffset": 90.0, "target": [0, 0, 0],
                               "targetOffset": [0, 0, 0], "targetOrientation": [0, 0, 0, 1],
                               "fovy": 45, "near": 0.5, "far": 5000},
               "followMode": "follow-none", "followTf": MAP_FRAME,
               "scene": {"transforms": {"showLabel": True, "axisScale": 0.4}},
               "transforms": {f"frame:{robot_frame(i)}": {"visible": True} for i in range(n)},
               "topics": scene, "layers": {}, "publish": {"type": "point"}}
    plot = {"title": "forward speed (m/s)",
            "paths": [{"value": f"/robot_{i}/odom.twist.twist.linear.x", "enabled": True,
                       "timestampMethod": "headerStamp", "label": f"robot {i}"}
                      for i in range(n)],
            "showLegend": True, "xAxisVal": "timestamp", "isSynced": True}
    return {"configById": {"3D!dfcoa": three_d, "Plot!dfcoa": plot},
            "globalVariables": {}, "userNodes": {}, "playbackConfig": {"speed": 1.0},
            "layout": {"direction": "row", "first": "3D!dfcoa", "second": "Plot!dfcoa",
                       "splitPercentage": 72}}
