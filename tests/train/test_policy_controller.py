"""A trained policy as a controller (``train.policy.PolicyController``): the episode loop drives
the env with it through the same code as training (the action spaces' ActionController), its
raw commands are what the env applies, and a policy's spec is named after its run folder or by
``NAME=``. A stand-in model (``predict`` as SB3's) keeps these tests free of torch."""

from __future__ import annotations

import json

import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

from azimut_env.vector_env import AzimutVectorEnv
from control.action_spaces.vector import VectorControllerAction
from control.controller import Controller
from control.rollout import run_episode, run_episodes
from train.policy import PolicyController, TrainedPolicy, policy_name


class RandomModel:
    """SB3's ``predict(obs, deterministic)`` with seeded uniform actions of ``size``."""

    def __init__(self, size: int, seed: int = 0, scale: float = 1.0) -> None:
        self.size, self.rng, self.scale = size, np.random.default_rng(seed), scale

    def predict(self, obs, deterministic=True):
        return (self.scale * self.rng.uniform(-1.2, 1.2, (obs.shape[0], self.size))).astype(np.float32), None


def _policy(action: str, size: int, seed: int = 0, scale: float = 1.0) -> TrainedPolicy:
    return TrainedPolicy(model=RandomModel(size, seed, scale), algo="ppo", action=action, env_kwargs={})


def test_a_policy_is_a_controller():
    ctl = PolicyController(_policy("raw", 8), "p")
    assert isinstance(ctl, Controller) and ctl.name == "p" and ctl.env_kwargs == {}
    with pytest.raises(ValueError, match="unknown action space"):
        PolicyController(TrainedPolicy(model=None, algo="ppo", action="nope"), "p")


@pytest.mark.parametrize("action, kind", [("residual", "residual"), ("icr-rate", "icr_rate")])
def test_policy_rollout_is_the_training_wrapper_step_for_step(action, kind):
    """The loop with the policy's controller sends the env what ``VectorControllerAction`` (the
    training env) sends for the same actions: the same observations, bit for bit."""
    steps = 60
    log = run_episode(PolicyController(_policy(action, 3, seed=4), "p"), "crab", seed=2, max_time=steps * 0.02)
    venv = AzimutVectorEnv(num_envs=1, track="crab", autoreset_mode=AutoresetMode.DISABLED, time_limit_factor=0.0)
    from azimut_env.tracks import make_track

    wrapped = VectorControllerAction(venv, action=kind)
    obs, _ = wrapped.reset(seed=2, options={"track": make_track("crab", rng=np.random.default_rng(2))})
    model = RandomModel(3, seed=4)
    for k in range(steps):
        a = model.predict(obs)[0]
        obs, _, term, trunc, info = wrapped.step(a)
        np.testing.assert_array_equal(info["pose"][0], log.pose[k])
        assert int(info["controller_mode"][0]) == int(log.mode[k])
        assert bool(info["limit_exceeded"][0]) == bool(log.violations[k])
        if term[0] or trunc[0]:
            break
    assert log.t.size == steps and log.beta_rate.shape == (steps, 4)


def test_raw_policy_commands_are_what_the_env_applies():
    """Raw actions go to the env as they are; the logged set-points and their finite differences
    are those of the clipped action the env applied (the observation's previous action)."""
    ctl = PolicyController(_policy("raw", 8, seed=1, scale=0.3), "raw")
    env = AzimutVectorEnv(num_envs=2, track="circle", autoreset_mode=AutoresetMode.DISABLED, time_limit_factor=0.0)
    obs, _ = env.reset(seed=[0, 1])
    ctl.reset(env, np.arange(2))
    prev_beta = env.setpoints_from_action(env.task.prev_action)[0]
    for _ in range(5):
        cmd = ctl.act(env, obs)
        assert cmd.action.dtype == np.float32 and cmd.mode is None and cmd.events is None
        obs, *_ = env.step(cmd.action)
        beta, phidot = env.setpoints_from_action(env.task.prev_action)
        np.testing.assert_array_equal(cmd.beta, beta)
        np.testing.assert_array_equal(cmd.phidot, phidot)
        np.testing.assert_array_equal(cmd.beta_rate, (beta - prev_beta) / env.control_period)
        prev_beta = beta
    env.close()


def test_policies_in_a_batch_end_on_their_own():
    logs = run_episodes(PolicyController(_policy("residual", 3, scale=0.0), "zero"), ["crab", "circle"], [0, 1],
                        max_time=1.0)
    assert [log.controller for log in logs] == ["zero", "zero"] and all(log.t.size == 50 for log in logs)
    assert all(log.error is None and np.isfinite(log.ret) for log in logs)


def test_policy_names(tmp_path):
    run = tmp_path / "my_run"
    run.mkdir()
    (run / "run.json").write_text(json.dumps({"algo": "ppo"}))
    assert policy_name(str(run / "model.zip")) == ("my_run", run / "model.zip")
    assert policy_name(str(run)) == ("my_run", run)
    ckpt = run / "checkpoints"
    ckpt.mkdir()
    assert policy_name(str(ckpt / "model_2048_steps.zip"))[0] == "my_run"  # the folder of run.json
    assert policy_name(f"short={run}") == ("short", run)
    assert policy_name(str(tmp_path / "a=b" / "model.zip"))[0] == "a=b"  # '/' in front of '=': a path
