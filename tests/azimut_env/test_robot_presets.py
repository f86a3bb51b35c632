"""Robots by name (presets) and from description files: RobotParams.preset / from_file."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from azimut_env.imperfections import PAPER_FRICTION, imperfections_of, with_imperfections
from azimut_env.params import RobotParams
from azimut_env.physics.stability import check_stability
from azimut_env.robot_file import PRESET_NAMES, RobotFileError, preset_source, resolve_robot
from estimation.geometry import RobotGeometry


def test_azimut3_preset_is_the_default_robot_bit_for_bit():
    """The preset azimut3 is Azimut-v2's default robot: RobotParams() with the paper's imperfections,
    which its file names; without them ("ideal") it is RobotParams() bit for bit."""
    p = RobotParams.preset("azimut3")
    assert p == with_imperfections(RobotParams(), "paper") and imperfections_of(p) == "paper"
    assert with_imperfections(p, "ideal") == RobotParams()
    d = RobotParams()
    for a, b in ((p.geometry.alpha, d.geometry.alpha), (p.geometry.l, d.geometry.l), (p.geometry.b, d.geometry.b),
                 (p.geometry.r, d.geometry.r)):
        assert a.tobytes() == b.tobytes()
    assert [imperfections_of(RobotParams.preset(n)) for n in PRESET_NAMES] == ["paper", "ideal", "ideal", "ideal"]


def test_the_preset_its_file_and_the_default_are_one_robot():
    """``robot="azimut3"``, the shipped file's path and no robot give the same env robot; the
    ``imperfections`` argument overrides what the file names."""
    from importlib import resources

    from azimut_env.env import AzimutEnv

    path = str(resources.files("azimut_env").joinpath("robots", "azimut3.toml"))
    paper = RobotParams.preset("azimut3")
    assert RobotParams.from_file(path) == paper
    for kwargs in ({}, {"robot": "azimut3"}, {"robot": path}):
        assert AzimutEnv(**kwargs).params == paper
        assert AzimutEnv(**kwargs, imperfections="ideal").params == RobotParams()
    assert AzimutEnv(params=RobotParams()).params == RobotParams()  # given parameters are used as given
    assert AzimutEnv(robot="tri", imperfections="paper").params == with_imperfections(RobotParams.preset("tri"),
                                                                                        "paper")


def _with_table(name: str, table: str) -> str:
    """Preset ``name``'s file with its ``[imperfections]`` table replaced by ``table``."""
    text = preset_source(name)
    head, _, rest = text.partition("[imperfections]")
    return head + table + "\n[geometry]" + rest.partition("[geometry]")[2]


def test_a_file_names_its_imperfections_preset_and_its_keys_override_it(tmp_path):
    path = tmp_path / "r.toml"
    path.write_text(_with_table("tri", "[imperfections]\npreset = 'paper'\n"))
    tri = RobotParams.preset("tri")
    assert RobotParams.from_file(path) == with_imperfections(tri, "paper")  # its own draw for 3 wheels
    path.write_text(_with_table("tri", "[imperfections]\npreset = 'paper'\nsteer_offset = [0.01, 0.0, -0.01]\n"
                                       "[steering]\nstiffness = 30.0\n[wheel]\ndrive_model = 'current_limit'\n"))
    p = RobotParams.from_file(path)
    assert p.imperfections.steer_offset == (0.01, 0.0, -0.01) and p.steering.stiffness == 30.0
    assert p.wheel.drive_model == "current_limit"
    assert p.steering.friction_coulomb == PAPER_FRICTION["friction_coulomb"]  # the rest is the preset's
    assert p.imperfections.radius_error == with_imperfections(tri, "paper").imperfections.radius_error
    assert imperfections_of(p) is None  # neither preset: the robot's own
    path.write_text(_with_table("tri", ""))  # no preset named: the tables' values (RobotParams' defaults)
    assert RobotParams.from_file(path) == tri and imperfections_of(tri) == "ideal"


@pytest.mark.parametrize("table, needle", [
    ("[imperfections]\npreset = 'real'\n", "[imperfections].preset = 'real': must be one of 'paper', 'ideal'"),
    ("[imperfections]\npreset = 1\n", "[imperfections].preset = 1: must be one of"),
    ("[imperfections]\npresets = 'paper'\n", "unknown key 'presets' (known: steer_offset"),
    ("[imperfections]\npreset = 'paper'\nsteer_offset = [0.0]\n", "has 1 values for 3 wheels"),
])
def test_bad_imperfections_preset_refused(tmp_path, table, needle):
    path = tmp_path / "r.toml"
    path.write_text(_with_table("tri", table))
    with pytest.raises(RobotFileError) as exc:
        RobotParams.from_file(path)
    assert needle in str(exc.value) and str(path) in str(exc.value)
    if "presets" in table:
        assert "preset)" in str(exc.value)  # the preset key is listed among the known ones


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_presets_load_and_pass_the_stability_budget(name):
    p = RobotParams.preset(name)
    check_stability(p, 0.02 / 8)
    assert p is RobotParams.preset(name)  # cached, frozen


def test_preset_shapes():
    sw = RobotParams.preset("swerve")
    assert sw.n == 4 and sw.geometry.unlimited_steering and sw.limits.unlimited_steering
    assert np.all(sw.geometry.b == 0.0)
    assert sw.limits.steer_action_range == (-math.pi, math.pi)
    assert 4.6 < sw.max_surface_speed < 4.7  # 6000 rpm / 6.746 at r = 0.050165 m
    assert RobotParams.preset("tri").n == 3 and RobotParams.preset("hex").n == 6
    for name in ("tri", "hex"):
        g = RobotParams.preset(name).geometry
        assert not g.unlimited_steering and np.all(g.b == 0.08)


def test_unknown_preset_lists_the_known_ones():
    with pytest.raises(ValueError, match="azimut3, swerve, tri, hex"):
        RobotParams.preset("quad")


def test_robot_and_params_together_refused():
    assert resolve_robot("tri", None, RobotParams) == RobotParams.preset("tri")
    assert resolve_robot(None, None, RobotParams) is None
    with pytest.raises(ValueError, match="both given"):
        resolve_robot("swerve", RobotParams(), RobotParams)


def test_from_file_reads_groups_and_keeps_defaults(tmp_path):
    text = preset_source("tri") + ("\n[chassis]\nmass = 30\n[sensors]\nwheel_cpr = 1024\n"
                                   "[limits]\nsteer_rate_max = 3.0\n")
    path = tmp_path / "r.toml"
    path.write_text(text)
    p = RobotParams.from_file(path)
    assert p.chassis.mass == 30.0 and isinstance(p.chassis.mass, float)
    assert p.sensors.wheel_cpr == 1024 and p.limits.steer_rate_max == 3.0
    assert p.tire == RobotParams().tire
    assert p.geometry == RobotParams.preset("tri").geometry


@pytest.mark.parametrize("extra, needle", [
    ("[limits]\nsteer_max = 1.0\n", "[limits].steer_max: the steering range is set in [geometry]"),
    ("[limits]\nsteer_rate = 1.0\n", "[limits]: unknown key 'steer_rate'"),
    ("[limits]\nsteer_rate_max = -1.0\n", "steer_rate_max must be finite and > 0"),
    ("[sensors]\nwheel_cpr = 10.5\n", "[sensors].wheel_cpr = 10.5: must be an integer"),
    ("[chassis]\nmass = true\n", "[chassis].mass = True: must be a number"),
    ("[steer_motor]\nmodel = 3\n", "[steer_motor].model = 3: must be a string"),
    ("[steer_motor]\nmodel = 'servo'\n", "model must be 'kinematic' or 'dc'"),
    ("gravity = -9.81\n", "gravity"),
    ("[tire]\n", None),
])
def test_bad_parameters_refused(tmp_path, extra, needle):
    base = preset_source("azimut3")
    head, _, rest = base.partition("[geometry]")
    path = tmp_path / "r.toml"
    path.write_text(head + extra + "\n[geometry]" + rest)
    if needle is None:
        assert RobotParams.from_file(path) == RobotParams.preset("azimut3")
        return
    with pytest.raises(RobotFileError) as exc:
        RobotParams.from_file(path)
    assert needle in str(exc.value) and str(path) in str(exc.value)


@pytest.mark.parametrize("top, needle", [
    ("nmae = 'r'\n", "unknown key 'nmae' (known: schema, name, description, sources, geometry, gravity, chassis"),
    ("chassis = 3\n", "chassis = 3: must be a table ([chassis])"),
    ("gravity = 0\n", "gravity = 0: must be > 0"),
])
def test_bad_top_level_keys_refused(tmp_path, top, needle):
    """The keys outside the header and [geometry] are this layer's: estimation.robot_file does not
    know them, the whole file is checked here."""
    path = tmp_path / "r.toml"
    path.write_text(top + preset_source("tri"))
    with pytest.raises(RobotFileError) as exc:
        RobotParams.from_file(path)
    assert needle in str(exc.value) and str(path) in str(exc.value) and "\n" not in str(exc.value)
    path.write_text(preset_source("tri") + "\n[chasis]\nmass = 3.0\n")
    with pytest.raises(RobotFileError, match="unknown key 'chasis'"):
        RobotParams.from_file(path)
    assert RobotGeometry.from_file(path) == RobotParams.preset("tri").geometry  # the geometry alone: read


def test_unlimited_geometry_needs_unlimited_limits():
    g = RobotGeometry.regular(4, unlimited_steering=True)
    with pytest.raises(ValueError, match="unlimited steering"):
        RobotParams(geometry=g)
    p = RobotParams(geometry=g, limits=replace(RobotParams().limits, steer_min=-math.inf, steer_max=math.inf))
    assert p.limits.unlimited_steering


def test_presets_are_package_data():
    from importlib import resources

    names = {p.name for p in resources.files("azimut_env").joinpath("robots").iterdir()}
    assert {f"{n}.toml" for n in PRESET_NAMES} <= names


def test_gym_make_and_make_vec_take_a_preset_or_a_file(tmp_path):
    import gymnasium as gym

    import azimut_env  # noqa: F401 (registers the env)

    env = gym.make(azimut_env.ENV_ID, robot="hex", track="circle")
    obs, _ = env.reset(seed=0)
    assert env.unwrapped.n == 6 and env.action_space.shape == (12,)
    venv = gym.make_vec(azimut_env.ENV_ID, num_envs=2, vectorization_mode="vector_entry_point", robot="tri",
                        track="circle")
    assert venv.unwrapped.n == 3 and venv.reset(seed=0)[0].shape[0] == 2
    path = tmp_path / "r.toml"
    path.write_text(preset_source("swerve"))
    assert gym.make(azimut_env.ENV_ID, robot=str(path), track="circle").unwrapped.geometry.unlimited_steering
    with pytest.raises(ValueError, match="both given"):
        gym.make(azimut_env.ENV_ID, robot="swerve", params=RobotParams())
    env.close()
    venv.close()
