"""The compiled twist baseline (``SwerveBatch``) against the NumPy reference (``SwerveController``
per robot), bit for bit on recorded episodes."""

from __future__ import annotations

import numpy as np
import pytest

from control.twist.wpilib import SwerveBatch, SwerveConfig, SwerveController


class _Recorder:
    def __init__(self, monkeypatch):
        self.calls: list = []
        self.batches: list = []
        rec = self
        step, reset = SwerveBatch.step, SwerveBatch.reset

        def recording_step(batch, rows, twists, beta_meas):
            if batch not in rec.batches:
                rec.batches.append(batch)
            cmd = step(batch, rows, twists, beta_meas)
            rec.calls.append(("step", batch, rows, np.array(twists), np.array(beta_meas), cmd))
            return cmd

        def recording_reset(batch, rows, beta, phidot):
            rec.calls.append(("reset", batch, np.array(rows), np.array(beta), np.array(phidot)))
            return reset(batch, rows, beta, phidot)

        monkeypatch.setattr(SwerveBatch, "step", recording_step)
        monkeypatch.setattr(SwerveBatch, "reset", recording_reset)


def _check(rec: _Recorder) -> int:
    """Replay every robot's calls through its own SwerveController; return the steps checked."""
    checked = 0
    for batch in rec.batches:
        ref = [None] * batch.num
        for call in rec.calls:
            if call[1] is not batch:
                continue
            if call[0] == "reset":
                for k, i in enumerate(call[2]):
                    ref[i] = SwerveController(batch.geom, batch.limits, batch.dt, batch.config)
                    ref[i].reset(call[3][k], call[4][k])
                continue
            rows, twists, beta_meas, cmd = call[2:]
            idx = np.arange(batch.num) if rows is None else np.asarray(rows)
            for k, i in enumerate(idx):
                want = ref[i].step(twists[k], beta_meas[k])
                for name in ("beta", "phidot", "beta_rate", "beta_accel", "phiddot"):
                    np.testing.assert_array_equal(getattr(cmd, name)[k], getattr(want, name), err_msg=name)
                np.testing.assert_array_equal(cmd.info["twist"][k], want.info["twist"])
                checked += 1
    return checked


def test_eval_twist_episodes_bit_for_bit(monkeypatch):
    from control.path_controllers import TwistPathController
    from control.rollout import run_episodes

    rec = _Recorder(monkeypatch)
    run_episodes(TwistPathController(), ["square", "crab", "figure8"], [0, 1, 2], max_time=8.0,
                 kicks=[None, {"step": 50, "wheels": [1], "impulse": -0.9}, None])
    assert _check(rec) == 3 * 400


def test_unlimited_steering_bit_for_bit(monkeypatch):
    from control.path_controllers import TwistPathController
    from control.rollout import run_episodes

    rec = _Recorder(monkeypatch)
    run_episodes(TwistPathController(), ["square", "figure8"], [0, 1], max_time=8.0, env_kwargs={"robot": "swerve"})
    assert _check(rec) == 2 * 400


@pytest.mark.parametrize("config", [SwerveConfig(), SwerveConfig(discretize=False, optimize=False, coupling=True,
                                                                  cosine_compensation=False, desaturate=False,
                                                                  offset_correction=False, speed_deadband=0.0)])
def test_random_twists_through_the_action_space_bit_for_bit(monkeypatch, config):
    from gymnasium.vector import AutoresetMode

    from azimut_env.vector_env import AzimutVectorEnv
    from control.action_spaces.vector import VectorControllerAction

    rec = _Recorder(monkeypatch)
    env = VectorControllerAction(AzimutVectorEnv(num_envs=3, track="random", autoreset_mode=AutoresetMode.SAME_STEP,
                                                 max_episode_steps=40), action="twist", controller="swerve",
                                 swerve_config=config)
    env.reset(seed=1)
    rng = np.random.default_rng(2)
    for _ in range(100):
        env.step(rng.uniform(-1, 1, env.action_space.shape))
    assert _check(rec) == 300


def test_the_batch_refuses_bad_input(geom, limits):
    batch = SwerveBatch(2, geom, limits)
    with pytest.raises(RuntimeError, match="never reset"):
        batch.step(None, np.zeros((2, 3)), np.zeros((2, geom.n)))
    batch.reset([0, 1], np.zeros((2, geom.n)), np.zeros((2, geom.n)))
    before = batch.beta.copy()
    with pytest.raises(ValueError, match="twist must be finite"):
        batch.step(None, np.array([[0.0, np.nan, 0.0], [0.0, 0.0, 0.0]]), np.zeros((2, geom.n)))
    with pytest.raises(ValueError, match="beta_meas must be finite"):
        batch.step([1], np.zeros((1, 3)), np.full((1, geom.n), np.inf))
    with pytest.raises(ValueError, match="shape"):
        batch.step(None, np.zeros((1, 3)), np.zeros((2, geom.n)))
    np.testing.assert_array_equal(batch.beta, before)


def test_limit_exceeded_is_limit_violations_any(limits):
    from control.limits import limit_exceeded, limit_violations

    rng = np.random.default_rng(3)
    scales = (limits.steer_rate_max, limits.steer_accel_max, limits.wheel_speed_max, limits.wheel_accel_max)
    vals = [rng.normal(0, 0.3 * s, (500, 4)) for s in scales]
    want = limit_violations(*vals, limits).any(axis=-1)
    np.testing.assert_array_equal(limit_exceeded(*vals, limits), want)
    assert 0 < want.sum() < 500
