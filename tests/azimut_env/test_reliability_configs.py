"""Regression tests of issue 10 for configs and wrappers: NaN, negative or wrongly typed values
are refused where they enter, not when they break something later."""

from __future__ import annotations

import math

import numpy as np
import pytest

from azimut_env.env import AzimutEnv
from azimut_env.tracks import Track
from azimut_env.validation import ResetNeeded, check_choice, check_index_list, check_int, check_range
from azimut_env.vector_env import AzimutVectorEnv
from control.action_spaces.single import ICRTargetAction, TwistAction
from control.action_spaces.vector import VectorControllerAction

NAN = float("nan")


@pytest.mark.parametrize("kwargs", [
    dict(min_norm=NAN), dict(min_norm=-0.1), dict(min_norm=1.0), dict(mu_max=NAN), dict(mu_max=0.0),
    dict(target_rate=math.inf), dict(cross_push=-1.0), dict(shape_targets="yes"), dict(icr_config={"a": 1}),
])
def test_icr_target_action_refuses_bad_config(kwargs):
    with pytest.raises((ValueError, TypeError)):
        ICRTargetAction(AzimutEnv(), **kwargs)


@pytest.mark.parametrize("kwargs", [dict(v_max=NAN), dict(w_max=-1.0), dict(controller="pid"),
                                    dict(swerve_config=3)])
def test_twist_action_refuses_bad_config(kwargs):
    with pytest.raises((ValueError, TypeError)):
        TwistAction(AzimutEnv(), **kwargs)


@pytest.mark.parametrize("kwargs", [dict(min_norm=NAN), dict(action=["icr_target"]), dict(mu_accel=-1.0),
                                    dict(follower_config="x"), dict(shape_targets=1)])
def test_vector_controller_action_refuses_bad_config(kwargs):
    with pytest.raises((ValueError, TypeError)):
        VectorControllerAction(AzimutVectorEnv(num_envs=2), **kwargs)


def test_wrappers_refuse_step_before_reset_and_complex_actions():
    env = ICRTargetAction(AzimutEnv())
    with pytest.raises(ResetNeeded):
        env.step(np.zeros(4))
    env.reset(seed=0)
    with pytest.raises(TypeError):
        env.step(np.zeros(4, complex))
    with pytest.raises(ValueError):
        env.step(np.array([0.0, 0.0, 1.0, NAN]))
    env.step(np.array([0.0, 0.0, 1.0, 0.2]))


@pytest.mark.parametrize("kwargs", [dict(ramp=NAN), dict(ramp=-1.0), dict(spacing=math.inf), dict(spacing=1e-12),
                                    dict(speed=-0.5), dict(speed=NAN), dict(closed="yes"),
                                    dict(progress_radius=math.inf), dict(heading="north"),
                                    dict(waypoints=[[0, 0], [1j, 0]]), dict(waypoints=[[0, 0]])])
def test_track_from_waypoints_refuses_bad_values(kwargs):
    args = {"waypoints": [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]], **kwargs}
    with pytest.raises((ValueError, TypeError)):
        Track.from_waypoints(**args)


def test_track_constructor_refuses_bad_fields():
    xy = np.array([[0.0, 0.0], [1.0, 0.0]])
    for kwargs in (dict(name=3), dict(progress_radius=NAN), dict(closed=None), dict(speed=np.array([1j, 1j]))):
        base = dict(name="t", xy=xy, heading=0.0, speed=0.5)
        base.update(kwargs)
        with pytest.raises((ValueError, TypeError)):
            Track(**base)
    with pytest.raises(ValueError):
        Track("t", xy, 0.0, 0.5).with_ramps(NAN)


def test_validation_helpers():
    assert check_int("k", np.int64(3)) == 3 and check_int("k", 4.0) == 4
    for bad in (True, "3", 2.5, NAN, None):
        with pytest.raises((ValueError, TypeError)):
            check_int("k", bad)
    assert check_range("x", 0.5, 0, 1) == 0.5
    for bad in (NAN, -0.1, 1.1, "0.5", 1j, True):
        with pytest.raises((ValueError, TypeError)):
            check_range("x", bad, 0, 1)
    assert check_index_list("w", (np.int32(1), 3), 4) == [1, 3]
    for bad in ([4], [-1], [1.0], ["1"], "12", [True], [1, 1], 3):
        with pytest.raises((ValueError, TypeError)):
            check_index_list("w", bad, 4)
    assert check_choice("c", "a", ("a", "b")) == "a"
    with pytest.raises(ValueError):
        check_choice("c", True, (1, 2))


def test_icr_target_zero_direction_is_hold_not_nan():
    """Found by the property tests: min_norm=0 with a zero direction divided 0/0 (NaN target)."""
    from control.action_spaces.single import icr_target_from_action

    lam, mu = icr_target_from_action(np.array([0.0, 0.0, 0.0, 0.3]), 1.0, 0.0)
    assert np.array_equal(lam, [0.0, 0.0, 1.0]) and mu == 0.0
    with pytest.raises(ValueError):
        ICRTargetAction(AzimutEnv(), min_norm=0.0)


@pytest.mark.parametrize("make", [
    lambda: __import__("azimut_env.physics.engine", fromlist=["x"]).BlowUpLimits(speed=NAN),
    lambda: __import__("azimut_env.params", fromlist=["x"]).RobotParams(limits=None),
    lambda: __import__("control.icr.controller", fromlist=["x"]).ICRControllerConfig(stop_hysteresis=NAN),
    lambda: __import__("control.icr.controller", fromlist=["x"]).ICRControllerConfig(n_kappa=2.5),
    lambda: __import__("control.icr.controller", fromlist=["x"]).ICRControllerConfig(reconfig_rate_fraction=2.0),
    lambda: __import__("control.twist.wpilib", fromlist=["x"]).SwerveConfig(discretize=NAN),
    lambda: __import__("control.follow.path_follower", fromlist=["x"]).PathFollowerConfig(preview=NAN),
    lambda: __import__("estimation.it", fromlist=["x"]).ITParams(accept_rms=NAN),
    lambda: __import__("estimation.it", fromlist=["x"]).ITParams(max_iter=2.5),
    lambda: __import__("estimation.oracle", fromlist=["x"]).OracleParams(grid_points=0),
    lambda: __import__("estimation.oracle", fromlist=["x"]).OracleParams(ring_radii=(NAN,)),
])
def test_config_fields_found_by_property_tests(make):
    """Found by the property tests: fields accepted NaN (BlowUpLimits: NaN thresholds disarm the
    blow-up check) or a wrong type (RobotParams(limits=None): AttributeError)."""
    with pytest.raises((ValueError, TypeError)):
        make()


def test_huge_time_limit_factor_means_no_limit():
    """Found by the property tests: time_limit_factor=5.7e15 overflowed the step-limit integer."""
    env = AzimutEnv(time_limit_factor=5744005514610670.0)
    env.reset(seed=0)
    env.step(np.zeros(8, np.float32))
    assert env.task.step_limit[0] == np.iinfo(np.int64).max
