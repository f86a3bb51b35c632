"""Azimut-v1: Gymnasium and SB3 checks, determinism, pickling, action validation, observation layout,
the controller interface, rendering, obstacles and kicks."""

from __future__ import annotations

import pickle
import textwrap
import warnings

import gymnasium as gym
import numpy as np
import pytest

import azimut_env  # noqa: F401  (registers Azimut-v1)
from azimut_env.env import AzimutEnv, h_state_from_measurements, observation_layout
from azimut_env.params import ActuatorLimits, action_from_setpoints, setpoints_from_action
from azimut_env.task.observation import observation_table
from estimation import canonical_eta, estimate_icr, mu_from_wheel_speeds, quality, steering_from_lambda


def test_registered_with_per_track_time_limit():
    env = gym.make("Azimut-v2", track="crab")
    assert env.spec.max_episode_steps is None  # the env truncates per track (time_limit_factor)
    assert isinstance(env.unwrapped, AzimutEnv)
    assert env.metadata["render_fps"] == 50
    env.reset(seed=0)
    limit = int(env.unwrapped.task.step_limit[0])
    assert 1000 < limit < 6000
    env.unwrapped.task.steps[0] = limit - 1
    _, _, _, truncated, _ = env.step(env.unwrapped.action_from_setpoints(env.unwrapped.measured_beta, np.zeros(4)))
    assert truncated
    env.close()


def test_retired_version_names_the_new_one():
    with pytest.raises(gym.error.DeprecatedEnv, match="Azimut-v2"), pytest.warns(DeprecationWarning):
        gym.make("Azimut-v0")


def test_gymnasium_check_env_without_warnings():
    from gymnasium.utils.env_checker import check_env

    env = gym.make("Azimut-v2").unwrapped
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env)


def test_sb3_check_env_without_warnings(env):
    pytest.importorskip("stable_baselines3")
    from stable_baselines3.common.env_checker import check_env

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env, warn=True)


def _rollout(env, seed, steps=50):
    obs, _ = env.reset(seed=seed)
    env.action_space.seed(seed)
    out = [obs]
    for _ in range(steps):
        obs, rew, term, trunc, info = env.step(env.action_space.sample())
        out.append(np.concatenate([obs, [rew], info["pose"], info["tire_forces"].ravel()]))
        if term or trunc:
            break
    return out


def test_determinism_same_seed_exact_equality():
    a, b = AzimutEnv(track="random"), AzimutEnv(track="random")
    ra, rb = _rollout(a, 7), _rollout(b, 7)
    assert len(ra) == len(rb)
    for x, y in zip(ra, rb):
        assert np.array_equal(x, y)
    # the same env replays an episode bit for bit after another episode
    _rollout(a, 3)
    rc = _rollout(a, 7)
    for x, y in zip(ra, rc):
        assert np.array_equal(x, y)


def test_pickle_round_trip():
    env = AzimutEnv(track="circle")
    env.reset(seed=1)
    for _ in range(10):
        env.step(env.action_space.sample())
    clone = pickle.loads(pickle.dumps(env))
    assert np.array_equal(clone.physics.chassis_pose(), env.physics.chassis_pose())
    assert clone.progress == env.progress
    action = np.full(8, 0.3, dtype=np.float32)
    o1, r1, *_ = env.step(action)
    o2, r2, *_ = clone.step(action)
    assert np.allclose(o1, o2, atol=1e-5) and r1 == pytest.approx(r2, abs=1e-6)


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_nan_action_raises_without_changing_state(bad, env):
    env.reset(seed=0)
    pose = env.physics.chassis_pose().copy()
    action = np.zeros(8, dtype=np.float32)
    action[3] = bad
    with pytest.raises(ValueError, match="NaN or inf"):
        env.step(action)
    assert np.array_equal(env.physics.chassis_pose(), pose)
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(5, dtype=np.float32))


def test_out_of_range_actions_are_clipped(make_env):
    a, b = make_env(), make_env()
    a.reset(seed=0)
    b.reset(seed=0)
    big = np.array([3, -3, 5, -9, 2, -2, 7, -7], dtype=np.float32)
    oa, *_ = a.step(big)
    ob, *_ = b.step(np.clip(big, -1, 1))
    assert np.array_equal(oa, ob)


def test_observation_layout_and_bounds():
    env = AzimutEnv(lookahead_count=4)
    obs, info = env.reset(seed=0)
    sl = env.observation_slices()
    assert sl == observation_layout(4, 4)
    assert max(s.stop for s in sl.values()) == env.observation_space.shape[0] == obs.shape[0]
    assert np.all(np.isfinite(env.observation_space.low)) and np.all(np.isfinite(env.observation_space.high))
    dec = env.decode_observation(obs)
    assert dec["lookahead"].shape == (4, 3)
    lam_hat, mu_hat = env.estimated_eta
    assert np.allclose(dec["lambda_hat"], lam_hat, atol=1e-6)
    assert np.allclose(dec["beta"], env.measured_beta, atol=1e-6)
    assert info["reward_terms"] == dict.fromkeys(info["reward_terms"], 0.0) and len(info["reward_terms"]) == 9
    assert observation_table() in textwrap.dedent(AzimutEnv.__doc__)  # the docs show the layout table
    _, rew, _, _, info = env.step(env.action_space.sample())
    assert set(info["reward_terms"]) == {"progress", "lateral", "heading", "overspeed", "slip", "antagonism",
                                         "nullspace_force", "action_rate", "off_track"}
    assert rew == pytest.approx(sum(info["reward_terms"].values()))
    for key in ("pose", "twist", "eta_true", "eta_hat", "tire_forces", "slip_power", "antagonism", "nullspace_force",
                "qua"):
        assert key in info
    assert 0.0 <= info["qua"] <= 1.0


def test_setpoint_map_round_trip_and_controller_interface(env):
    env.reset(seed=0)
    lim = env.limits
    assert isinstance(lim, ActuatorLimits)
    beta = np.array([0.3, -1.2, 1.5, 0.0])
    phidot = np.array([5.0, -19.0, 0.0, 12.0])
    action = env.action_from_setpoints(beta, phidot)
    assert action.dtype == np.float32 and action.shape == (8,)
    b2, p2 = env.setpoints_from_action(action)
    assert np.allclose(b2, beta, atol=1e-6) and np.allclose(p2, phidot, atol=1e-5)
    b3, p3 = setpoints_from_action(action_from_setpoints(beta[None], phidot[None], lim), lim, 4)
    assert b3.shape == (1, 4)
    assert env.measured_phidot.shape == (4,) and env.measured_motor_angles.shape == (4,)
    assert env.track.length > 0 and env.control_period == 0.02


def test_h_state_matches_estimation(geom):
    rng = np.random.default_rng(0)
    for _ in range(50):
        q = rng.uniform(-1.5, 1.5, size=4)
        phidot = rng.uniform(-10, 10, size=4)
        lam, mu, beta_est, qua = h_state_from_measurements(q, phidot, geom)
        lam_ref = estimate_icr(q, geom)
        mu_ref = mu_from_wheel_speeds(lam_ref, phidot, geom)
        lam_c, mu_c = canonical_eta(lam_ref, mu_ref, mu_tol=1e-3)
        assert np.allclose(lam, lam_c, atol=1e-12) and mu == pytest.approx(float(mu_c), abs=1e-12)
        be_ref = steering_from_lambda(lam_ref, geom, singular_fill=q)
        assert np.allclose(beta_est, be_ref, atol=1e-12)
        assert qua == pytest.approx(float(quality(be_ref, q)), abs=1e-12)


def test_rgb_array_rendering_headless():
    pytest.importorskip("pygame")
    env = gym.make("Azimut-v2", render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (640, 640, 3) and frame.dtype == np.uint8 and frame.std() > 0
    env.close()


def test_record_video(tmp_path):
    pytest.importorskip("pygame")
    pytest.importorskip("moviepy")
    from gymnasium.wrappers import RecordVideo

    env = RecordVideo(gym.make("Azimut-v2", render_mode="rgb_array"), str(tmp_path / "videos"),
                      episode_trigger=lambda e: True,
                      disable_logger=True)
    env.reset(seed=0)
    for _ in range(20):
        env.step(env.action_space.sample())
    env.close()
    assert list((tmp_path / "videos").glob("*.mp4"))


def test_obstacles_and_kick_options():
    env = AzimutEnv(track="circle")
    # an obstacle right on the track ahead of the robot
    env.reset(seed=0, options={"obstacles": [(0.6, 0.1, 0.2)], "kick": {"step": 5, "wheels": [0, 2], "impulse": 0.3}})
    assert len(env.physics.obstacles) == 1
    beta0 = None
    for t in range(8):
        _, _, term, _, info = env.step(np.zeros(8, dtype=np.float32))
        if t == 4:
            beta0 = info["beta_true"].copy()
        assert "error" not in info
    assert abs(info["beta_true"][0] - beta0[0]) > 0.05  # knocked
    env.kick([1], -0.3)
    env.reset(seed=0)
    assert len(env.physics.obstacles) == 0
    with pytest.raises(ValueError):
        env.reset(options={"bogus": 1})
    with pytest.raises(ValueError, match="overlap"):
        env.reset(seed=0, options={"obstacles": [(0.1, 0.2, 0.3)]})


def test_constructor_validation():
    with pytest.raises(ValueError):
        AzimutEnv(track="nope")
    with pytest.raises(ValueError):
        AzimutEnv(domain_randomization=2.0)
    with pytest.raises(ValueError):
        AzimutEnv(render_mode="ascii")
    env = AzimutEnv(domain_randomization=0.2, sensors="ideal", control_period=0.04, substeps=20)
    assert env.metadata["render_fps"] == 25
    env.reset(seed=3)
    env.step(env.action_space.sample())


def test_h_state_batch_matches_single(geom):
    from azimut_env.env import h_state_batch

    rng = np.random.default_rng(3)
    q = rng.uniform(-1.5, 1.5, size=(20, 4))
    w = rng.uniform(-10, 10, size=(20, 4))
    lam, mu, be, qua = h_state_batch(q, w, geom)
    for i in range(20):
        l1, m1, b1, q1 = h_state_from_measurements(q[i], w[i], geom)
        assert np.allclose(lam[i], l1, atol=1e-12) and mu[i] == pytest.approx(m1, abs=1e-12)
        assert np.allclose(be[i], b1, atol=1e-12) and qua[i] == pytest.approx(q1, abs=1e-12)


def test_domain_randomization_varies_parameters_per_reset(make_env):
    from azimut_env.physics.engine import WP

    env = make_env(domain_randomization=0.3)
    env.reset(seed=1)
    mu1, k1 = env.physics.wheel_params[0, 0, WP.MU], env.physics.wheel_params[0, 0, WP.K_S]
    m1 = env.physics.chassis[0].mass
    env.reset(seed=2)
    assert env.physics.wheel_params[0, 0, WP.MU] != mu1 and env.physics.wheel_params[0, 0, WP.K_S] != k1
    assert env.physics.chassis[0].mass != m1
    plain = make_env()
    plain.reset(seed=1)
    assert plain.physics.wheel_params[0, 0, WP.MU] == plain.params.tire.friction


def test_steering_encoder_bias_is_constant_per_episode():
    from azimut_env.params import SensorParams

    env = AzimutEnv(sensors=SensorParams(0.0, 0.0, 0.0, 0, 0.0, steer_bias=0.05))
    _, info = env.reset(seed=0)
    d0 = env.measured_beta - info["beta_true"]
    assert np.all(np.abs(d0) > 0)
    for _ in range(5):
        _, _, _, _, info = env.step(np.zeros(8, dtype=np.float32))
    assert np.allclose(env.measured_beta - info["beta_true"], d0, atol=1e-12)
    env.reset(seed=1)
    assert not np.allclose(env.measured_beta - env.physics.steering_angles()[0], d0)


def test_one_front_end_for_both_envs():
    """Both envs take the TaskConfig fields as keywords (their signatures list them, defaults from
    TaskConfig), refuse an unknown keyword by name, and implement their controller Protocol."""
    import dataclasses
    import inspect

    from azimut_env.interface import ControllerInterface, VectorControllerInterface, missing_members
    from azimut_env.task.config import TaskConfig
    from azimut_env.vector_env import AzimutVectorEnv

    for cls in (AzimutEnv, AzimutVectorEnv):
        params = inspect.signature(cls.__init__).parameters
        for f in dataclasses.fields(TaskConfig):
            assert f.name in params
            if f.name != "localisation":
                assert params[f.name].default == getattr(TaskConfig(), f.name)
        with pytest.raises(TypeError, match="progress_wieght"):
            cls(progress_wieght=2.0)
    env, venv = AzimutEnv(reward_weights={"lateral": 0.7}), AzimutVectorEnv(num_envs=2, reward_weights={"lateral": 0.7})
    assert env.config == venv.config == TaskConfig(reward_weights={"lateral": 0.7})
    assert isinstance(env, ControllerInterface) and not missing_members(env, ControllerInterface)
    assert isinstance(venv, VectorControllerInterface) and not missing_members(venv, VectorControllerInterface)
    assert missing_members(venv, ControllerInterface) == ["track"]
