"""WPILib data logs with one entry per module and signal (estimation.logs.wpilog_modules), each
logged at its own times, brought onto one clock by sample-and-hold; the gyro heading of every wpilog
reader; the CLI's reading flags and their refusals; Team 1714's real log (when ../shared has it) and
a trimmed copy of Team 1672's (tests/data/team1672_trimmed.wpilog)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from logs_data import heading_of, motion
from test_logs_formats import SWERVE, _wpilog

from estimation import RobotGeometry, estimate_eta
from estimation.logs import BAD_REASONS, estimate_log, fold_coaxial, open_log
from estimation.logs.source import BAD_STALE, beta_from_heading
from jobs.cli import main

REAL = Path(__file__).resolve().parents[3] / "shared/data/real-logs"
FIXTURE = Path(__file__).resolve().parents[1] / "data/team1672_trimmed.wpilog"
NAMES = ("fl", "fr", "bl", "br")
T0_US = 1_000_000  # the robot clock at the first loop (0 would mean "now" to wpiutil)
LOOP_US = 20_000
SCALE = 0.0023089  # Falcon raw units to m/s at a 4 in wheel, 6.75:1
SCHEMAS = (("Rotation2d", "double value"), ("Translation2d", "double x;double y"),
           ("Pose2d", "Translation2d translation;Rotation2d rotation"))


def _motion(n=300, still=(100, 160)):
    """A swerve motion at 50 Hz with a standstill (wheels at rest, steering frozen) over loops ``still``."""
    m = motion(SWERVE, n, dt=LOOP_US * 1e-6, noise=0.0)
    a, b = still
    m.beta[a:b] = m.beta[a]
    m.phidot[a:b] = 0.0
    return m


def _write(path, m, *, steer="deg", convention="heading", wheel_scale=SCALE, yaw=None, seed=1):
    """Per-module entries as robot code logs them: steering ``NT:/SmartDashboard/Mod {i} Cancoder`` on
    change (quantized like an encoder; unit ``steer``: deg, rad, rot or rotation2d), 1-4 ms into the loop;
    wheel speeds ``mod{i}/driveMotorSpeed`` every loop in units of ``wheel_scale`` m/s, module 0 at the
    loop's start, the others jittered by up to 0.7 ms. Returns the logged steering [rad] and wheel
    values as the reader converts them, per loop (the value held at each loop)."""
    wpiutil = pytest.importorskip("wpiutil")
    from wpiutil.log import RawLogEntry

    rng = np.random.default_rng(seed)
    n = len(m.t_s)
    angle = heading_of(m.beta, SWERVE) if convention == "heading" else m.beta.copy()
    angle = np.mod(angle + np.pi, 2 * np.pi) - np.pi
    if steer == "deg":
        logged = np.round(np.degrees(angle), 2)  # a CANcoder's resolution, about 0.09 deg
        as_rad = np.deg2rad(logged)
    elif steer == "rot":
        logged = np.round(angle / (2 * np.pi), 5)
        as_rad = logged * (2 * np.pi)
    else:
        logged = as_rad = angle
    wheel = m.phidot * SWERVE.r / wheel_scale
    log = wpiutil.DataLogWriter(str(path))
    for name, text in SCHEMAS:
        log.addSchema(f"struct:{name}", "structschema", text, T0_US)
    nt_schema = RawLogEntry(log, "NT:/.schema/struct:ChassisSpeeds", "", "structschema", T0_US)
    nt_schema.append(b"double vx;double vy;double omega", T0_US)
    typ = "struct:Rotation2d" if steer == "rotation2d" else "double"
    steers = [RawLogEntry(log, f"NT:/SmartDashboard/Mod {k} Cancoder", "", typ, T0_US) for k in range(4)]
    wheels = [RawLogEntry(log, f"mod{k}/driveMotorSpeed", "", "double", T0_US) for k in range(4)]
    RawLogEntry(log, "NT:/SmartDashboard/Mod 0 Name", "", "string", T0_US).append(b"front left", T0_US)
    yaws = {}
    if yaw is not None:
        yaws = {"/gyro/deg": RawLogEntry(log, "/gyro/deg", "", "double", T0_US),
                "/gyro/rot2d": RawLogEntry(log, "/gyro/rot2d", "", "struct:Rotation2d", T0_US),
                "/gyro/pose": RawLogEntry(log, "/gyro/pose", "", "struct:Pose2d", T0_US),
                "/gyro/array": RawLogEntry(log, "/gyro/array", "", "double[]", T0_US)}
    for k in range(n):
        t = T0_US + k * LOOP_US
        for j in range(4):
            if k == 0 or logged[k, j] != logged[k - 1, j]:
                steers[j].append(np.float64(logged[k, j]).tobytes(), t + 1000 + int(rng.integers(0, 3000)))
            wheels[j].append(np.float64(wheel[k, j]).tobytes(), t + (0 if j == 0 else int(rng.integers(50, 700))))
        if yaw is not None:
            wrapped = float(np.mod(yaw[k] + np.pi, 2 * np.pi) - np.pi)
            yaws["/gyro/deg"].append(np.float64(np.degrees(wrapped)).tobytes(), t + 500)
            if k % 7 == 3:  # a repeated timestamp: the last value counts; a NaN: dropped
                yaws["/gyro/deg"].append(np.float64(np.nan).tobytes(), t + 600)
                yaws["/gyro/deg"].append(np.float64(0.0).tobytes(), t + 500)
                yaws["/gyro/deg"].append(np.float64(np.degrees(wrapped)).tobytes(), t + 500)
            yaws["/gyro/rot2d"].append(np.float64(wrapped).tobytes(), t + 500)
            yaws["/gyro/pose"].append(np.array([1.0, 2.0, wrapped]).tobytes(), t + 500)
            yaws["/gyro/array"].append(np.array([1.0, 2.0, wrapped]).tobytes(), t + 500)
        if k % 100 == 0:
            log.flush()
    log.flush()
    log.stop()
    return as_rad, wheel


def _open(path, **options):
    kw = {"steer_entry": "NT:/SmartDashboard/Mod {i} Cancoder", "wheel_entry": "mod{i}/driveMotorSpeed",
          "angle_unit": "deg", "wheel_scale": SCALE}
    kw.update(options)
    return open_log(path, SWERVE, NAMES, **{k: v for k, v in kw.items() if v is not None})


def _expected(as_rad, wheel, wheel_scale=SCALE, convention="heading"):
    beta = beta_from_heading(as_rad, SWERVE) if convention == "heading" else as_rad
    return fold_coaxial(beta, wheel * wheel_scale / SWERVE.r, SWERVE)


@pytest.mark.parametrize("steer", ["deg", "rot", "rad", "rotation2d"])
def test_samples_after_sample_and_hold_are_the_logged_values(tmp_path, steer):
    m = _motion()
    path = tmp_path / "robot.wpilog"
    as_rad, wheel = _write(path, m, steer=steer)
    src = _open(path, angle_unit=None if steer == "rotation2d" else steer, max_age_s=5.0)
    assert src.n_samples == len(m.t_s) and src.clock_entry == "mod0/driveMotorSpeed"
    assert src.steer_entries == [f"NT:/SmartDashboard/Mod {k} Cancoder" for k in range(4)]
    assert src.lookahead_ns == LOOP_US * 1000 // 2 and src.n_stale == 0
    assert "ChassisSpeeds" in src.structs.schemas  # read from NT:/.schema/struct:ChassisSpeeds
    r = estimate_log(src, ["IT"], chunk_size=64)
    beta, phidot = _expected(as_rad, wheel)
    assert r.t_ns.size == len(m.t_s) and not r.skipped
    assert np.array_equal(r.t_ns, (T0_US + np.arange(len(m.t_s)) * LOOP_US) * 1000)
    np.testing.assert_allclose(r.beta, beta, atol=1e-12)
    np.testing.assert_allclose(r.phidot, phidot, rtol=1e-12, atol=1e-12)
    lam, mu, _, _ = estimate_eta(m.beta, m.phidot, SWERVE)  # the motion itself, within the encoder's resolution
    moving = np.abs(mu) > 0.1
    assert np.all(np.abs(np.abs(np.sum(r.lam["IT"][moving] * lam[moving], axis=1)) - 1) < 1e-3)


def test_stale_ticks_are_skipped_and_counted(tmp_path):
    m = _motion(still=(100, 160))
    path = tmp_path / "robot.wpilog"
    as_rad, wheel = _write(path, m)
    src = _open(path)  # default max age 0.5 s
    # the steering is logged on change: frozen from loop 100, its value is older than 0.5 s from loop 126
    # (26 loops of 20 ms, less the 1-4 ms into its loop) until it changes again at loop 160
    assert src.n_stale == 34 and "stale_ticks" in src.describe() and src.describe()["max_age_s"] == 0.5
    r = estimate_log(src, ["IT"])
    assert r.skipped == {BAD_REASONS[BAD_STALE]: 34} and r.t_ns.size == len(m.t_s) - 34
    keep = np.ones(len(m.t_s), bool)
    keep[126:160] = False
    beta, phidot = _expected(as_rad, wheel)
    np.testing.assert_allclose(r.beta, beta[keep], atol=1e-12)
    np.testing.assert_allclose(r.phidot, phidot[keep], atol=1e-12)
    assert _open(path, max_age_s=1.5).n_stale == 0


def test_wheel_scale_beta_convention_and_inverted_motor(tmp_path):
    m = _motion()
    path = tmp_path / "robot.wpilog"
    as_rad, wheel = _write(path, m, steer="rad", convention="beta", wheel_scale=-0.01)
    src = _open(path, angle_unit="rad", steer_convention="beta", wheel_scale=-0.01, max_age_s=5.0)
    r = estimate_log(src, ["IT"])
    beta, phidot = _expected(as_rad, wheel, wheel_scale=-0.01, convention="beta")
    np.testing.assert_allclose(r.beta, beta, atol=1e-12)
    np.testing.assert_allclose(r.phidot, phidot, atol=1e-12)
    np.testing.assert_allclose(np.abs(r.phidot), np.abs(m.phidot), atol=1e-9)


def test_module_names_pattern(tmp_path):
    """{module} names the module: the entries of a robot file's names, or of --module-names."""
    wpiutil = pytest.importorskip("wpiutil")
    from wpiutil.log import RawLogEntry

    path = tmp_path / "yagsl.wpilog"
    log = wpiutil.DataLogWriter(str(path))
    for k, mod in enumerate(("frontleft", "frontright", "backleft", "backright")):
        a = RawLogEntry(log, f"/swerve/modules/{mod}/Adjusted Absolute Encoder", "", "double", T0_US)
        v = RawLogEntry(log, f"/swerve/modules/{mod}/Raw Drive Velocity", "", "float", T0_US)
        for i in range(10):
            a.append(np.float64(90.0).tobytes(), T0_US + i * LOOP_US)
            v.append(np.float32(0.5 + k).tobytes(), T0_US + i * LOOP_US + 100)
    log.flush()
    log.stop()
    src = open_log(path, SWERVE, ("frontleft", "frontright", "backleft", "backright"),
                   steer_entry="/swerve/modules/{module}/Adjusted Absolute Encoder",
                   wheel_entry="/swerve/modules/{module}/Raw Drive Velocity", angle_unit="deg")
    r = estimate_log(src, ["IT"])
    beta, phidot = fold_coaxial(beta_from_heading(np.full((1, 4), np.pi / 2), SWERVE),
                                (0.5 + np.arange(4))[None, :] / SWERVE.r, SWERVE)
    assert r.t_ns.size == 10 and src.clock_entry == "/swerve/modules/frontleft/Adjusted Absolute Encoder"
    np.testing.assert_allclose(r.beta, np.repeat(beta, 10, axis=0))
    np.testing.assert_allclose(r.phidot, np.repeat(phidot, 10, axis=0))


@pytest.mark.parametrize("entry", ["/gyro/deg", "/gyro/rot2d", "/gyro/pose", "/gyro/array"])
def test_yaw_from_number_rotation2d_pose2d_and_pose_array(tmp_path, entry):
    m = _motion()
    yaw = 3.0 + 0.05 * np.arange(len(m.t_s))  # crosses +π, then turns more than once
    path = tmp_path / "robot.wpilog"
    _write(path, m, yaw=yaw)
    src = _open(path, yaw_entry=entry, yaw_unit="deg" if entry == "/gyro/deg" else None)
    track = src.yaw()
    assert track.source == f"entry {entry}"
    assert np.array_equal(track.t_ns, (T0_US + 500 + np.arange(len(m.t_s)) * LOOP_US) * 1000)
    np.testing.assert_allclose(track.yaw, yaw, atol=1e-9)


def test_yaw_of_a_state_array_log(tmp_path):
    m = motion(SWERVE, 50)
    path = tmp_path / "robot.wpilog"
    _wpilog(path, m, SWERVE)
    src = open_log(path, SWERVE, NAMES, yaw_entry="/RealOutputs/Odometry/Robot")
    np.testing.assert_allclose(src.yaw().yaw, np.unwrap(m.pose[:, 2]))
    assert src.describe()["yaw_entry"] == "/RealOutputs/Odometry/Robot"
    assert open_log(path, SWERVE, NAMES).yaw() is None


# ----------------------------------------------------------------------------------------------- CLI


def _cli(argv, capsys):
    code = main(argv)
    captured = capsys.readouterr()
    return code, captured.out, captured.err


@pytest.fixture
def module_log(tmp_path):
    path = tmp_path / "robot.wpilog"
    _write(path, _motion(n=60, still=(20, 30)), yaw=np.zeros(60))
    robot = tmp_path / "swerve.toml"
    robot.write_text('schema = 1\nname = "s"\n[geometry]\nsteering = "unlimited"\nb_m = 0.0\nr_m = 0.0508\n'
                     + "".join(f'[[geometry.modules]]\nname = "{n}"\nx_m = {x}\ny_m = {y}\n'
                               for n, x, y in (("fl", 0.3, 0.3), ("fr", 0.3, -0.3), ("bl", -0.3, 0.3),
                                               ("br", -0.3, -0.3))))
    return path, robot


MOD_FLAGS = ["--steer-entry", "NT:/SmartDashboard/Mod {i} Cancoder", "--wheel-entry", "mod{i}/driveMotorSpeed"]


def test_cli_per_module_entries(tmp_path, capsys, module_log):
    path, robot = module_log
    out = tmp_path / "out"
    code, stdout, err = _cli(["estimate", str(path), "--robot-file", str(robot), *MOD_FLAGS, "--angle-unit", "deg",
                              "--wheel-scale", str(SCALE), "--max-age", "2", "--yaw-entry", "/gyro/deg",
                              "--yaw-unit", "deg", "--steer-convention", "heading", "--no-plots", "--methods", "IT",
                              "--out", str(out)], capsys)
    assert code == 0, err
    assert "estimated 60 samples of 60 (0 skipped)" in stdout
    report = (out / "report.md").read_text()
    assert "clock_entry mod0/driveMotorSpeed" in report and "yaw_entry /gyro/deg" in report


@pytest.mark.parametrize("extra, words", [
    (["--steer-entry", "NT:/SmartDashboard/Mod {i} Cancodr", "--wheel-entry", "mod{i}/driveMotorSpeed",
      "--angle-unit", "deg"],
     ["'NT:/SmartDashboard/Mod 0 Cancodr' for module 0 (fl)", "near: 'NT:/SmartDashboard/Mod 0 Cancoder'"]),
    (["--steer-entry", "NT:/SmartDashboard/Mod 0 Cancoder", "--wheel-entry", "mod{i}/driveMotorSpeed",
      "--angle-unit", "deg"], ["names one entry for 4 modules", "{i}"]),
    (["--steer-entry", "NT:/SmartDashboard/Mod {i} Name", "--wheel-entry", "mod{i}/driveMotorSpeed",
      "--angle-unit", "deg"], ["is string, not one of double, float, int64, int, struct:Rotation2d"]),
    (MOD_FLAGS, ["angle unit", "--angle-unit"]),
    ([*MOD_FLAGS, "--angle-unit", "deg", "--yaw-entry", "/gyro/deg"], ["--yaw-unit"]),
    ([*MOD_FLAGS, "--angle-unit", "deg", "--yaw-entry", "/gyro/rot2d", "--yaw-unit", "deg"], ["does not apply"]),
    ([*MOD_FLAGS, "--angle-unit", "deg", "--yaw-entry", "mod0/nothing", "--yaw-unit", "deg"], ["no entry"]),
    ([*MOD_FLAGS, "--angle-unit", "deg", "--yaw-unit", "deg"], ["--yaw-unit: needs --yaw-entry"]),
    ([*MOD_FLAGS, "--angle-unit", "deg", "--wheel-scale", "0"], ["--wheel-scale"]),
    ([*MOD_FLAGS, "--angle-unit", "deg", "--wheel-scale", "nan"], ["--wheel-scale must be finite"]),
    ([*MOD_FLAGS, "--angle-unit", "deg", "--wheel-scale", "inf"], ["--wheel-scale must be finite"]),
    ([*MOD_FLAGS, "--angle-unit", "deg", "--max-age", "0"], ["--max-age must be > 0"]),
    ([*MOD_FLAGS, "--angle-unit", "deg", "--max-age", "-1"], ["--max-age must be > 0"]),
    ([*MOD_FLAGS, "--angle-unit", "deg", "--max-age", "nan"], ["--max-age must be finite"]),
    ([*MOD_FLAGS, "--angle-unit", "deg", "--states-entry", "x"], ["--states-entry: does not apply"]),
    (["--steer-entry", "NT:/SmartDashboard/Mod {i} Cancoder", "--angle-unit", "deg"], ["needs --wheel-entry"]),
    (["--wheel-entry", "mod{i}/driveMotorSpeed"], ["needs --steer-entry"]),
    (["--wheel-scale", "2"], ["applies to per-module entries only"]),
    (["--max-age", "2"], ["applies to per-module entries only"]),
    ([*MOD_FLAGS, "--angle-unit", "deg", "--topic", "/x"], ["--topic: does not apply to a wpilog log"]),
    ([*MOD_FLAGS, "--angle-unit", "deg", "--module-names", "a,b,c"], ["--module-names", "3 module names"]),
    ([*MOD_FLAGS[:2], "--wheel-entry", "{module}/speed", "--angle-unit", "deg",
      "--module-names", "a,b,c,d"], ["'a/speed' for module 0 (a)"]),
])
def test_bad_module_flags_are_one_line_exit_2(tmp_path, capsys, module_log, extra, words):
    path, robot = module_log
    out = tmp_path / "out"
    code, _, err = _cli(["estimate", str(path), "--robot-file", str(robot), *extra, "--out", str(out)], capsys)
    assert code == 2, err
    assert err.count("\n") == 1 and err.startswith("azimut estimate: error:") and "Traceback" not in err, err
    assert all(w in err for w in words), err
    assert not out.exists()


def test_module_flags_on_other_layouts_are_refused(tmp_path, capsys):
    m = motion(SWERVE, 30)
    states = tmp_path / "states.wpilog"
    _wpilog(states, m, SWERVE)
    csv = tmp_path / "run.csv"
    csv.write_text("t,steer_a,wheel_a\n0,0,0\n")
    out = tmp_path / "out"
    for argv, words in (([str(states), "--steer-convention", "beta"], "always headings"),
                        ([str(states), "--angle-unit", "rot", "--wheel-scale", "2"], "per-module entries only"),
                        ([str(csv), *MOD_FLAGS], "--steer-entry: does not apply to a csv log"),
                        ([str(csv), "--yaw-entry", "x"], "--yaw-entry: does not apply to a csv log")):
        code, _, err = _cli(["estimate", *argv, "--robot", "swerve", "--out", str(out)], capsys)
        assert code == 2 and err.count("\n") == 1 and words in err, err
        assert not out.exists()


# ------------------------------------------------------------------------------------------ real logs


@pytest.mark.skipif(not (REAL / "team1714_20230325_214134.wpilog").is_file(),
                    reason="Team 1714's log is not in ../shared/data/real-logs (it may not be committed)")
def test_team1714_real_log(tmp_path, capsys):
    import json

    out = tmp_path / "out"
    code, stdout, err = _cli(["estimate", str(REAL / "team1714_20230325_214134.wpilog"),
                              "--robot-file", str(REAL / "team1714_mk4i.toml"),
                              "--steer-entry", "NT:/SmartDashboard/Mod {i} Cancoder",
                              "--wheel-entry", "mod{i}/driveMotorSpeed", "--angle-unit", "deg",
                              "--wheel-scale", "0.0023089", "--no-plots", "--methods", "IT", "--out", str(out)], capsys)
    assert code == 0, err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["samples"]["read"] == 8328  # one tick per driveMotorSpeed record of module 0
    assert summary["log"]["clock_entry"] == "mod0/driveMotorSpeed"
    assert summary["samples"]["estimated"] + summary["log"]["stale_ticks"] == 8328
    assert summary["samples"]["estimated"] > 8000


def test_team1672_trimmed_fixture_state_array_and_yaw():
    geom = RobotGeometry(alpha=np.arctan2([0.3429, -0.3429, 0.3429, -0.3429], [0.4191, 0.4191, -0.4191, -0.4191]),
                         l=np.hypot(0.4191, 0.3429), b=0.0, r=0.0508)
    entries = "NT:/SmartDashboard/swerve/"
    src = open_log(FIXTURE, geom, NAMES, states_entry=entries + "advantagescope/currentStates",
                   yaw_entry=entries + "imu/raw", yaw_unit="deg")
    r = estimate_log(src, ["IT"])
    assert r.n_read == 608 and r.t_ns.size == 608
    speed = np.abs(r.phidot) * geom.r
    assert speed.mean(axis=1).max() > 1.5 and (speed.mean(axis=1) < 0.01).sum() > 100  # driving and standstill
    assert np.median(r.qua["IT"][speed.mean(axis=1) > 0.5]) > 0.99  # wheels parallel while driving
    yaw = src.yaw()
    assert yaw.t_ns.size == 270 and np.ptp(yaw.yaw) < np.radians(5)
    rot = open_log(FIXTURE, geom, NAMES, yaw_entry=entries + "advantagescope/robotRotation").yaw()
    np.testing.assert_allclose(rot.yaw, yaw.yaw, atol=1e-12)
    modules = open_log(FIXTURE, geom, ("frontleft", "frontright", "backleft", "backright"),
                       steer_entry=entries + "modules/{module}/Adjusted Absolute Encoder",
                       wheel_entry=entries + "modules/{module}/Raw Drive Velocity", angle_unit="deg", max_age_s=5.0)
    assert modules.n_samples == 260 and modules.n_stale == 1
