"""azimut estimate: a good log gives its report; a bad one is refused in one line with exit
status 2, and nothing is written."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from logs_data import MODULES4, motion

from estimation import estimate_eta
from estimation.logs.csv_log import write_csv_log
from jobs.cli import main


def _run(argv, capsys):
    code = main(argv)
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def _one_line_exit_2(argv, capsys, out):
    code, _, err = _run(argv, capsys)
    assert code == 2, err
    assert err.count("\n") == 1 and err.startswith("azimut estimate: error:") and "Traceback" not in err, err
    assert not out.exists()
    return err


@pytest.fixture
def csv_log(tmp_path, geom):
    m = motion(geom, 300, noise=0.02)
    beta = m.beta.copy()
    beta[17, 2] = np.nan
    path = tmp_path / "robot.csv"
    write_csv_log(path, m.t_s, beta, m.phidot, MODULES4, pose=m.pose)
    return path, m, beta


def test_estimate_a_csv_log(tmp_path, capsys, csv_log, geom):
    path, m, beta = csv_log
    out = tmp_path / "out"
    code, stdout, err = _run(["estimate", str(path), "--out", str(out), "--csv", "--methods", "IT,NE,LS"], capsys)
    assert code == 0, err
    assert "estimated 299 samples of 300 (1 skipped)" in stdout
    for name in ("samples.npz", "samples.csv", "report.md", "summary.json", "steer_space.png", "qua_time.png",
                 "odometry.png"):
        assert (out / name).is_file(), name
    good = np.isfinite(beta).all(axis=1)
    lam, mu, _, qua = estimate_eta(m.beta[good], m.phidot[good], geom)
    with np.load(out / "samples.npz") as z:
        assert np.array_equal(z["lam_IT"], lam) and np.array_equal(z["mu_IT"], mu) and np.array_equal(z["qua_IT"], qua)
        assert z["pose"].shape == (299, 3) and z["truth_pose"].shape == (299, 3)
        np.testing.assert_allclose(z["twist_IT"], mu[:, None] * np.column_stack([lam[:, 1], -lam[:, 0], lam[:, 2]]))
    header = (out / "samples.csv").read_text().splitlines()[0].split(",")
    assert header[:2] == ["t_s", "beta_front_left"] and "lam_u_IT" in header and "truth_theta" in header
    summary = json.loads((out / "summary.json").read_text())
    assert summary["samples"]["skipped_total"] == 1 and summary["odometry"]["drift"]["samples"] == 299
    report = (out / "report.md").read_text()
    assert "| a steering angle or wheel speed is NaN or infinite | 1 |" in report and "| LS |" in report


def _write(path, text):
    path.write_text(text)
    return path


def _csv_text(m, modules=MODULES4, rows=None):
    header = "t," + ",".join(f"steer_{x},wheel_{x}" for x in modules)
    lines = [header] + [",".join(f"{v:.17g}" for v in [m.t_s[k], *np.ravel(np.column_stack([m.beta[k], m.phidot[k]]))])
                        for k in range(len(m.t_s) if rows is None else rows)]
    return "\n".join(lines) + "\n"


def _bad_csv(kind, tmp_path, geom):
    m = motion(geom, 20)
    text = _csv_text(m)
    p = tmp_path / "bad.csv"
    if kind == "missing column":
        return _write(p, text.replace("wheel_rear_left", "wheel_rl")), "no column 'wheel_rear_left'"
    if kind == "unknown module":
        return _write(p, text.replace("t,", "t,steer_arm,", 1).replace("\n0,", "\n0,0,", 1)), "names no module"
    if kind == "truncated":
        return _write(p, text[:-30]), "a truncated or malformed file"
    if kind == "not a number":
        lines = text.splitlines()
        fields = lines[5].split(",")
        fields[2] = "abc"
        lines[5] = ",".join(fields)
        return _write(p, "\n".join(lines) + "\n"), "could not convert string 'abc'"
    if kind == "unsorted":
        lines = text.splitlines()
        lines[8], lines[9] = lines[9], lines[8]
        return _write(p, "\n".join(lines) + "\n"), "timestamps not increasing at sample 8"
    if kind == "duplicated":
        lines = text.splitlines()
        lines[9] = lines[8]
        return _write(p, "\n".join(lines) + "\n"), "timestamps duplicated at sample 8"
    if kind == "empty":
        return _write(p, "# nothing\n"), "empty: no header line"
    raise AssertionError(kind)


@pytest.mark.parametrize("kind", ["missing column", "unknown module", "truncated", "not a number", "unsorted",
                                  "duplicated", "empty"])
def test_bad_csv_is_one_line_exit_2(kind, tmp_path, capsys, geom):
    path, match = _bad_csv(kind, tmp_path, geom)
    err = _one_line_exit_2(["estimate", str(path), "--out", str(tmp_path / "out"), "--no-plots"], capsys,
                           tmp_path / "out")
    assert match in err


def _bag(tmp_path, geom, joints=None, n=30):
    rosbags = pytest.importorskip("rosbags.rosbag2")
    from rosbags.typesys import Stores, get_typestore

    from estimation.logs.ros import BagWriter

    m = motion(geom, n)
    joints = joints or [f"{x}_steer" for x in MODULES4] + [f"{x}_drive" for x in MODULES4]
    w = BagWriter(tmp_path / "bag")
    pos = np.column_stack([m.beta, np.full((n, 4), np.nan)])
    vel = np.column_stack([np.full((n, 4), np.nan), m.phidot])
    w.add_joint_states("/joint_states", 10**18 + m.t_ns, joints, pos, vel)
    w.close()
    assert rosbags and get_typestore(Stores.ROS2_HUMBLE)
    return tmp_path / "bag"


def test_bad_ros_bags_are_one_line_exit_2(tmp_path, capsys, geom):
    bag = _bag(tmp_path, geom)
    out = tmp_path / "out"
    base = ["estimate", str(bag), "--out", str(out), "--no-plots"]
    assert "no topic /js" in _one_line_exit_2(base + ["--topic", "/js"], capsys, out)
    assert "no joint 'front_left_wheel' for module 'front_left'" in _one_line_exit_2(
        base + ["--drive-joint", "{module}_wheel"], capsys, out)
    assert "must contain {module}" in _one_line_exit_2(base + ["--drive-joint", "wheel"], capsys, out)
    assert "--truth-entry: does not apply to a ros log" in _one_line_exit_2(base + ["--truth-entry", "x"], capsys, out)
    mcap = next(bag.glob("*.mcap"))
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(mcap.read_bytes()[:-200])
    err = _one_line_exit_2(["estimate", str(cut), "--out", str(out)], capsys, out)
    assert "cannot be read as a ROS 2 bag" in err
    code, _, err = _run(base, capsys)
    assert code == 0, err


def test_bad_wpilogs_are_one_line_exit_2(tmp_path, capsys, geom):
    from test_logs_formats import SWERVE, _wpilog

    out = tmp_path / "out"
    good = tmp_path / "robot.wpilog"
    _wpilog(good, motion(SWERVE, 50), SWERVE)
    data = good.read_bytes()
    cut = _write(tmp_path / "cut.wpilog", "")
    cut.write_bytes(data[:-5])
    assert "truncated: the record at byte" in _one_line_exit_2(["estimate", str(cut), "--out", str(out)], capsys, out)
    base = ["estimate", str(good), "--out", str(out), "--no-plots"]
    assert "whose angle unit the log does not say" in _one_line_exit_2(
        base + ["--states-entry", "/RealOutputs/SwerveStates/Setpoints"], capsys, out)
    assert "no entry '/Nope'" in _one_line_exit_2(base + ["--states-entry", "/Nope"], capsys, out)
    assert "always headings" in _one_line_exit_2(base + ["--steer-convention", "beta"], capsys, out)
    other = tmp_path / "x.wpilog"
    other.write_bytes(b"not a log at all, just text")
    assert "not a WPILib data log (starts with" in _one_line_exit_2(["estimate", str(other), "--out", str(out)], capsys,
                                                                     out)
    other = tmp_path / "x.bin"
    other.write_bytes(b"not a log at all, just text")
    assert "cannot tell its format" in _one_line_exit_2(["estimate", str(other), "--out", str(out)], capsys, out)
    fake = tmp_path / "y.bin"
    fake.write_bytes(b"WPILOG\x00\x02" + bytes(10))
    assert "version 2.0" in _one_line_exit_2(["estimate", str(fake), "--out", str(out)], capsys, out)
    code, stdout, err = _run(base, capsys)
    assert code == 0, err


def test_wrong_record_size_samples_are_skipped(tmp_path, capsys):
    from test_logs_formats import SWERVE, _wpilog

    from estimation import RobotGeometry
    from estimation.logs import estimate_log, open_log

    good = tmp_path / "robot.wpilog"
    _wpilog(good, motion(SWERVE, 50), SWERVE)
    tri = RobotGeometry.regular(3, l=0.3, b=0.0, r=0.05)
    with pytest.raises(ValueError, match="no good sample among the 50 read .50 x the record does not hold one value"):
        estimate_log(open_log(good, tri))


def test_missing_log_and_bad_robot_file(tmp_path, capsys):
    out = tmp_path / "out"
    assert "no such file or directory" in _one_line_exit_2(["estimate", str(tmp_path / "nope.csv"), "--out",
                                                            str(out)], capsys, out)
    bad_robot = _write(tmp_path / "r.toml", "schema = 1\n[geometry]\nr_m = 0.05\n")
    code, _, err = _run(["estimate", str(bad_robot), "--robot-file", str(bad_robot), "--out", str(out)], capsys)
    assert code == 2 and err.count("\n") == 1 and "robot file" in err


def test_subprocess_refusal_has_no_traceback(tmp_path, geom):
    path, _ = _bad_csv("unsorted", tmp_path, geom)
    proc = subprocess.run([sys.executable, "-m", "jobs.cli", "estimate", str(path), "--out", str(tmp_path / "o"),
                           "--no-plots"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1 and "Traceback" not in proc.stderr
    assert not (tmp_path / "o").exists()


# ------------------------------------------- every format, written by its own writer, through the CLI

_SWERVE_TOML = """schema = 1
name = "swerve_fl_fr_bl_br"

[geometry]
steering = "unlimited"
b_m = 0.0
r_m = 0.0508
""" + "".join(f"""
[[geometry.modules]]
name = "{name}"
x_m = {x}
y_m = {y}
""" for name, x, y in (("fl", 0.3, 0.3), ("fr", 0.3, -0.3), ("bl", -0.3, 0.3), ("br", -0.3, -0.3)))


def _rosbags_bag(path, m, storage):
    from test_logs_formats import T0_NS, _joint_state, _ros

    Writer, StoragePlugin, ts = _ros()
    joints = [f"{mod}_steer" for mod in MODULES4] + [f"{mod}_drive" for mod in MODULES4]
    with Writer(path, version=9, storage_plugin=getattr(StoragePlugin, storage)) as w:
        c = w.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=ts)
        for k in range(len(m.t_s)):
            t = T0_NS + int(m.t_ns[k])
            w.write(c, t, _joint_state(ts, t, joints, np.r_[m.beta[k], np.zeros(4)], np.r_[np.zeros(4), m.phidot[k]]))
    return path


def _mcap_package_file(path, m):
    from test_logs_formats import T0_NS, _joint_state, _ros

    _, _, ts = _ros()
    mcap_writer = pytest.importorskip("mcap.writer")
    joints = [f"{mod}_steer" for mod in MODULES4] + [f"{mod}_drive" for mod in MODULES4]
    msgdef, _ = ts.generate_msgdef("sensor_msgs/msg/JointState", ros_version=2)
    with open(path, "wb") as fh:
        w = mcap_writer.Writer(fh)
        w.start(profile="ros2", library="azimut-tests")
        schema = w.register_schema(name="sensor_msgs/msg/JointState", encoding="ros2msg", data=msgdef.encode())
        channel = w.register_channel(topic="/joint_states", message_encoding="cdr", schema_id=schema)
        for k in range(len(m.t_s)):
            t = T0_NS + int(m.t_ns[k])
            data = _joint_state(ts, t, joints, np.r_[m.beta[k], np.zeros(4)], np.r_[np.zeros(4), m.phidot[k]])
            w.add_message(channel_id=channel, log_time=t, data=bytes(data), publish_time=t)
        w.finish()
    return path


@pytest.mark.parametrize("writer", ["rosbags-mcap", "rosbags-sqlite3", "mcap-package", "wpiutil"])
def test_each_writers_log_through_azimut_estimate_matches_estimate_eta(writer, tmp_path, capsys, geom):
    """A log written by the format's own writer (rosbags' Writer, the mcap package's Writer,
    WPILib's DataLogWriter), read back by ``azimut estimate``: samples.npz holds estimate_eta's
    λ̂, μ̂ and qua of the same arrays, bit for bit, for every estimator."""
    argv = []
    if writer == "wpiutil":
        from test_logs_formats import _wpilog

        from estimation import RobotGeometry

        robot = tmp_path / "swerve.toml"
        robot.write_text(_SWERVE_TOML)
        g = RobotGeometry.from_file(robot)
        m = motion(g, 120, noise=0.01)
        log = tmp_path / "robot.wpilog"
        beta, phidot = _wpilog(log, m, g)  # the module states as read: headings and flips folded
        argv = ["--robot-file", str(robot)]
    else:
        m = motion(geom, 120, noise=0.01)
        beta, phidot, g = m.beta, m.phidot, geom
        log = (_mcap_package_file(tmp_path / "plain.mcap", m) if writer == "mcap-package"
               else _rosbags_bag(tmp_path / "bag", m, writer.split("-")[1].upper()))
    out = tmp_path / "out"
    code, stdout, err = _run(["estimate", str(log), "--out", str(out), "--no-plots", *argv], capsys)
    assert code == 0, err
    assert "estimated 120 samples of 120 (0 skipped)" in stdout
    with np.load(out / "samples.npz") as z:
        for method, key in (("IT", "IT"), ("IT+", "ITplus"), ("NE", "NE"), ("LS", "LS"), ("NS", "NS")):
            lam, mu, _, qua = estimate_eta(beta, phidot, g, method)
            assert np.array_equal(z[f"lam_{key}"], lam), method
            assert np.array_equal(z[f"mu_{key}"], mu), method
            assert np.array_equal(z[f"qua_{key}"], qua), method
