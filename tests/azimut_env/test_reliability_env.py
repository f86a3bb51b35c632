"""Regression tests of issue 10 for the envs: bad input is refused where it enters (constructor,
``reset`` option, ``step``), with ``ValueError``/``TypeError``/``ResetNeeded``, and a refused input
changes no state (the next good call behaves as if the bad one had never happened)."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

from azimut_env.env import AzimutEnv
from azimut_env.task.core import TaskConfig
from azimut_env.tracks import Track, make_track
from azimut_env.validation import ResetNeeded


def rollout(env, seed=3, steps=8, options=None):
    obs, _ = env.reset(seed=seed, options=options)
    out = [obs]
    rng = np.random.default_rng(0)
    for _ in range(steps):
        obs, r, term, trunc, _ = env.step(rng.uniform(-1, 1, env.action_space.shape).astype(np.float32))
        out.append(np.append(obs, r))
    return np.array(out[1:])


@pytest.fixture(scope="module")
def reference():
    """``rollout`` of a fresh default env (the episode every refused call must leave intact)."""
    env = AzimutEnv()
    out = rollout(env)
    env.close()
    return out


def test_reset_needed_is_gymnasium_and_runtime_error():
    assert issubclass(ResetNeeded, gym.error.ResetNeeded) and issubclass(ResetNeeded, RuntimeError)


def test_unwrapped_env_refuses_step_and_kick_before_reset(env, zero_action):
    with pytest.raises(ResetNeeded):
        env.step(zero_action)
    with pytest.raises(ResetNeeded):
        env.kick([0], 0.1)


@pytest.mark.parametrize("kick, err", [
    ({"wheels": [7], "impulse": 0.5}, ValueError),
    ({"wheels": [1.0], "impulse": 0.5}, TypeError),
    ({"wheels": ["1"], "impulse": 0.5}, TypeError),
    ({"wheels": "01", "impulse": 0.5}, TypeError),
    ({"wheels": [0, 0], "impulse": 0.5}, ValueError),
    ({"wheels": [True], "impulse": 0.5}, TypeError),
    ({"wheels": [0], "impulse": float("nan")}, ValueError),
    ({"wheels": [0], "impulse": "big"}, TypeError),
    ({"step": -1}, ValueError),
    ({"step": 2.5}, ValueError),
    ({"bogus": 1}, ValueError),
    ([0, 1], TypeError),
])
def test_bad_kick_refused_at_reset_and_changes_nothing(kick, err, env, zero_action, reference):
    env.reset(seed=11)
    before = env.true_pose.copy()
    with pytest.raises(err):
        env.reset(seed=99, options={"kick": kick})
    assert np.array_equal(env.true_pose, before)  # the refused reset changed nothing...
    env.step(zero_action)  # ...and the running episode goes on
    assert np.array_equal(rollout(env), reference)


def test_good_kick_option_still_works(env, reference):
    a = rollout(env, options={"kick": {"step": 2, "wheels": [np.int64(1), 3], "impulse": 0.2}})
    assert np.all(np.isfinite(a)) and not np.array_equal(a, reference)


@pytest.mark.parametrize("options, err", [
    ({"start_progress": float("nan")}, ValueError),
    ({"start_progress": "1"}, TypeError),
    ({"track": "nope"}, ValueError),
    ({"track": 3}, TypeError),
    ({"obstacles": [(1.0, "a", 0.1)]}, ValueError),
    ({"obstacles": 5}, TypeError),
    ({"obstacles": [(1.0, 1.0, -0.1)]}, ValueError),
    ({"unknown": 1}, ValueError),
    ("paper", TypeError),
    ({"start_progress": -5.0}, ValueError),  # paper is open: [0, length]; was clamped silently
    ({"start_progress": 1e9}, ValueError),
    ({"track": "crab", "start_progress": 4.8}, ValueError),
])
def test_bad_reset_options_refused_without_side_effects(options, err, env, zero_action, reference):
    with pytest.raises(err):
        env.reset(seed=5, options=options)
    with pytest.raises(ResetNeeded):  # a refused first reset leaves it un-reset
        env.step(zero_action)
    assert np.array_equal(rollout(env), reference)


@pytest.mark.parametrize("seed", [-1, 1.5, "3", True])
def test_bad_seed_refused(seed, env):
    with pytest.raises((ValueError, TypeError)):
        env.reset(seed=seed)


def test_failed_reset_refuses_step_until_a_reset_succeeds(env, zero_action, reference):
    env.reset(seed=0)
    start = make_track("paper").sample(0.0)
    with pytest.raises(ValueError, match="overlap"):
        env.reset(seed=1, options={"obstacles": [(float(start[0]), float(start[1]), 0.3)]})
    for _ in range(3):
        with pytest.raises(ResetNeeded):
            env.step(zero_action)
    assert np.array_equal(rollout(env), reference)


def test_failed_reset_without_seed_does_not_consume_the_generator(make_env):
    a, b = make_env(), make_env()
    a.reset(seed=4)
    b.reset(seed=4)
    start = make_track("paper").sample(0.0)
    with pytest.raises(ValueError):
        a.reset(options={"obstacles": [(float(start[0]), float(start[1]), 0.3)]})
    oa, _ = a.reset()
    ob, _ = b.reset()
    assert np.array_equal(oa, ob)


def test_track_named_like_a_builtin_does_not_replace_it(env, make_env):
    paper = make_track("paper")
    fake = Track("paper", np.array([[0.0, 0.0], [5.0, 0.0]]), 0.0, 0.5)
    env.reset(seed=0, options={"track": fake})
    assert env.track is fake
    env.reset(seed=0)
    assert env.track.length == pytest.approx(paper.length) and env.track is not fake
    fake_circle = Track("circle", np.array([[0.0, 0.0], [3.0, 0.0]]), 0.0, 0.5)
    env2 = make_env(track="circle")
    env2.reset(seed=0, options={"track": fake_circle})
    env2.reset(seed=0)
    assert env2.track.length == pytest.approx(make_track("circle").length)


def test_track_far_from_origin_refused_where_it_enters(env):
    far = Track("far", np.array([[1e5, 0.0], [1e5 + 5, 0.0]]), 0.0, 0.5)
    with pytest.raises(ValueError, match="translate"):
        AzimutEnv(track=far)
    with pytest.raises(ValueError, match="translate"):
        env.reset(options={"track": far})


@pytest.mark.parametrize("kwargs", [
    dict(control_period=float("nan")), dict(control_period=0.0), dict(substeps=0), dict(substeps=2.5),
    dict(solver_iterations=-1), dict(domain_randomization=float("nan")), dict(reward_weights={"lateral": -1.0}),
    dict(max_lateral_error=float("inf")), dict(lookahead_count=0), dict(lookahead_spacing=float("nan")),
    dict(start_noise=-0.1), dict(noise_scale=float("nan")), dict(sensors="perfect"), dict(sensors=3),
    dict(params="default"), dict(track=None), dict(obstacles=[(0.0, 0.0, float("nan"))]),
    dict(render_mode="video"), dict(reward_weights={"progress": "1"}), dict(reward_weights={"slipp": 1.0}),
    dict(reward_weights=[("slip", 1.0)]), dict(reward_weights={"slip": float("nan")}),
])
def test_constructor_refuses_bad_kwargs(kwargs):
    with pytest.raises((ValueError, TypeError)):
        AzimutEnv(**kwargs)


def test_task_config_stores_canonical_types():
    cfg = TaskConfig(substeps=np.int64(4), control_period=np.float32(0.02), lookahead_count=3.0)
    assert type(cfg.substeps) is int and type(cfg.control_period) is float and cfg.lookahead_count == 3


# ---------------------------------------------------------------------- vector env


def test_vector_bad_kick_in_one_sub_env_is_refused_before_any_reset(make_vector_env):
    env = make_vector_env(num_envs=3)
    env.reset(seed=0)
    pose = env.true_pose.copy()
    with pytest.raises(ValueError):
        env.reset(seed=1, options=[None, {"kick": {"wheels": [7]}}, None])
    assert np.array_equal(env.true_pose, pose)  # sub-env 0 was not reset either
    env.step(np.zeros((3, 8), np.float32))


def test_vector_first_reset_with_mask_is_refused_then_works(make_vector_env):
    env = make_vector_env(num_envs=3)
    with pytest.raises(ValueError, match="not been reset"):
        env.reset(seed=0, options={"reset_mask": np.array([True, False, True])})
    with pytest.raises(ResetNeeded):
        env.step(np.zeros((3, 8), np.float32))
    env.reset(seed=0)
    env.step(np.zeros((3, 8), np.float32))
    obs, *_ = env.reset(options={"reset_mask": np.array([False, True, False])})
    env.step(np.zeros((3, 8), np.float32))


def test_vector_failed_reset_refuses_step(make_vector_env):
    start = make_track("paper").sample(0.0)
    env = make_vector_env(num_envs=2, obstacles=[(float(start[0]), float(start[1]), 0.3)])
    with pytest.raises(ValueError, match="overlap"):
        env.reset(seed=0)
    with pytest.raises(ResetNeeded):
        env.step(np.zeros((2, 8), np.float32))
    with pytest.raises(ResetNeeded):
        env.kick(0, [0], 0.1)


@pytest.mark.parametrize("seed", [-1, [0, "a"], [0], "7", 2.0])
def test_vector_bad_seed_refused(seed, make_vector_env):
    with pytest.raises((ValueError, TypeError)):
        make_vector_env(num_envs=2).reset(seed=seed)


def test_vector_sub_env_matches_single_after_refused_resets(make_env, make_vector_env):
    single = rollout(make_env(), seed=7)
    env = make_vector_env(num_envs=2)
    for bad in ({"kick": {"wheels": [9]}}, [None, {"start_progress": math.inf}], {"track": object()}):
        with pytest.raises((ValueError, TypeError)):
            env.reset(seed=0, options=bad)
    env.reset(seed=7)
    rng = np.random.default_rng(0)
    rows = []
    for _ in range(8):
        a = rng.uniform(-1, 1, 8).astype(np.float32)
        obs, r, *_ = env.step(np.stack([a, a]))
        rows.append(np.append(obs[0], r[0]))
    assert np.array_equal(np.array(rows), single)


def test_step_refuses_complex_and_object_actions(env):
    env.reset(seed=0)
    with pytest.raises(TypeError):
        env.step(np.zeros(8, complex))
    with pytest.raises(TypeError):
        env.step(np.array(["a"] * 8))
    with pytest.raises(ValueError):
        env.step(np.full(8, 1e300))  # beyond float32: inf


@pytest.mark.parametrize("bad", [{"seed": -1}, {"seed": 0, "options": {"kick": {"wheels": [7], "impulse": 1.0}}}])
def test_refused_first_reset_through_gym_make_leaves_the_next_good_episode_intact(bad):
    """Through ``gymnasium.make`` (the documented path), a refused first reset changes nothing:
    the next good reset and step replay an env that never saw it (Gymnasium's passive checker
    used to be left without data by the refused reset and raised a TypeError at the first step)."""
    env, ref = gym.make("Azimut-v2"), gym.make("Azimut-v2")
    with pytest.raises(ValueError):
        env.reset(**bad)
    obs, _ = env.reset(seed=0)
    obs_ref, _ = ref.reset(seed=0)
    np.testing.assert_array_equal(obs, obs_ref)
    action = np.zeros(env.action_space.shape, dtype=env.action_space.dtype)
    out, out_ref = env.step(action), ref.step(action)
    np.testing.assert_array_equal(out[0], out_ref[0])
    assert out[1] == out_ref[1]
    env.close()
    ref.close()


def test_start_progress_on_a_closed_track_wraps_modulo_its_length(make_env):
    """New-user trial: on ``circle`` start_progress 1e9 was not wrapped and the episode ended
    after one step; now a lap later is the same place (the env docstring's reset options)."""
    from azimut_env.tracks import make_track

    length = make_track("circle").length
    a, b = make_env(track="circle"), make_env(track="circle")
    far = 1e6 * length + 2.0
    obs_far, _ = a.reset(seed=1, options={"start_progress": far})
    obs_near, _ = b.reset(seed=1, options={"start_progress": far % length})
    assert np.allclose(obs_far, obs_near)
    obs_neg, _ = b.reset(seed=1, options={"start_progress": 2.0 - length})
    assert np.allclose(obs_neg, a.reset(seed=1, options={"start_progress": 2.0})[0], atol=1e-9)
    for _ in range(5):
        *_, term, trunc, _ = a.step(np.zeros(a.action_space.shape, np.float32))
        assert not (term or trunc)


def test_start_progress_on_an_open_track_is_kept_inside_it(make_env):
    env = make_env(track="paper")
    from azimut_env.tracks import make_track

    length = make_track("paper").length
    env.reset(seed=0, options={"start_progress": length})  # the end itself is allowed
    env.reset(seed=0, options={"start_progress": 0.0})
    with pytest.raises(ValueError, match=r"start_progress.*\[0, "):
        env.reset(seed=0, options={"start_progress": length + 0.01})


def test_vector_option_errors_name_the_sub_env(make_vector_env):
    """New-user trial: with a per-env options list the error did not say which sub-env."""
    env = make_vector_env(num_envs=3)
    with pytest.raises(ValueError, match=r"options\[2\] \(sub-env 2\).*start_progress"):
        env.reset(seed=0, options=[None, {}, {"start_progress": -1.0}])
    with pytest.raises(TypeError, match=r"options\[1\] \(sub-env 1\)"):
        env.reset(seed=0, options=[None, {"kick": 3}, None])
