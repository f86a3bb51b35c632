"""A fast path for ``sensor_msgs/msg/JointState``: its stamp, positions and velocities read from the
serialized bytes by NumPy, a whole chunk at once, instead of one ``rosbags`` deserialization per
message (which dominates the reading of a long bag).

A JointState in little-endian CDR (OMG, "Extensible and Dynamic Topic Types for DDS" 1.3, 2020,
§7.4.3, the encoding ROS 2 bags store, after a 4-byte encapsulation header ``00 01 00 00``) is::

    int32 sec, uint32 nanosec | string frame_id | string[] name | float64[] position, velocity, effort

(a string is a uint32 length, counting its NUL, then its bytes; a sequence a uint32 count, then
its elements; each value aligned to its size from the start of the data). Every message whose bytes
up to its ``position`` count equal a known layout's has that layout's offsets. A layout is accepted
only once ``rosbags`` decodes its first message to the same values; anything else (another
encapsulation, a mismatch) is decoded by ``rosbags``, message by message.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

__all__ = ["JointStateLayout", "parse_layout", "JointStateBatcher", "POSE_STRINGS", "pose_offset", "decode_poses"]

_U32 = struct.Struct("<I")
_DATA = 4  # the CDR data starts after the encapsulation header


def _align(p: int, a: int) -> int:
    return _DATA + ((p - _DATA + a - 1) // a) * a


@dataclass(frozen=True)
class JointStateLayout:
    """Where the values of one JointState layout lie: ``key`` the bytes from the frame id to the
    position count (inclusive), the message's byte length, the names, and the offset and count
    of the positions and the velocities."""

    key: bytes
    length: int
    names: tuple[str, ...]
    pos_off: int
    n_pos: int
    vel_count_off: int
    vel_off: int
    n_vel: int


def parse_layout(raw: bytes) -> JointStateLayout | None:
    """The layout of one serialized JointState, or None if it is not little-endian CDR or its
    bytes do not parse."""
    raw = bytes(raw)
    if len(raw) < 24 or raw[:2] != b"\x00\x01":
        return None
    try:
        p = _DATA + 8
        (n,) = _U32.unpack_from(raw, p)
        p += 4 + n
        p = _align(p, 4)
        (count,) = _U32.unpack_from(raw, p)
        p += 4
        names = []
        for _ in range(count):
            p = _align(p, 4)
            (n,) = _U32.unpack_from(raw, p)
            names.append(raw[p + 4:p + 3 + n].decode())
            p += 4 + n
        p = _align(p, 4)
        (n_pos,) = _U32.unpack_from(raw, p)
        key_end = p + 4
        p = _align(key_end, 8) if n_pos else key_end
        pos_off = p
        p = _align(p + 8 * n_pos, 4)
        vel_count_off = p
        (n_vel,) = _U32.unpack_from(raw, p)
        p += 4
        p = _align(p, 8) if n_vel else p
        vel_off = p
        if vel_off + 8 * n_vel > len(raw):
            return None
    except (struct.error, UnicodeDecodeError):
        return None
    return JointStateLayout(bytes(raw[_DATA + 8:key_end]), len(raw), tuple(names), pos_off, n_pos, vel_count_off,
                            vel_off, n_vel)


class JointStateBatcher:
    """Collects serialized JointStates of known layouts and decodes them a batch at a time.

    ``check(raw, layout) -> bool``: whether ``rosbags`` decodes ``raw`` to the values this module
    reads with ``layout`` (called once per new layout). :meth:`layout_of` returns a message's
    accepted layout, or None (then the caller decodes it another way)."""

    #: how many recently seen layouts are tried before a message is parsed (joint groups published
    #: in separate messages alternate between a few layouts)
    RECENT = 4

    def __init__(self, check) -> None:
        self._check = check
        self._layouts: dict[tuple, JointStateLayout | None] = {}
        self._recent: list[JointStateLayout] = []

    def layout_of(self, raw: bytes) -> JointStateLayout | None:
        for last in self._recent:
            if (len(raw) == last.length and raw[_DATA + 8:_DATA + 8 + len(last.key)] == last.key
                    and _U32.unpack_from(raw, last.vel_count_off)[0] == last.n_vel):
                return last
        layout = parse_layout(raw)
        if layout is None:
            return None
        ident = (layout.key, layout.n_vel, layout.length)
        if ident not in self._layouts:
            self._layouts[ident] = layout if self._check(raw, layout) else None
        accepted = self._layouts[ident]
        if accepted is not None:
            self._recent = [accepted] + [r for r in self._recent if r is not accepted][:self.RECENT - 1]
        return accepted

    @staticmethod
    def decode(raws: list[bytes], layout: JointStateLayout) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(stamp [ns] (m,), positions (m, n_pos), velocities (m, n_vel)) of messages of one layout."""
        buf = np.frombuffer(b"".join(raws), dtype=np.uint8).reshape(len(raws), layout.length)
        sec = np.ascontiguousarray(buf[:, _DATA:_DATA + 4]).view("<i4")[:, 0].astype(np.int64)
        nsec = np.ascontiguousarray(buf[:, _DATA + 4:_DATA + 8]).view("<u4")[:, 0].astype(np.int64)
        pos = np.ascontiguousarray(buf[:, layout.pos_off:layout.pos_off + 8 * layout.n_pos]).view("<f8")
        vel = np.ascontiguousarray(buf[:, layout.vel_off:layout.vel_off + 8 * layout.n_vel]).view("<f8")
        return sec * 1_000_000_000 + nsec, pos, vel


#: the strings before the pose in a reference-pose message: the header's frame id, and an
#: Odometry's child frame id; the pose (Point x, y, z; Quaternion x, y, z, w: 7 float64) comes next.
#: An Imu's header is followed by its orientation (Quaternion) and orientation covariance (float64[9])
POSE_STRINGS = {"nav_msgs/msg/Odometry": 2, "geometry_msgs/msg/PoseStamped": 1,
                "geometry_msgs/msg/PoseWithCovarianceStamped": 1, "sensor_msgs/msg/Imu": 1}


def pose_offset(raw: bytes, strings: int) -> tuple[bytes, int] | None:
    """(the bytes of the strings before the pose, the pose's offset) of a little-endian CDR message
    whose header (stamp, frame id) and ``strings − 1`` more strings precede a Pose; None if it is
    not little-endian CDR or too short."""
    raw = bytes(raw)
    if len(raw) < 24 or raw[:2] != b"\x00\x01":
        return None
    p = _DATA + 8
    try:
        for _ in range(strings):
            p = _align(p, 4)
            (n,) = _U32.unpack_from(raw, p)
            p += 4 + n
    except struct.error:
        return None
    off = _align(p, 8)
    return (bytes(raw[_DATA + 8:p]), off) if off + 56 <= len(raw) else None


def decode_poses(raws: list[bytes], length: int, off: int, count: int = 7) -> tuple[np.ndarray, np.ndarray]:
    """(stamp [ns] (m,), (m, count) float64 values from ``off``) of messages of one layout: a pose's
    x, y, z, qx, qy, qz, qw (the default); an Imu's qx, qy, qz, qw and orientation covariance
    (``count`` 5 reads its first element)."""
    buf = np.frombuffer(b"".join(raws), dtype=np.uint8).reshape(len(raws), length)
    sec = np.ascontiguousarray(buf[:, _DATA:_DATA + 4]).view("<i4")[:, 0].astype(np.int64)
    nsec = np.ascontiguousarray(buf[:, _DATA + 4:_DATA + 8]).view("<u4")[:, 0].astype(np.int64)
    return sec * 1_000_000_000 + nsec, np.ascontiguousarray(buf[:, off:off + 8 * count]).view("<f8")
