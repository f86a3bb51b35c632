"""ROS 2 bags (MCAP or SQLite3 storage, a bag directory or a bare ``.mcap`` / ``.db3`` file) through
``rosbags`` (the ``logs`` extra; no ROS install needed): a streaming reader of
``sensor_msgs/msg/JointState`` and a writer of the messages an episode export needs.

Reading: module ``m``'s steering angle is the ``position`` of joint ``steer_joint.format(module=m)``
and its wheel spin rate φ̇ [rad/s] the ``velocity`` of joint ``drive_joint.format(module=m)`` (the
robot file's module names; joints are found by name in each message, so their order may change and
other joints may be present). Each message's time is its ``header.stamp`` (``time="header"``, the
default) or the time the bag recorded it (``time="log"``). A reference pose may come from a
``nav_msgs/msg/Odometry``, ``geometry_msgs/msg/PoseStamped`` or ``PoseWithCovarianceStamped``
topic (x, y and the yaw of the orientation), a gyro heading (``yaw_topic``) from a
``sensor_msgs/msg/Imu`` or one of those (:mod:`estimation.logs.ros_poses`).

When most messages hold every robot joint, each message is a sample (one that lacks a joint is
skipped and counted), streamed a chunk at a time. Otherwise (the joints come in groups, in separate
messages, on one topic or several) the groups are merged onto one clock by sample-and-hold, with a
maximum age ``max_age_s`` (:mod:`estimation.logs.ros_merge`).

Tested with rosbags 0.11 (``Writer(path, version=9, storage_plugin=...)``; bare files need 0.11).
"""

from __future__ import annotations

import heapq
import json
import math
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from estimation.geometry import RobotGeometry
from estimation.logs.hold import DEFAULT_MAX_AGE_S
from estimation.logs.ros_cdr import JointStateBatcher
from estimation.logs.ros_merge import check_signals, merged_chunks, scan_joints
from estimation.logs.ros_poses import (
                                       IMU,
                                       TRUTH_TYPES,
                                       YAW_TYPES,
                                       check_yaw_topic,
                                       read_poses,
                                       read_yaw,
                                       yaw_from_quaternion,
)
from estimation.logs.source import (
                                    BAD_MISSING_JOINT,
                                    BAD_NO_VELOCITY,
                                    STEER_CONVENTIONS,
                                    GroundTruth,
                                    LogError,
                                    LogSource,
                                    SampleChunk,
                                    YawTrack,
                                    beta_from_heading,
                                    fold_coaxial,
)

__all__ = ["RosLog", "BagWriter", "JOINT_STATE", "TRUTH_TYPES", "YAW_TYPES", "IMU", "yaw_from_quaternion",
           "TIME_SOURCES"]

JOINT_STATE = "sensor_msgs/msg/JointState"
#: where a message's time comes from: its header's stamp, or the time the bag logged it
TIME_SOURCES = ("header", "log")


def _rosbags():
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise LogError("reading ROS 2 bags needs the rosbags package: pip install 'azimut[logs]'") from None
    return AnyReader, get_typestore(Stores.ROS2_HUMBLE)


class RosLog(LogSource):
    """A ROS 2 bag's JointState topics as wheel samples (see the module docstring).

    ``topic``: the JointState topic, or a list of them (joint groups on several topics, merged);
    ``yaw_topic``: a heading for :meth:`yaw` (an Imu with orientation, or a pose topic);
    ``max_age_s``: the oldest a held joint value may be when groups are merged [s] (> 0; inf: no limit).
    After :meth:`chunks`, ``merged`` says whether groups were merged, ``clock_joint`` names the joint
    whose timestamps made the clock and ``stale_ticks`` counts the ticks marked stale.
    """

    format = "ROS 2 bag"

    def __init__(self, path, geom: RobotGeometry, modules, topic: str | Sequence[str] = "/joint_states",
                 steer_joint: str = "{module}_steer", drive_joint: str = "{module}_drive",
                 truth_topic: str | None = None, time: str = "header", steer_convention: str = "beta",
                 yaw_topic: str | None = None, max_age_s: float = DEFAULT_MAX_AGE_S) -> None:
        super().__init__(path, geom, modules)
        topics = (topic,) if isinstance(topic, str) else tuple(topic)
        if not topics or not all(isinstance(x, str) and x for x in topics) or len(set(topics)) != len(topics):
            raise ValueError(f"topic must be a topic name or a list of distinct topic names, got {topic!r}")
        if isinstance(max_age_s, bool) or not isinstance(max_age_s, (int, float)) or not max_age_s > 0:
            raise ValueError(f"max_age_s must be a number > 0 (inf: no limit), got {max_age_s!r}")
        if time not in TIME_SOURCES:
            raise ValueError(f"time must be one of {TIME_SOURCES}, got {time!r}")
        if steer_convention not in STEER_CONVENTIONS:
            raise ValueError(f"steer_convention must be one of {STEER_CONVENTIONS}, got {steer_convention!r}")
        for name, template in (("steer_joint", steer_joint), ("drive_joint", drive_joint)):
            if "{module}" not in template:
                raise ValueError(f"{name} must contain {{module}} (the module's name), got {template!r}")
        self.topics, self.topic = topics, ", ".join(topics)
        self.truth_topic, self.yaw_topic, self.time = truth_topic, yaw_topic, time
        self.steer_convention, self.max_age_s = steer_convention, float(max_age_s)
        # inf (no limit) or a huge age: a bound that clock - t cannot overflow against
        self.max_age_ns = round(min(self.max_age_s * 1e9, 2.0**62))
        self.steer_joints = [steer_joint.replace("{module}", m) for m in self.modules]
        self.drive_joints = [drive_joint.replace("{module}", m) for m in self.modules]
        if not Path(path).exists():
            raise self.error("no such file or directory")
        self._any_reader, self._typestore = _rosbags()
        with self._open() as reader:
            topics = {c.topic: c.msgtype for c in reader.connections}
            for t in self.topics:
                self._check_topic(topics, t, (JOINT_STATE,), "joint states")
            if truth_topic is not None:
                self._check_topic(topics, truth_topic, TRUTH_TYPES, "reference pose")
            if yaw_topic is not None:
                check_yaw_topic(self, reader, topics, yaw_topic)
            scan = scan_joints(self, reader, [c for c in reader.connections if c.topic in self.topics])
        if scan.n_messages == 0:
            raise self.error(f"topic {self.topic} holds no message")
        # most messages hold every joint: one sample per message; else joint groups, merged
        self.merged = len(self.topics) > 1 or 2 * scan.n_complete < scan.n_messages
        self.clock_joint: str | None = None
        self.stale_ticks = 0
        if self.merged:
            check_signals(self, scan)
            self.clock_joint = (self.steer_joints + self.drive_joints)[int(np.argmax(scan.counts))]
            self.n_samples = max(scan.counts)
        else:
            self.n_samples = scan.n_messages

    @contextmanager
    def _open(self):
        """The bag opened with rosbags' AnyReader; an error opening it -> LogError."""
        reader = self._any_reader([Path(self.path)], default_typestore=self._typestore)
        try:
            reader.open()
        except Exception as exc:  # noqa: BLE001 (rosbags and its storage raise many types: say it in one line)
            raise self.error(f"cannot be read as a ROS 2 bag ({type(exc).__name__}: {exc})") from None
        try:
            yield reader
        finally:
            reader.close()

    def _raw_messages(self, reader, conns) -> Iterator[tuple[object, int, bytes]]:
        """(connection, log time [ns], serialized message) of ``conns`` in the bag's time order; a
        storage error -> LogError."""
        it = reader.messages(connections=conns)
        while True:
            try:
                yield next(it)
            except StopIteration:
                return
            except Exception as exc:  # noqa: BLE001
                raise self.error(f"cannot be read to its end ({type(exc).__name__}: {exc}): a truncated or "
                                 "corrupt file?") from None

    def _deserialize(self, reader, conn, raw):
        return self._deserialize_type(reader, conn.msgtype, raw, conn.topic)

    def _deserialize_type(self, reader, msgtype: str, raw, topic: str | None = None):
        try:
            return reader.deserialize(raw, msgtype)
        except Exception as exc:  # noqa: BLE001
            raise self.error(f"a {topic or msgtype} message cannot be decoded ({type(exc).__name__}: {exc})") from None

    def _time(self, t_log: int, stamp_ns: int, topic: str) -> int:
        if self.time == "log":
            return int(t_log)
        if stamp_ns == 0:
            raise self.error(f"a {topic} message has no header stamp (0); pass time='log' (--time log) to use the "
                             "time the bag recorded it")
        return int(stamp_ns)

    def _check_topic(self, topics: dict, topic: str, types: tuple, what: str) -> None:
        if topic not in topics:
            raise self.error(f"no topic {topic} ({what}); the bag has: "
                             + (", ".join(f"{k} [{v}]" for k, v in sorted(topics.items())) or "no topic"))
        if topics[topic] not in types:
            raise self.error(f"topic {topic} holds {topics[topic]}, not {' or '.join(types)}")

    def _columns(self, names) -> tuple[list[int], list[int]]:
        """The indices of the modules' steering and drive joints in a message's ``names`` (-1: absent)."""
        index = {j: i for i, j in enumerate(names)}
        return [index.get(j, -1) for j in self.steer_joints], [index.get(j, -1) for j in self.drive_joints]

    def _batcher(self, reader) -> JointStateBatcher:
        """A batcher of the JointState fast path, each new layout checked against rosbags' decoding."""

        def same_values(raw, layout) -> bool:  # rosbags' decoding of a new layout's first message
            msg = self._deserialize_type(reader, JOINT_STATE, raw)
            t, pos, vel = JointStateBatcher.decode([raw], layout)
            stamp = int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)
            return (tuple(msg.name) == layout.names and int(t[0]) == stamp
                    and np.array_equal(msg.position, pos[0]) and np.array_equal(msg.velocity, vel[0]))

        return JointStateBatcher(same_values)

    def chunks(self, size: int) -> Iterator[SampleChunk]:
        if self.merged:
            yield from merged_chunks(self, size)
            return
        with self._open() as reader:
            conns = [c for c in reader.connections if c.topic in self.topics]
            batcher = self._batcher(reader)
            fill = _Fill(self, size)
            for conn, t_log, raw in self._raw_messages(reader, conns):
                layout = batcher.layout_of(raw)
                if layout is not None:
                    fill.add_raw(t_log, raw, layout)
                else:
                    fill.add_message(t_log, self._deserialize(reader, conn, raw))
                if fill.count == size:
                    yield fill.flush()
            if fill.count:
                yield fill.flush()

    def ground_truth(self) -> GroundTruth | None:
        if self.truth_topic is None:
            return None
        with self._open() as reader:
            return read_poses(self, reader, self.truth_topic)

    def yaw(self) -> YawTrack | None:
        if self.yaw_topic is None:
            return None
        with self._open() as reader:
            return read_yaw(self, reader, self.yaw_topic)

    def describe(self) -> dict:
        return {"format": self.format, "path": self.path,
                "topic": self.topics[0] if len(self.topics) == 1 else list(self.topics), "time": self.time,
                "steer_joints": self.steer_joints, "drive_joints": self.drive_joints,
                "truth_topic": self.truth_topic, "yaw_topic": self.yaw_topic, "steer_convention": self.steer_convention,
                "merged": self.merged, "clock_joint": self.clock_joint, "max_age_s": self.max_age_s,
                "stale_ticks": self.stale_ticks}


class _Fill:
    """One chunk of JointState samples being filled: messages decoded by rosbags go in at once,
    those of a known layout (:mod:`estimation.logs.ros_cdr`) are decoded together at the flush."""

    def __init__(self, log: RosLog, size: int) -> None:
        self.log, self.size = log, size
        self._reset()

    def _reset(self) -> None:
        n = self.log.geom.n
        self.t_log = np.empty(self.size, np.int64)
        self.stamp = np.zeros(self.size, np.int64)
        self.q = np.full((self.size, n), np.nan)
        self.w = np.full((self.size, n), np.nan)
        self.bad = np.zeros(self.size, np.int8)
        self.groups: dict = {}
        self.count = 0

    def _put(self, rows, names, pos, vel) -> None:
        """Positions and velocities (m, J) of messages with joint ``names`` into ``rows``."""
        steer, drive = self.log._columns(names)
        if min(steer + drive, default=0) < 0 or pos.shape[1] != len(names):
            self.bad[rows] = BAD_MISSING_JOINT
        elif vel.shape[1] != len(names):
            self.bad[rows] = BAD_NO_VELOCITY
        else:
            self.q[rows] = pos[:, steer]
            self.w[rows] = vel[:, drive]

    def add_message(self, t_log: int, msg) -> None:
        k = self.count
        self.t_log[k] = t_log
        self.stamp[k] = int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)
        self._put([k], list(msg.name), np.asarray(msg.position)[None], np.asarray(msg.velocity)[None])
        self.count += 1

    def add_raw(self, t_log: int, raw: bytes, layout) -> None:
        k = self.count
        self.t_log[k] = t_log
        rows, raws = self.groups.setdefault(layout, ([], []))
        rows.append(k)
        raws.append(raw)
        self.count += 1

    def flush(self) -> SampleChunk:
        for layout, (rows, raws) in self.groups.items():
            stamp, pos, vel = JointStateBatcher.decode(raws, layout)
            self.stamp[rows] = stamp
            self._put(rows, list(layout.names), pos, vel)
        m = self.count
        if self.log.time == "header":
            zero = np.flatnonzero(self.stamp[:m] == 0)
            if zero.size:
                self.log._time(0, 0, self.log.topic)  # refuses the log
            t = self.stamp[:m].copy()
        else:
            t = self.t_log[:m].copy()
        q = self.q[:m]
        if self.log.steer_convention == "heading":
            q = beta_from_heading(q, self.log.geom)
        beta, phidot = fold_coaxial(q, self.w[:m], self.log.geom)
        chunk = SampleChunk(t, beta, phidot, self.bad[:m].copy())
        self._reset()
        return chunk


class BagWriter:
    """A ROS 2 bag (MCAP by default, which Foxglove opens; or SQLite3) of the messages an episode
    export writes. Each ``add_*`` queues one series (several may share a topic, as joint groups
    do); :meth:`close` writes them all merged in time order. Times are int nanoseconds; each
    message's header stamp equals its log time."""

    def __init__(self, path, storage: str = "mcap") -> None:
        try:
            from rosbags.rosbag2 import StoragePlugin, Writer
            from rosbags.typesys import Stores, get_typestore
        except ImportError:
            raise LogError("writing ROS 2 bags needs the rosbags package: pip install 'azimut[logs]'") from None
        if storage not in ("mcap", "sqlite3"):
            raise ValueError(f"storage must be 'mcap' or 'sqlite3', got {storage!r}")
        self.path = Path(path)
        if self.path.exists():
            raise ValueError(f"{self.path} exists already (a bag is a new directory)")
        self.ts = get_typestore(Stores.ROS2_HUMBLE)
        plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
        self._writer = Writer(self.path, version=9, storage_plugin=plugin)
        self._series: list = []

    def _type(self, name: str):
        return self.ts.types[name]

    def _header(self, t: int, frame: str):
        return self._type("std_msgs/msg/Header")(
            stamp=self._type("builtin_interfaces/msg/Time")(sec=t // 1_000_000_000, nanosec=t % 1_000_000_000),
            frame_id=frame)

    def _quaternion(self, theta: float):
        return self._type("geometry_msgs/msg/Quaternion")(x=0.0, y=0.0, z=math.sin(theta / 2), w=math.cos(theta / 2))

    def _pose(self, p):
        return self._type("geometry_msgs/msg/Pose")(
            position=self._type("geometry_msgs/msg/Point")(x=float(p[0]), y=float(p[1]), z=0.0),
            orientation=self._quaternion(float(p[2])))

    def _vector(self, v):
        return self._type("geometry_msgs/msg/Vector3")(x=float(v[0]), y=float(v[1]), z=float(v[2]))

    def _add(self, topic: str, msgtype: str, t_ns, make) -> None:
        t_ns = np.asarray(t_ns, dtype=np.int64)
        self._series.append((topic, msgtype, t_ns, make))

    def add_joint_states(self, topic: str, t_ns, names, position, velocity, frame: str = "") -> None:
        """JointState messages: ``names`` (J,), ``position`` and ``velocity`` (T, J) (NaN allowed)."""
        cls = self._type(JOINT_STATE)
        pos = np.ascontiguousarray(position, dtype=np.float64)
        vel = np.ascontiguousarray(velocity, dtype=np.float64)
        names = list(names)
        self._add(topic, JOINT_STATE, t_ns, lambda i, t: cls(header=self._header(t, frame), name=names,
                                                             position=pos[i].copy(), velocity=vel[i].copy(),
                                                             effort=np.zeros(0)))

    def add_odometry(self, topic: str, t_ns, pose, twist, frame: str = "odom", child: str = "base_link") -> None:
        """nav_msgs/Odometry: ``pose`` (T, 3) (x, y, θ) in ``frame``, ``twist`` (T, 3) (ẋ, ẏ, θ̇) in ``child``."""
        cls = self._type("nav_msgs/msg/Odometry")
        pwc = self._type("geometry_msgs/msg/PoseWithCovariance")
        twc = self._type("geometry_msgs/msg/TwistWithCovariance")
        tw = self._type("geometry_msgs/msg/Twist")
        self._add(topic, "nav_msgs/msg/Odometry", t_ns, lambda i, t: cls(
            header=self._header(t, frame), child_frame_id=child,
            pose=pwc(pose=self._pose(pose[i]), covariance=np.zeros(36)),
            twist=twc(twist=tw(linear=self._vector((twist[i][0], twist[i][1], 0.0)),
                               angular=self._vector((0.0, 0.0, twist[i][2]))), covariance=np.zeros(36))))

    def add_pose_stamped(self, topic: str, t_ns, pose, frame: str = "world") -> None:
        """geometry_msgs/PoseStamped: ``pose`` (T, 3) (x, y, θ)."""
        cls = self._type("geometry_msgs/msg/PoseStamped")
        self._add(topic, "geometry_msgs/msg/PoseStamped", t_ns,
                  lambda i, t: cls(header=self._header(t, frame), pose=self._pose(pose[i])))

    def add_imu(self, topic: str, t_ns, yaw, yaw_rate=None, frame: str = "imu_link") -> None:
        """sensor_msgs/Imu: orientation of heading ``yaw`` (T,) [rad] (None: no orientation, all zeros with
        orientation_covariance[0] = -1 as ROS marks it), angular velocity z ``yaw_rate`` (T,) (default 0)."""
        cls, quat = self._type(IMU), self._type("geometry_msgs/msg/Quaternion")
        n = len(np.asarray(t_ns))
        rate = np.zeros(n) if yaw_rate is None else np.asarray(yaw_rate, dtype=np.float64)
        cov = np.zeros(9)
        if yaw is None:
            cov[0] = -1.0

        def make(i, t):
            q = quat(x=0.0, y=0.0, z=0.0, w=0.0) if yaw is None else self._quaternion(float(yaw[i]))
            return cls(header=self._header(t, frame), orientation=q, orientation_covariance=cov.copy(),
                       angular_velocity=self._vector((0.0, 0.0, rate[i])), angular_velocity_covariance=np.zeros(9),
                       linear_acceleration=self._vector((0.0, 0.0, 0.0)), linear_acceleration_covariance=np.zeros(9))

        self._add(topic, IMU, t_ns, make)

    def add_vector3_stamped(self, topic: str, t_ns, vec, frame: str = "base_link") -> None:
        """geometry_msgs/Vector3Stamped: ``vec`` (T, 3)."""
        cls = self._type("geometry_msgs/msg/Vector3Stamped")
        self._add(topic, "geometry_msgs/msg/Vector3Stamped", t_ns,
                  lambda i, t: cls(header=self._header(t, frame), vector=self._vector(vec[i])))

    def add_twist_stamped(self, topic: str, t_ns, twist, frame: str = "base_link") -> None:
        """geometry_msgs/TwistStamped: ``twist`` (T, 3) (ẋ, ẏ, θ̇)."""
        cls, tw = self._type("geometry_msgs/msg/TwistStamped"), self._type("geometry_msgs/msg/Twist")
        self._add(topic, "geometry_msgs/msg/TwistStamped", t_ns, lambda i, t: cls(
            header=self._header(t, frame), twist=tw(linear=self._vector((twist[i][0], twist[i][1], 0.0)),
                                                    angular=self._vector((0.0, 0.0, twist[i][2])))))

    def add_transforms(self, topic: str, t_ns, pose, parent: str = "world", child: str = "base_link") -> None:
        """tf2_msgs/TFMessage with one parent -> child transform per message: ``pose`` (T, 3)."""
        cls, tfs = self._type("tf2_msgs/msg/TFMessage"), self._type("geometry_msgs/msg/TransformStamped")
        tr = self._type("geometry_msgs/msg/Transform")
        self._add(topic, "tf2_msgs/msg/TFMessage", t_ns, lambda i, t: cls(transforms=[tfs(
            header=self._header(t, parent), child_frame_id=child,
            transform=tr(translation=self._vector((pose[i][0], pose[i][1], 0.0)),
                         rotation=self._quaternion(float(pose[i][2]))))]))

    def set_custom_data(self, key: str, value: str) -> None:
        """A string entry of the bag's ``metadata.yaml`` (rosbag2's ``custom_data``)."""
        self._writer.set_custom_data(key, str(value))

    def close(self) -> None:
        """Write every queued series, merged in time order, and close the bag."""
        w = self._writer
        w.open()
        try:
            conns: dict = {}  # series on one topic (joint groups) share its connection
            for topic, msgtype, _, _ in self._series:
                if (topic, msgtype) not in conns:
                    conns[topic, msgtype] = w.add_connection(topic, msgtype, typestore=self.ts)
            streams = [_stream(order, conns[topic, msgtype], msgtype, t_ns, make)
                       for order, (topic, msgtype, t_ns, make) in enumerate(self._series)]
            for t, _, i, conn, msgtype, make in heapq.merge(*streams):
                w.write(conn, t, self.ts.serialize_cdr(make(i, t), msgtype))
        finally:
            w.close()


def _stream(order: int, conn, msgtype: str, t_ns: np.ndarray, make) -> Iterator[tuple]:
    """One series' messages as (time, series order, index, connection, type, maker), in its order."""
    for i, t in enumerate(t_ns.tolist()):
        yield t, order, i, conn, msgtype, make


#: the ``custom_data`` keys of an ``azimut eval --export`` bag: the robot's name (a preset) or
#: file path, and its geometry as JSON (n, alpha, l, b)
ROBOT_KEY, GEOMETRY_KEY = "azimut.robot", "azimut.geometry"


def recorded_robot(path) -> tuple[str, dict] | None:
    """(robot, geometry) an ``azimut eval --export`` bag folder records in its ``metadata.yaml``,
    or None (another bag, a bare storage file, no such entries)."""
    meta = Path(path) / "metadata.yaml"
    if not meta.is_file():
        return None
    try:
        from ruamel.yaml import YAML

        data = YAML(typ="safe").load(meta.read_text())
        custom = data["rosbag2_bagfile_information"].get("custom_data") or {}
        return str(custom[ROBOT_KEY]), json.loads(custom[GEOMETRY_KEY])
    except (ImportError, OSError, ValueError, KeyError, TypeError, AttributeError):
        return None
