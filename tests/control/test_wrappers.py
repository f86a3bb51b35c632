"""RL action-space wrappers: ICR targets and twists through the controllers."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import azimut_env  # noqa: F401  (registers Azimut-v1)
from control.action_spaces.single import ICRTargetAction, TwistAction


def _rollout(wrapper_cls, actions, seed=0, **kw):
    env = wrapper_cls(gym.make("Azimut-v2", track="circle"), **kw)
    obs, _ = env.reset(seed=seed)
    out = [obs]
    infos = []
    for a in actions:
        obs, r, term, trunc, info = env.step(a)
        assert env.observation_space.contains(obs)
        assert np.isfinite(r)
        out.append(obs)
        infos.append(info)
    env.close()
    return np.array(out), infos


@pytest.mark.parametrize("wrapper_cls,kw,dim", [(ICRTargetAction, {}, 4), (TwistAction, {}, 3),
                                                (TwistAction, {"controller": "swerve"}, 3)])
def test_wrappers_step_deterministically(wrapper_cls, kw, dim):
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, size=(40, dim)).astype(np.float32)
    a, infos = _rollout(wrapper_cls, actions, **kw)
    b, _ = _rollout(wrapper_cls, actions, **kw)
    np.testing.assert_array_equal(a, b)
    if wrapper_cls is ICRTargetAction or kw.get("controller", "icr") == "icr":
        assert not any(i["limit_exceeded"] for i in infos)  # the ICR controller keeps every limit


def test_icr_target_moves_the_robot_along_the_target():
    env = ICRTargetAction(gym.make("Azimut-v2", track="circle"), mu_max=0.5)
    env.reset(seed=0)
    base = env.unwrapped
    start = base.true_pose.copy()
    for _ in range(150):  # λ = (0, 1, 0): translation along +x of the chassis at μ = 0.5 m/s
        env.step(np.array([0.0, 1.0, 0.0, 1.0], dtype=np.float32))
    d = base.true_pose[:2] - start[:2]
    c, s = np.cos(start[2]), np.sin(start[2])
    body = np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1]])
    assert body[0] > 0.5 and abs(body[1]) < 0.1 * body[0]


def test_wrappers_reject_bad_actions():
    env = TwistAction(gym.make("Azimut-v2", track="circle"))
    env.reset(seed=0)
    with pytest.raises(ValueError):
        env.step(np.array([np.nan, 0, 0], dtype=np.float32))
    with pytest.raises(ValueError):
        TwistAction(gym.make("Azimut-v2"), controller="pid")


@pytest.mark.parametrize("k", range(4))
def test_singular_icr_targets_in_the_simulator(k):
    """An ICR exactly on steering axis k, then its antipode with μ swapped, then μ far beyond the
    limits: commands stay finite and within limits, the robot stays healthy."""
    from estimation import RobotGeometry

    s = RobotGeometry.azimut3().s_unit[k]
    env = ICRTargetAction(gym.make("Azimut-v2", track="circle"), mu_max=5.0)
    env.reset(seed=k)
    for a in [np.r_[s, 0.2]] * 60 + [np.r_[-s, -0.2]] * 30 + [np.r_[s, 1.0]] * 60:
        obs, r, term, trunc, info = env.step(a.astype(np.float32))
        assert np.all(np.isfinite(obs)) and "error" not in info
        assert not info["limit_exceeded"]
