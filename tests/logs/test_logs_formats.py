"""Each format written by its own writer (rosbags' Writer, the mcap package's Writer, wpiutil's
DataLogWriter, the CSV writer), read back by estimation.logs, and estimated as estimate_eta
estimates the same arrays."""

from __future__ import annotations

import numpy as np
import pytest
from logs_data import MODULES4, heading_of, motion

from estimation import RobotGeometry, estimate_eta
from estimation.logs import detect_format, estimate_log, fold_coaxial, open_log
from estimation.logs.csv_log import write_csv_log

T0_NS = 1_700_000_000 * 10**9  # a Unix time, as ROS stamps are


def _check(result, beta, phidot, geom, methods=("IT", "IT+", "NE", "LS", "NS")):
    for method in methods:
        lam, mu, _, qua = estimate_eta(beta, phidot, geom, method)
        assert np.array_equal(result.lam[method], lam), method
        assert np.array_equal(result.mu[method], mu), method
        assert np.array_equal(result.qua[method], qua), method


# ---------------------------------------------------------------------------------------------- CSV


def test_csv_round_trip(tmp_path, geom):
    m = motion(geom, 150, noise=0.01)
    path = tmp_path / "log.csv"
    write_csv_log(path, m.t_s, m.beta, m.phidot, MODULES4, pose=m.pose)
    assert detect_format(path) == "csv"
    r = estimate_log(open_log(path, geom, MODULES4))
    _check(r, m.beta, m.phidot, geom)
    np.testing.assert_array_equal(r.truth.pose, m.pose)


def test_csv_columns_in_any_order_with_extra_columns_and_heading_convention(tmp_path):
    geom = RobotGeometry.regular(4, l=0.25, b=0.0, r=0.05)  # coaxial: headings fold exactly
    m = motion(geom, 80)
    heading = np.mod(heading_of(m.beta, geom) + np.pi, 2 * np.pi) - np.pi  # in ]-π, π] as most robots log it
    names = [f"module_{k}" for k in range(4)]
    cols = {"battery": np.full(80, 12.0), "t": m.t_s}
    for k in (2, 0, 3, 1):
        cols[f"wheel_{names[k]}"] = m.phidot[:, k]
        cols[f"steer_{names[k]}"] = heading[:, k]
    path = tmp_path / "log.csv"
    np.savetxt(path, np.column_stack(list(cols.values())), delimiter=",", header=",".join(cols), comments="# a\n",
               fmt="%.17g")
    src = open_log(path, geom, names, steer_convention="heading")
    assert src.ignored == ["battery"]
    r = estimate_log(src)
    beta, phidot = fold_coaxial(heading - geom.alpha + np.pi / 2, m.phidot, geom)
    _check(r, beta, phidot, geom)
    lam, mu, _, _ = estimate_eta(m.beta, m.phidot, geom)  # the same motion as the β convention gives
    np.testing.assert_allclose(r.lam["IT"], lam, atol=1e-9)
    np.testing.assert_allclose(r.mu["IT"], mu, atol=1e-9)


# ---------------------------------------------------------------------------------------- ROS 2 bags


def _ros():
    pytest.importorskip("rosbags")
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    return Writer, StoragePlugin, get_typestore(Stores.ROS2_HUMBLE)


def _joint_state(ts, t_ns, names, pos, vel):
    JS, H, T = (ts.types[n] for n in ("sensor_msgs/msg/JointState", "std_msgs/msg/Header",
                                      "builtin_interfaces/msg/Time"))
    msg = JS(header=H(stamp=T(sec=t_ns // 10**9, nanosec=t_ns % 10**9), frame_id="base_link"), name=list(names),
             position=np.asarray(pos, float), velocity=np.asarray(vel, float), effort=np.zeros(0))
    return ts.serialize_cdr(msg, JS.__msgtype__)


def _odometry(ts, t_ns, pose):
    O, H, T = (ts.types[n] for n in ("nav_msgs/msg/Odometry", "std_msgs/msg/Header", "builtin_interfaces/msg/Time"))
    P, PC, Q, Pt = (ts.types[n] for n in ("geometry_msgs/msg/Pose", "geometry_msgs/msg/PoseWithCovariance",
                                          "geometry_msgs/msg/Quaternion", "geometry_msgs/msg/Point"))
    TW, TC, V = (ts.types[n] for n in ("geometry_msgs/msg/Twist", "geometry_msgs/msg/TwistWithCovariance",
                                       "geometry_msgs/msg/Vector3"))
    msg = O(header=H(stamp=T(sec=t_ns // 10**9, nanosec=t_ns % 10**9), frame_id="odom"), child_frame_id="base_link",
            pose=PC(pose=P(position=Pt(x=pose[0], y=pose[1], z=0.0),
                           orientation=Q(x=0.0, y=0.0, z=np.sin(pose[2] / 2), w=np.cos(pose[2] / 2))),
                    covariance=np.zeros(36)),
            twist=TC(twist=TW(linear=V(x=0.0, y=0.0, z=0.0), angular=V(x=0.0, y=0.0, z=0.0)), covariance=np.zeros(36)))
    return ts.serialize_cdr(msg, O.__msgtype__)


@pytest.mark.parametrize("storage", ["MCAP", "SQLITE3"])
def test_ros_bag_round_trip(tmp_path, geom, storage):
    Writer, StoragePlugin, ts = _ros()
    m = motion(geom, 120, noise=0.01)
    rng = np.random.default_rng(5)
    joints = [f"{mod}_steer" for mod in MODULES4] + [f"{mod}_drive" for mod in MODULES4] + ["arm_joint"]
    bag = tmp_path / "bag"
    with Writer(bag, version=9, storage_plugin=getattr(StoragePlugin, storage)) as w:
        c = w.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=ts)
        c_odo = w.add_connection("/ground_truth", "nav_msgs/msg/Odometry", typestore=ts)
        for k in range(120):
            order = rng.permutation(len(joints))  # joints come in any order: they are found by name
            pos = np.r_[m.beta[k], np.full(4, 7.0), 0.5][order]
            vel = np.r_[np.zeros(4), m.phidot[k], 0.0][order]
            t = T0_NS + int(m.t_ns[k])
            w.write(c, t + 1000, _joint_state(ts, t, [joints[j] for j in order], pos, vel))  # logged 1 µs later
            if k % 2 == 0:
                w.write(c_odo, t + 1000, _odometry(ts, t, m.pose[k]))
    assert detect_format(bag) == "ros"
    src = open_log(bag, geom, MODULES4, truth_topic="/ground_truth")
    r = estimate_log(src, chunk_size=50)
    _check(r, m.beta, m.phidot, geom)
    assert np.array_equal(r.t_ns, T0_NS + m.t_ns)  # header stamps, not the log times
    np.testing.assert_allclose(r.truth.pose, m.pose[::2], atol=1e-12)
    r_log = estimate_log(open_log(bag, geom, MODULES4, time="log"))
    assert np.array_equal(r_log.t_ns, T0_NS + m.t_ns + 1000)


def test_bare_mcap_written_by_the_mcap_package(tmp_path, geom):
    _, _, ts = _ros()
    mcap_writer = pytest.importorskip("mcap.writer")
    m = motion(geom, 60, noise=0.01)
    joints = [f"{mod}_steer" for mod in MODULES4] + [f"{mod}_drive" for mod in MODULES4]
    path = tmp_path / "plain.mcap"
    msgdef, _ = ts.generate_msgdef("sensor_msgs/msg/JointState", ros_version=2)
    with open(path, "wb") as fh:
        w = mcap_writer.Writer(fh)
        w.start(profile="ros2", library="azimut-tests")
        schema = w.register_schema(name="sensor_msgs/msg/JointState", encoding="ros2msg", data=msgdef.encode())
        channel = w.register_channel(topic="/joint_states", message_encoding="cdr", schema_id=schema)
        for k in range(60):
            t = T0_NS + int(m.t_ns[k])
            data = _joint_state(ts, t, joints, np.r_[m.beta[k], np.zeros(4)], np.r_[np.zeros(4), m.phidot[k]])
            w.add_message(channel_id=channel, log_time=t, data=bytes(data), publish_time=t)
        w.finish()
    assert detect_format(path) == "ros"
    _check(estimate_log(open_log(path, geom, MODULES4)), m.beta, m.phidot, geom)


# ----------------------------------------------------------------------------------------- .wpilog


SWERVE = RobotGeometry(alpha=np.arctan2([0.3, -0.3, 0.3, -0.3], [0.3, 0.3, -0.3, -0.3]), l=0.3 * np.sqrt(2), b=0.0,
                       r=0.0508)  # FL, FR, BL, BR as WPILib templates order them


def _wpilog(path, m, geom, *, legacy_deg=False, flush_every=200):
    """A log as WPILib/AdvantageKit write it, with wpiutil's own DataLogWriter: module states
    (speed m/s, angle = heading in ]-π, π], optimised: the nearer of angle and angle + π), a Pose2d."""
    wpiutil = pytest.importorskip("wpiutil")
    from wpiutil.log import RawLogEntry

    heading = heading_of(m.beta, geom)
    speed = m.phidot * geom.r
    flip = np.random.default_rng(2).random(heading.shape) < 0.4  # SwerveModuleState.optimize
    heading = np.where(flip, heading + np.pi, heading)
    speed = np.where(flip, -speed, speed)
    heading = np.mod(heading + np.pi, 2 * np.pi) - np.pi
    t0 = 1_000_000  # µs on the robot clock (0 would mean "now" to wpiutil)
    log = wpiutil.DataLogWriter(str(path), extraHeader="azimut-tests")
    for name, text in (("Rotation2d", "double value"), ("Translation2d", "double x;double y"),
                       ("Pose2d", "Translation2d translation;Rotation2d rotation"),
                       ("SwerveModuleState", "double speed;Rotation2d angle")):
        log.addSchema(f"struct:{name}", "structschema", text, t0)
    if legacy_deg:
        states = RawLogEntry(log, "/RealOutputs/SwerveStates/Measured", "", "double[]", t0)
    else:
        states = RawLogEntry(log, "/RealOutputs/SwerveStates/Measured", "", "struct:SwerveModuleState[]", t0)
    setpoints = RawLogEntry(log, "/RealOutputs/SwerveStates/Setpoints", "", "double[]", t0)
    pose = RawLogEntry(log, "/RealOutputs/Odometry/Robot", "", "struct:Pose2d", t0)
    for k in range(len(m.t_s)):
        t = t0 + int(round(m.t_s[k] * 1e6))
        pairs = np.column_stack([np.degrees(heading[k]), speed[k]]) if legacy_deg else np.column_stack([speed[k],
                                                                                                        heading[k]])
        states.append(pairs.astype("<f8").tobytes(), t)
        setpoints.append(np.zeros(8).tobytes(), t)
        pose.append(m.pose[k].astype("<f8").tobytes(), t)
        if k % flush_every == 0:
            log.flush()  # wpiutil's writer blocks once about 1 MiB is unflushed
    log.flush()
    log.stop()
    if legacy_deg:
        heading = np.deg2rad(np.degrees(heading))  # what the reader reads back
    beta, phidot = fold_coaxial(heading - geom.alpha + np.pi / 2, speed / geom.r, geom)
    return beta, phidot


@pytest.mark.parametrize("legacy_deg", [False, True])
def test_wpilog_round_trip(tmp_path, legacy_deg):
    m = motion(SWERVE, 200, noise=0.01)
    path = tmp_path / "robot.wpilog"
    beta, phidot = _wpilog(path, m, SWERVE, legacy_deg=legacy_deg)
    assert detect_format(path) == "wpilog"
    options = {"states_entry": "/RealOutputs/SwerveStates/Measured", "angle_unit": "deg"} if legacy_deg else {}
    src = open_log(path, SWERVE, ["fl", "fr", "bl", "br"], truth_entry="/RealOutputs/Odometry/Robot", **options)
    assert src.states_entry == "/RealOutputs/SwerveStates/Measured" and src.extra_header == "azimut-tests"
    r = estimate_log(src, chunk_size=64)
    _check(r, beta, phidot, SWERVE)
    assert np.array_equal(r.t_ns, 1_000_000_000 + np.rint(m.t_s * 1e6).astype(np.int64) * 1000)
    np.testing.assert_array_equal(r.truth.pose, m.pose)
    lam, mu, _, _ = estimate_eta(m.beta, m.phidot, SWERVE)  # headings and flips undone: the motion itself
    np.testing.assert_allclose(r.lam["IT"], lam, atol=1e-9)
    np.testing.assert_allclose(r.mu["IT"], mu, atol=1e-9)


def test_wpilog_record_walk_agrees_with_wpiutil_datalogreader(tmp_path):
    pytest.importorskip("wpiutil")
    from wpiutil.log import DataLogReader

    from estimation.logs.wpilog import read_wpilog_index

    m = motion(SWERVE, 300)
    path = tmp_path / "robot.wpilog"
    _wpilog(path, m, SWERVE)
    buf, index, extra = read_wpilog_index(path)
    ours = [(int(index.entry[i]), int(index.ts[i]), bytes(buf[index.off[i]:index.off[i] + index.size[i]]))
            for i in range(index.entry.size)]
    theirs = [(rec.getEntry(), rec.getTimestamp(), bytes(rec.getRaw())) for rec in DataLogReader(str(path))]
    assert ours == theirs and extra == DataLogReader(str(path)).getExtraHeader()
