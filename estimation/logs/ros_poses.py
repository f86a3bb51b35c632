"""Poses and headings from a ROS 2 bag: a reference pose (``nav_msgs/msg/Odometry``,
``geometry_msgs/msg/PoseStamped``, ``PoseWithCovarianceStamped``: x, y and the yaw of the
orientation) and a gyro's heading (the yaw of a ``sensor_msgs/msg/Imu``'s orientation, or of one
of those poses).

Each message's stamp and values are read from its serialized bytes a batch at a time
(:func:`~estimation.logs.ros_cdr.pose_offset`, :func:`~estimation.logs.ros_cdr.decode_poses`), a
new layout being accepted once ``rosbags`` decodes its first message to the same values; anything
else is decoded by ``rosbags``. The functions take the :class:`~estimation.logs.ros.RosLog` whose
bag they read (its ``time`` option, its error messages).
"""

from __future__ import annotations

import numpy as np

from estimation.libm import atan2
from estimation.logs.ros_cdr import POSE_STRINGS, decode_poses, pose_offset
from estimation.logs.source import GroundTruth, YawTrack

__all__ = ["TRUTH_TYPES", "IMU", "YAW_TYPES", "yaw_from_quaternion", "read_poses", "read_yaw", "check_yaw_topic"]

#: message types a reference pose may come from
TRUTH_TYPES = ("nav_msgs/msg/Odometry", "geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/PoseWithCovarianceStamped")
IMU = "sensor_msgs/msg/Imu"
#: message types a heading (``yaw_topic``) may come from
YAW_TYPES = (IMU,) + TRUTH_TYPES


def yaw_from_quaternion(x, y, z, w):
    """The rotation about z [rad] of unit quaternions (x, y, z, w) (arrays or floats):
    atan2(2(wz + xy), 1 − 2(y² + z²))."""
    return atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def _stamp_ns(msg) -> int:
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)


def _pose_values(msg) -> np.ndarray:
    """x, y, z, qx, qy, qz, qw of a reference-pose message (Odometry, Pose(WithCovariance)Stamped)."""
    pose = msg.pose.pose if hasattr(msg.pose, "pose") else msg.pose
    p, o = pose.position, pose.orientation
    return np.array([p.x, p.y, p.z, o.x, o.y, o.z, o.w], dtype=np.float64)


def _imu_values(msg) -> np.ndarray:
    """qx, qy, qz, qw and orientation_covariance[0] of an Imu."""
    o = msg.orientation
    return np.array([o.x, o.y, o.z, o.w, msg.orientation_covariance[0]], dtype=np.float64)


def _values_of(msgtype: str):
    return (_imu_values, 5) if msgtype == IMU else (_pose_values, 7)


def _read(log, reader, topic: str) -> tuple[str, np.ndarray, np.ndarray]:
    """(message type, times [ns] per ``log.time`` (m,), values (m, 7) or Imu's (m, 5)) of ``topic``,
    in the bag's order."""
    conns = [c for c in reader.connections if c.topic == topic]
    msgtype = conns[0].msgtype
    strings = POSE_STRINGS[msgtype]
    values_of, count = _values_of(msgtype)
    layouts: dict[tuple, bool] = {}
    t_all, rows_values, groups = [], [], {}
    for conn, t_log, raw in log._raw_messages(reader, conns):
        k = len(t_all)
        got = pose_offset(raw, strings)
        ident = None if got is None else (got[0], len(raw), got[1])
        if ident is not None and ident not in layouts:  # a new layout: rosbags must agree on its first message
            msg = log._deserialize(reader, conn, raw)
            stamp, values = decode_poses([raw], len(raw), got[1], count)
            layouts[ident] = bool(np.array_equal(values[0], values_of(msg), equal_nan=True)
                                  and stamp[0] == _stamp_ns(msg))
        if ident is not None and layouts[ident]:
            rows, raws = groups.setdefault(ident, ([], []))
            rows.append(k)
            raws.append(raw)
            t_all.append((t_log, 0))
            rows_values.append(None)
        else:
            msg = log._deserialize(reader, conn, raw)
            t_all.append((t_log, _stamp_ns(msg)))
            rows_values.append(values_of(msg))
    t_log = np.array([t for t, _ in t_all], dtype=np.int64).reshape(-1)
    stamp = np.array([s for _, s in t_all], dtype=np.int64).reshape(-1)
    values = np.zeros((len(rows_values), count))
    for k, v in enumerate(rows_values):
        if v is not None:
            values[k] = v
    for (_, length, off), (rows, raws) in groups.items():
        stamp[rows], values[rows] = decode_poses(raws, length, off, count)
    if log.time == "header":
        if np.any(stamp == 0):
            log._time(0, 0, topic)  # refuses the log
        return msgtype, stamp, values
    return msgtype, t_log, values


def read_poses(log, reader, topic: str) -> GroundTruth:
    """The reference pose of ``topic`` (one of :data:`TRUTH_TYPES`), in the bag's order."""
    _, t, values = _read(log, reader, topic)
    yaw = yaw_from_quaternion(values[:, 3], values[:, 4], values[:, 5], values[:, 6])
    return GroundTruth(t, np.column_stack([values[:, 0], values[:, 1], yaw]), f"topic {topic}")


def _no_orientation(values: np.ndarray) -> np.ndarray:
    """Imu rows (m, 5) without an orientation: all zeros, or covariance[0] = -1 (ROS's convention)."""
    return np.all(values[:, :4] == 0.0, axis=1) | (values[:, 4] == -1.0)


def _no_orientation_error(log, topic: str, what: str):
    return log.error(f"yaw topic {topic}: {what} no orientation (all zeros or orientation_covariance[0] = -1, ROS's "
                     "'not estimated'); name a topic with a heading (an Imu with orientation, an Odometry, a pose)")


def read_yaw(log, reader, topic: str) -> YawTrack:
    """The heading of ``topic`` (one of :data:`YAW_TYPES`): the yaw of each message's orientation, in
    time order (a repeated time keeps the bag's last message), unwrapped."""
    msgtype, t, values = _read(log, reader, topic)
    if msgtype == IMU:
        missing = _no_orientation(values)
        if missing.any():
            raise _no_orientation_error(log, topic, f"{int(missing.sum())} of its {missing.size} Imu messages have")
    q = values[:, 3:7] if msgtype != IMU else values[:, 0:4]
    yaw = yaw_from_quaternion(q[:, 0], q[:, 1], q[:, 2], q[:, 3])
    order = np.argsort(t, kind="stable")
    t, yaw = t[order], yaw[order]
    keep = np.r_[t[1:] != t[:-1], True] if t.size else np.zeros(0, bool)
    return YawTrack(t[keep], np.unwrap(yaw[keep]), f"topic {topic} ({msgtype})")


def check_yaw_topic(log, reader, topics: dict, topic: str) -> None:
    """Refuse (``LogError``) a yaw topic that is missing (listing the bag's topics of usable types), of
    another type, empty, or an Imu whose first message has no orientation."""
    if topic not in topics:
        usable = [f"{k} [{v}]" for k, v in sorted(topics.items()) if v in YAW_TYPES]
        raise log.error(f"no yaw topic {topic}; the bag's topics of a usable type ({', '.join(YAW_TYPES)}): "
                        + (", ".join(usable) or "none"))
    if topics[topic] not in YAW_TYPES:
        raise log.error(f"yaw topic {topic} holds {topics[topic]}, not {' or '.join(YAW_TYPES)}")
    conns = [c for c in reader.connections if c.topic == topic]
    first = next(log._raw_messages(reader, conns), None)
    if first is None:
        raise log.error(f"yaw topic {topic} holds no message")
    if topics[topic] == IMU:
        conn, _, raw = first
        if _no_orientation(_imu_values(log._deserialize(reader, conn, raw))[None]).any():
            raise _no_orientation_error(log, topic, "its first Imu message has")
