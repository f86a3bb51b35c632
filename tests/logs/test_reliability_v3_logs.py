"""Issue 31's log defects: a stale samples.csv beside a new estimate, wpilog timestamps past 2^63 ns,
a struct schema that lies at the same size, CSV times in microseconds, a CSV of a million columns."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from estimation.logs.csv_log import write_csv_log
from estimation.logs.wpistruct import StructRegistry
from jobs.cli import main

MODULES = ("fl", "fr", "bl", "br")


def _robot(tmp_path) -> Path:
    body = 'schema = 1\nname = "sw"\n[geometry]\nsteering = "unlimited"\nb_m = 0.0\nr_m = 0.05\n'
    for m, (sx, sy) in zip(MODULES, [(1, 1), (1, -1), (-1, 1), (-1, -1)]):
        body += f'[[geometry.modules]]\nname = "{m}"\nx_m = {sx * 0.3}\ny_m = {sy * 0.3}\n'
    path = tmp_path / "robot.toml"
    path.write_text(body)
    return path


def _log(tmp_path, t_s=None) -> Path:
    t = np.arange(200) * 0.02 if t_s is None else t_s
    beta = np.tile([0.1, -0.1, 0.2, -0.2], (t.size, 1))
    path = tmp_path / "run.csv"
    write_csv_log(path, t, beta, np.ones_like(beta), MODULES)
    return path


def _refused(capsys, argv, *words):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and all(w in err for w in words), err


def test_estimate_again_without_csv_leaves_no_stale_csv(tmp_path):
    robot, log, out = _robot(tmp_path), _log(tmp_path), tmp_path / "out"
    assert main(["estimate", str(log), "--robot-file", str(robot), "--no-plots", "--csv", "--out", str(out)]) == 0
    assert (out / "samples.csv").is_file()
    (out / "mine.txt").write_text("the user's own file")
    assert main(["estimate", str(log), "--robot-file", str(robot), "--no-plots", "--out", str(out)]) == 0
    assert not (out / "samples.csv").exists()
    assert (out / "mine.txt").is_file()  # not ours: kept


def test_csv_times_in_microseconds_are_refused_as_such(tmp_path, capsys):
    robot = _robot(tmp_path)
    log = _log(tmp_path, t_s=1.7e15 + np.arange(200) * 2e4)
    _refused(capsys, ["estimate", str(log), "--robot-file", str(robot), "--no-plots", "--out", str(tmp_path / "o")],
             "microseconds")
    assert not (tmp_path / "o").exists()
    log = _log(tmp_path, t_s=1.7e15 + np.arange(200) * 0.02)  # seconds, but a clock no int64 of ns holds
    _refused(capsys, ["estimate", str(log), "--robot-file", str(robot), "--no-plots", "--out", str(tmp_path / "o")],
             "not a time in seconds")


def test_csv_of_a_million_columns_reads_without_allocating_for_them(tmp_path):
    robot = _robot(tmp_path)
    cols = ["t"] + [f"steer_{m}" for m in MODULES] + [f"wheel_{m}" for m in MODULES]
    extra = 1_000_000
    path = tmp_path / "wide.csv"
    with path.open("w") as fh:
        fh.write(",".join(cols + [f"x{k}" for k in range(extra)]) + "\n")
        zeros = ",0" * extra
        for i in range(3):
            fh.write(f"{0.02 * i},0.1,-0.1,0.2,-0.2,1,1,1,1{zeros}\n")
    assert main(["estimate", str(path), "--robot-file", str(robot), "--no-plots", "--out", str(tmp_path / "o")]) == 0


def _record(entry: int, ts: int, payload: bytes) -> bytes:
    return bytes([(3 << 2) | (7 << 4) | 3]) + struct.pack("<IIQ", entry, len(payload), ts) + payload


def _start(eid: int, name: str, typ: str) -> bytes:
    n, t = name.encode(), typ.encode()
    return (b"\x00" + struct.pack("<I", eid) + struct.pack("<I", len(n)) + n + struct.pack("<I", len(t)) + t
            + struct.pack("<I", 0))


def test_wpilog_timestamp_past_what_nanoseconds_hold_is_refused(tmp_path, capsys):
    robot = _robot(tmp_path)
    states = np.column_stack([np.ones(4), np.zeros(4)]).astype("<f8").tobytes()
    body = _record(0, 0, _start(1, "/states", "struct:SwerveModuleState[]"))
    body += _record(1, 1_000, states) + _record(1, 2**63 + 5, states)
    path = tmp_path / "big.wpilog"
    path.write_bytes(b"WPILOG" + struct.pack("<HI", 0x0100, 0) + body)
    _refused(capsys, ["estimate", str(path), "--robot-file", str(robot), "--no-plots", "--out", str(tmp_path / "o")],
             str(path), "record 2", "292 years")


@pytest.mark.parametrize("schema", ["int64 speed;Rotation2d angle", "double speed;bool angle[8]"])
def test_wpilog_schema_that_lies_at_the_same_size_is_refused(tmp_path, capsys, schema):
    robot = _robot(tmp_path)
    states = np.column_stack([np.ones(4), np.zeros(4)]).astype("<f8").tobytes()
    body = _record(0, 0, _start(1, "/.schema/struct:SwerveModuleState", "structschema"))
    body += _record(1, 0, schema.encode())
    body += _record(0, 0, _start(2, "/states", "struct:SwerveModuleState[]"))
    body += b"".join(_record(2, 20_000 * k, states) for k in range(5))
    path = tmp_path / "lie.wpilog"
    path.write_bytes(b"WPILOG" + struct.pack("<HI", 0x0100, 0) + body)
    _refused(capsys, ["estimate", str(path), "--robot-file", str(robot), "--no-plots", "--out", str(tmp_path / "o")],
             str(path), "'/states'", "not WPILib's")


def test_wpilib_types_decode_by_their_own_schemas():
    reg = StructRegistry()
    for name in ("Rotation2d", "Pose2d", "SwerveModuleState", "SwerveModuleVelocity"):
        assert reg.dtype(name).itemsize in (8, 16, 24)
    reg.add("Rotation2d", "double  value")  # the same layout written differently: accepted
    assert reg.dtype("Pose2d").itemsize == 24
    reg.add("Rotation2d", "float value;float pad")
    with pytest.raises(ValueError, match="not WPILib's"):
        reg.dtype("Pose2d")  # a part that lies makes the whole lie


def test_wpilog_negative_timestamps_are_read_as_wpilib_reads_them(tmp_path):
    """NetworkTables values from before the robot clock started carry negative timestamps (Team
    1672's log has 84): read signed, as WPILib's DataLogReader does, not refused."""
    robot = _robot(tmp_path)
    states = np.column_stack([np.ones(4), np.zeros(4)]).astype("<f8").tobytes()
    body = _record(0, 0, _start(1, "NT:/early", "double")) + _record(1, -123_000_000 & (2**64 - 1),
                                                                        struct.pack("<d", 1.0))
    body += _record(0, 0, _start(2, "/states", "struct:SwerveModuleState[]"))
    body += b"".join(_record(2, 20_000 * k, states) for k in range(5))
    path = tmp_path / "early.wpilog"
    path.write_bytes(b"WPILOG" + struct.pack("<HI", 0x0100, 0) + body)
    assert main(["estimate", str(path), "--robot-file", str(robot), "--no-plots", "--out", str(tmp_path / "o")]) == 0


def test_csv_robot_clock_microseconds_are_refused_by_their_period(tmp_path, capsys):
    robot = _robot(tmp_path)
    log = _log(tmp_path, t_s=np.arange(200) * 2e4)  # µs of the robot clock: 20,000 "s" apart
    _refused(capsys, ["estimate", str(log), "--robot-file", str(robot), "--no-plots", "--out", str(tmp_path / "o")],
             "20000 s apart", "microseconds")


def test_angle_unit_on_a_struct_state_array_is_refused(tmp_path, capsys):
    robot = _robot(tmp_path)
    states = np.column_stack([np.ones(4), np.zeros(4)]).astype("<f8").tobytes()
    body = _record(0, 0, _start(1, "/states", "struct:SwerveModuleState[]"))
    body += b"".join(_record(1, 20_000 * k, states) for k in range(5))
    path = tmp_path / "s.wpilog"
    path.write_bytes(b"WPILOG" + struct.pack("<HI", 0x0100, 0) + body)
    _refused(capsys, ["estimate", str(path), "--robot-file", str(robot), "--angle-unit", "deg", "--no-plots",
                      "--out", str(tmp_path / "o")], "'/states'", "does not apply")


_values = st.one_of(st.floats(allow_nan=True, allow_infinity=True, width=64), st.integers(-10**20, 10**20),
                    st.sampled_from(["x", "", "1e309", "0x10", "nan", " 3"]))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(rows=st.lists(st.lists(_values, min_size=9, max_size=9), min_size=0, max_size=12),
       times=st.one_of(st.none(), st.lists(st.floats(-1e20, 1e20), min_size=12, max_size=12)))
def test_any_csv_is_refused_in_one_line_or_estimated_finite(tmp_path, capsys, rows, times):
    """The class of CSV inputs (issue 31): whatever the cells hold, `azimut estimate` refuses the log
    in one line naming it, or estimates it with finite angles, speeds and λ̂."""
    robot = _robot(tmp_path)
    path = tmp_path / "any.csv"
    head = ["t"] + [f"steer_{m}" for m in MODULES] + [f"wheel_{m}" for m in MODULES]
    lines = [",".join(head)]
    for i, row in enumerate(rows):
        if times is not None:
            row = [times[i]] + row[1:]
        lines.append(",".join(str(v) for v in row))
    path.write_text("\n".join(lines) + "\n")
    out = tmp_path / f"o{len(list(tmp_path.iterdir()))}"
    capsys.readouterr()
    rc = main(["estimate", str(path), "--robot-file", str(robot), "--no-plots", "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert rc in (0, 2), err
    if rc == 2:
        assert len(err.splitlines()) == 1 and str(path) in err, err
        assert not out.exists()
    else:
        npz = np.load(out / "samples.npz")
        assert all(np.isfinite(npz[k]).all() for k in ("t_s", "beta", "phidot", "lam_IT", "mu_IT"))
