"""The JointState / pose fast path reads what rosbags deserializes, and the ROS reader falls back
to rosbags (or marks the sample) wherever a message departs from the layout."""

from __future__ import annotations

import numpy as np
import pytest
from logs_data import MODULES4, motion

from estimation.logs import estimate_log, open_log

rosbags = pytest.importorskip("rosbags")

from rosbags.rosbag2 import Writer  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402

from estimation.logs.ros_cdr import JointStateBatcher, decode_poses, parse_layout, pose_offset  # noqa: E402

TS = get_typestore(Stores.ROS2_HUMBLE)
JS, H, T = (TS.types[n] for n in ("sensor_msgs/msg/JointState", "std_msgs/msg/Header", "builtin_interfaces/msg/Time"))


def _js(t, frame, names, pos, vel, effort=()):
    return TS.serialize_cdr(JS(header=H(stamp=T(sec=t // 10**9, nanosec=t % 10**9), frame_id=frame), name=list(names),
                               position=np.asarray(pos, float), velocity=np.asarray(vel, float),
                               effort=np.asarray(effort, float)), JS.__msgtype__)


def test_layout_reads_what_rosbags_deserializes():
    rng = np.random.default_rng(0)
    for _ in range(200):
        j = int(rng.integers(0, 6))
        names = ["j" * int(rng.integers(1, 9)) + str(i) for i in range(j)]
        n_pos, n_vel = (j if rng.random() < 0.8 else 0), (j if rng.random() < 0.8 else 0)
        t = int(rng.integers(1, 2**31 * 10**9))
        raw = _js(t, "f" * int(rng.integers(0, 7)), names, rng.normal(size=n_pos), rng.normal(size=n_vel),
                  rng.normal(size=int(rng.integers(0, 3))))
        layout = parse_layout(raw)
        msg = TS.deserialize_cdr(raw, JS.__msgtype__)
        stamp, pos, vel = JointStateBatcher.decode([raw], layout)
        assert layout.names == tuple(msg.name) and int(stamp[0]) == msg.header.stamp.sec * 10**9 + \
            msg.header.stamp.nanosec
        assert np.array_equal(pos[0], msg.position) and np.array_equal(vel[0], msg.velocity)
    assert parse_layout(b"\x00\x00\x00\x00" + bytes(40)) is None  # big-endian CDR: rosbags decodes it


def test_pose_offset_reads_what_rosbags_deserializes():
    PS, P, Pt, Q = (TS.types[n] for n in ("geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/Pose",
                                          "geometry_msgs/msg/Point", "geometry_msgs/msg/Quaternion"))
    for frame in ("", "w", "world", "map_frame"):
        msg = PS(header=H(stamp=T(sec=3, nanosec=9), frame_id=frame),
                 pose=P(position=Pt(x=1.5, y=-2.0, z=0.1), orientation=Q(x=0.1, y=0.2, z=0.3, w=0.9)))
        raw = TS.serialize_cdr(msg, PS.__msgtype__)
        _, off = pose_offset(raw, 1)
        stamp, values = decode_poses([raw], len(raw), off)
        assert int(stamp[0]) == 3 * 10**9 + 9 and values[0].tolist() == [1.5, -2.0, 0.1, 0.1, 0.2, 0.3, 0.9]


def test_mixed_bag_fast_path_and_fallbacks(tmp_path, geom):
    m = motion(geom, 60)
    steer = [f"{x}_steer" for x in MODULES4]
    drive = [f"{x}_drive" for x in MODULES4]
    PS, P, Pt, Q = (TS.types[n] for n in ("geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/Pose",
                                          "geometry_msgs/msg/Point", "geometry_msgs/msg/Quaternion"))
    bag = tmp_path / "bag"
    expect_bad = {}
    with Writer(bag, version=9) as w:  # SQLite3, the rosbag2 default
        c = w.add_connection("/joint_states", JS.__msgtype__, typestore=TS)
        cp = w.add_connection("/pose", PS.__msgtype__, typestore=TS)
        for k in range(60):
            t = 10**18 + int(m.t_ns[k])
            names, pos, vel = steer + drive, np.r_[m.beta[k], np.zeros(4)], np.r_[np.zeros(4), m.phidot[k]]
            frame = "base_link" if k < 30 else "b"  # a second layout half way
            if k == 10:
                vel = []  # no velocities
                expect_bad[k] = "the message has no wheel velocities"
            if k == 20:
                names, pos, vel = names[1:], pos[1:], vel[1:]  # a joint missing
                expect_bad[k] = "a module's steering or drive joint is missing from the message"
            if k == 40:
                order = [7, 0, 6, 1, 5, 2, 4, 3]  # another order: found by name
                names, pos, vel = [names[i] for i in order], pos[order], vel[order]
            w.write(c, t, _js(t, frame, names, pos, vel))
            w.write(cp, t, TS.serialize_cdr(PS(header=H(stamp=T(sec=t // 10**9, nanosec=t % 10**9), frame_id="map"),
                                               pose=P(position=Pt(x=m.pose[k, 0], y=m.pose[k, 1], z=0.0),
                                                      orientation=Q(x=0.0, y=0.0, z=np.sin(m.pose[k, 2] / 2),
                                                                    w=np.cos(m.pose[k, 2] / 2)))), PS.__msgtype__))
    r = estimate_log(open_log(bag, geom, MODULES4, truth_topic="/pose"), chunk_size=16)
    good = np.array([k not in expect_bad for k in range(60)])
    assert r.n_read == 60 and r.t_ns.size == 58
    assert r.skipped == {why: 1 for why in expect_bad.values()}
    assert np.array_equal(r.beta, m.beta[good]) and np.array_equal(r.phidot, m.phidot[good])
    assert np.array_equal(r.t_ns, 10**18 + m.t_ns[good])
    np.testing.assert_allclose(r.truth.pose[:, :2], m.pose[:, :2], rtol=0, atol=0)
    np.testing.assert_allclose(r.truth.pose[:, 2], m.pose[:, 2], atol=1e-12)
