"""Robot description files, geometry part (estimation.robot_file, RobotGeometry.from_file)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from estimation.geometry import RobotGeometry
from estimation.robot_file import RobotFileError, parse_robot_text, read_robot_file

SQUARE = """
schema = 1
name = "test"
[geometry]
steering = "{steering}"
b_m = 0.05
r_m = 0.07
[[geometry.modules]]
x_m = 0.3
y_m = 0.2
[[geometry.modules]]
alpha_deg = 135.0
l_m = 0.25
b_m = 0.0
[[geometry.modules]]
x_m = -0.3
y_m = -0.2
r_m = 0.09
"""


def _write(tmp_path, text, name="robot.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_geometry_from_file_reads_both_axis_forms_and_defaults(tmp_path):
    g = RobotGeometry.from_file(_write(tmp_path, SQUARE.format(steering="limited")))
    assert g.n == 3 and not g.unlimited_steering
    np.testing.assert_allclose(g.axis_xy[0], [0.3, 0.2])
    np.testing.assert_allclose(g.alpha[1], np.deg2rad(135.0))
    np.testing.assert_allclose(g.l[1], 0.25)
    np.testing.assert_array_equal(g.b, [0.05, 0.0, 0.05])
    np.testing.assert_array_equal(g.r, [0.07, 0.07, 0.09])
    assert (g.steer_min, g.steer_max) == (-math.pi / 2, math.pi / 2)


def test_unlimited_steering_flag(tmp_path):
    g = RobotGeometry.from_file(_write(tmp_path, SQUARE.format(steering="unlimited")))
    assert g.unlimited_steering
    assert g != RobotGeometry.from_file(_write(tmp_path, SQUARE.format(steering="limited"), "b.toml"))


def test_azimut3_layout_from_file_is_the_default_geometry(tmp_path):
    text = """schema = 1
[geometry]
b_m = 0.08
r_m = 0.08
""" + "".join(f"[[geometry.modules]]\nalpha_deg = {a}\nl_m = 0.30\n" for a in (45.0, 135.0, -135.0, -45.0))
    assert RobotGeometry.from_file(_write(tmp_path, text)) == RobotGeometry.azimut3()


@pytest.mark.parametrize("edit, needle", [
    (lambda t: t.replace("schema = 1", "schema = 2"), "schema"),
    (lambda t: t.replace("schema = 1\n", ""), "missing key 'schema'"),
    (lambda t: t.replace('name = "test"', 'name = 3'), "name = 3: must be a string"),
    (lambda t: t.replace("y_m = 0.2\n", "y_m = 0.2\nz_m = 1.0\n", 1), "[geometry.modules][0]: unknown key 'z_m'"),
    (lambda t: t.replace("x_m = 0.3", "x_m = 'a'", 1), "[geometry.modules][0].x_m = 'a'"),
    (lambda t: t.replace("x_m = 0.3", "x_m = nan", 1), "must be finite"),
    (lambda t: t.replace("x_m = 0.3\n", "", 1), "needs x_m and y_m"),
    (lambda t: t.replace("alpha_deg = 135.0", "alpha_deg = 135.0\nx_m = 1.0"), "not both"),
    (lambda t: t.replace("l_m = 0.25", "l_m = -0.25"), "l_m = -0.25: must be > 0"),
    (lambda t: t.replace("r_m = 0.09", "r_m = 0.0"), "r_m = 0.0: must be > 0"),
    (lambda t: t.replace('steering = "limited"', 'steering = "free"'), "steering = 'free'"),
    (lambda t: t.replace('steering = "limited"', 'steering = "limited"\nsteer_range_deg = [-90, 80]'),
     "span 180 degrees"),
    (lambda t: t.replace('steering = "limited"', 'steering = "unlimited"\nsteer_range_deg = [-90, 90]'),
     "unlimited steering has no range"),
    (lambda t: t.split("[[geometry.modules]]\nx_m = -0.3")[0], "n >= 3"),
    (lambda t: t.replace("y_m = -0.2", "y_m = 0.2").replace("x_m = -0.3", "x_m = 0.3"), "all on one line"),
    (lambda t: t.replace("[geometry]", "[geometry]\nwheels = 3"), "unknown key 'wheels'"),
    (lambda t: t + "\n[limits\n", "not valid TOML"),
])
def test_bad_files_refused_naming_file_key_value(tmp_path, edit, needle):
    path = _write(tmp_path, edit(SQUARE.format(steering="limited")))
    with pytest.raises(RobotFileError) as exc:
        RobotGeometry.from_file(path)
    msg = str(exc.value)
    assert needle in msg and str(path) in msg and "\n" not in msg


def test_missing_file_and_directory(tmp_path):
    with pytest.raises(RobotFileError, match="no such file"):
        read_robot_file(tmp_path / "nope.toml")
    with pytest.raises(RobotFileError, match="directory"):
        read_robot_file(tmp_path)


def test_duplicate_module_names_refused(tmp_path):
    text = SQUARE.format(steering="limited").replace("[[geometry.modules]]\n", "[[geometry.modules]]\nname = 'a'\n")
    with pytest.raises(RobotFileError, match="two modules have this name"):
        RobotGeometry.from_file(_write(tmp_path, text))


def test_other_keys_are_the_callers():
    """The header and [geometry] are this layer's; any other key is the caller's to name (the
    simulator's tables: azimut_env.robot_file), refused only against the list it gives."""
    text = SQUARE.format(steering="limited").replace('name = "test"', 'name = "test"\ngravity = 9.81') + \
        "\n[chassis]\nmass = 3.0\n"
    assert parse_robot_text(text, "t")["chassis"] == {"mass": 3.0}  # geometry alone: left to its reader
    assert parse_robot_text(text, "t", others=("gravity", "chassis"))["gravity"] == 9.81
    with pytest.raises(RobotFileError, match=r"robot file t: unknown key 'chassis' \(known: schema, name, "
                                             r"description, sources, geometry, gravity\)"):
        parse_robot_text(text, "t", others=("gravity",))
