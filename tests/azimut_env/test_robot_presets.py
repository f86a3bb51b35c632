"""Robots by name (presets) and from description files: RobotParams.preset / from_file."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from azimut_env.params import RobotParams
from azimut_env.physics.stability import check_stability
from azimut_env.robot_file import PRESET_NAMES, RobotFileError, preset_source, resolve_robot
from estimation.geometry import RobotGeometry


def test_azimut3_preset_is_the_default_bit_for_bit():
    p = RobotParams.preset("azimut3")
    assert p == RobotParams()
    d = RobotParams()
    for a, b in ((p.geometry.alpha, d.geometry.alpha), (p.geometry.l, d.geometry.l), (p.geometry.b, d.geometry.b),
                 (p.geometry.r, d.geometry.r)):
        assert a.tobytes() == b.tobytes()


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
        assert RobotParams.from_file(path) == RobotParams()
        return
    with pytest.raises(RobotFileError) as exc:
        RobotParams.from_file(path)
    assert needle in str(exc.value) and str(path) in str(exc.value)


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
