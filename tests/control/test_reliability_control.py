"""Issue 20 (reliability v2), control: the action wrappers check what the env would refuse before
any controller or target state moves; ``PathFollower.reset`` checks its progress."""

from __future__ import annotations

import math

import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

from azimut_env.env import AzimutEnv
from azimut_env.tracks import make_track
from azimut_env.validation import ResetNeeded
from azimut_env.vector_env import AzimutVectorEnv
from control.action_spaces.single import ICRTargetAction, TwistAction
from control.action_spaces.vector import VectorControllerAction
from control.follow.batch import BatchFollower
from control.follow.path_follower import PathFollower


@pytest.mark.parametrize("kind", ["residual", "icr_rate"])
def test_vector_wrapper_refused_step_moves_no_controller_state(kind):
    """The vector action wrappers advanced every robot's controller and target state before
    refusing a step on a sub-env that had ended, so the trajectory differed from one without the
    refused call."""
    def make():
        env = VectorControllerAction(AzimutVectorEnv(num_envs=2, max_episode_steps=3,
                                                     autoreset_mode=AutoresetMode.DISABLED), action=kind)
        env.reset(seed=0)
        return env

    env, ref = make(), make()
    acts = np.random.default_rng(0).uniform(-1, 1, (8,) + env.action_space.shape).astype(np.float32)
    for e in (env, ref):  # sub-env 1 ends at the third step, sub-env 0 (reset after two) goes on
        e.step(acts[0])
        e.step(acts[1])
        e.reset(options={"reset_mask": np.array([True, False])})
        assert e.step(acts[2])[3].tolist() == [False, True]
    with pytest.raises(RuntimeError, match=r"sub-envs \[1\] ended"):
        env.step(acts[3])
    for e in (env, ref):
        e.reset(options={"reset_mask": np.array([False, True])})
    for a in acts[4:6]:  # sub-env 0 ends at the second
        got, want = env.step(a), ref.step(a)
        assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])


@pytest.mark.parametrize("cls", [ICRTargetAction, TwistAction])
def test_single_wrapper_refused_step_moves_no_controller_state(cls):
    env, ref = cls(AzimutEnv()), cls(AzimutEnv())
    env.reset(seed=1)
    ref.reset(seed=1)
    acts = np.random.default_rng(1).uniform(-1, 1, (6,) + env.action_space.shape).astype(np.float32)
    env.step(acts[0])
    ref.step(acts[0])
    env.unwrapped._done_error = "a physics failure (simulated)"  # the env refuses every step now
    with pytest.raises(ResetNeeded):
        env.step(acts[1])
    env.unwrapped._done_error = None
    for a in acts[1:]:
        assert np.array_equal(env.step(a)[0], ref.step(a)[0])


@pytest.mark.parametrize("progress, error", [(math.nan, ValueError), (math.inf, ValueError), (1e9, ValueError),
                                             (-0.5, ValueError), (True, TypeError), (np.True_, TypeError),
                                             ("1", TypeError), (10**400, ValueError)])
def test_path_follower_reset_progress_checked(progress, error):
    """``PathFollower.reset(progress=nan | inf | 1e9)`` was accepted and the next step reported
    the lap finished; ``progress=True`` was taken as 1."""
    track = make_track("paper")  # an open track
    follower = PathFollower(track)
    follower.reset(2.0)
    with pytest.raises(error, match="progress"):
        follower.reset(progress)
    assert follower.progress == 2.0  # unchanged by the refusal
    batch = BatchFollower(1)
    with pytest.raises(error, match="progress"):
        batch.reset(0, track, progress)


def test_path_follower_reset_progress_on_a_closed_track():
    track = make_track("circle")  # progress counts laps there: within one lap either way of the start
    follower = PathFollower(track)
    follower.reset(-0.01)  # just before the start line
    assert follower.progress == -0.01
    with pytest.raises(ValueError, match="off the track"):
        follower.reset(track.length * 3 + 1.25)
    follower.reset(np.float32(2.0))
    assert type(follower.progress) is float and follower.progress == 2.0
    follower.reset(None)
    assert follower.progress is None
