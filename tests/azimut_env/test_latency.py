"""Command latency (``action_latency``): a per-robot FIFO of set-points in the task."""

from __future__ import annotations

import numpy as np
import pytest
from test_vector_env import _run_equivalence  # tests/ is on sys.path (pytest rootdir-relative import)

from azimut_env.env import AzimutEnv
from azimut_env.params import RobotParams, setpoints_from_action
from azimut_env.task.core import AzimutTask, TaskConfig

PARAMS = RobotParams()


def _actions(steps, seed=3):
    rng = np.random.default_rng(seed)
    a = np.clip(rng.normal(0.0, 0.3, (steps, 8)) + np.r_[np.zeros(4), np.full(4, 0.5)], -1, 1)
    return a.astype(np.float32)


@pytest.mark.parametrize("k", [1, 3])
def test_latency_shifts_the_response_by_exactly_k_steps(k):
    """Robot with latency k fed a[0..T) against a robot without latency that holds its reset
    set-points for k steps and is then fed the same a[0..T): the same physics, bit for bit."""
    seq = _actions(40)
    late = AzimutTask(PARAMS, TaskConfig(action_latency=k))
    now = AzimutTask(PARAMS, TaskConfig())
    for task in (late, now):
        task.reset_robot(0, np.random.default_rng(7), fresh_space=True)
    hist_late, hist_now = [], []
    for t in range(len(seq) + k):
        late.apply_actions(seq[min(t, len(seq) - 1)][None])
        late.step_physics()
        hist_late.append(late.physics.summary[0].copy())
        if t >= k:
            now.apply_actions(seq[t - k][None])
        now.step_physics()
        hist_now.append(now.physics.summary[0].copy())
    hist_late, hist_now = np.array(hist_late), np.array(hist_now)
    assert np.array_equal(hist_late, hist_now)
    # and the response does move: the robot is not at rest
    assert np.ptp(hist_late[:, 0]) > 0.01


def test_applied_set_points_are_those_of_k_steps_before_and_reset_empties_the_queue():
    k = 2
    env = AzimutEnv(action_latency=k, sensors="ideal")
    env.reset(seed=1)
    phys = env.unwrapped.task.physics
    held = phys.commands[0].copy()
    seq = _actions(8)
    for t, a in enumerate(seq):
        env.step(a)
        if t < k:
            assert np.array_equal(phys.commands[0], held)
        else:
            beta, phidot = setpoints_from_action(seq[t - k], PARAMS.limits, 4)
            assert np.allclose(phys.commands[0, :, 0], beta) and np.allclose(phys.commands[0, :, 1], phidot)
    env.reset(seed=2)
    held = phys.commands[0].copy()
    for a in seq[:k]:
        env.step(a)
        assert np.array_equal(phys.commands[0], held)  # nothing of the last episode comes out


def test_latency_zero_is_the_default_and_unchanged():
    a, b = AzimutEnv(), AzimutEnv(action_latency=0)
    oa, _ = a.reset(seed=4)
    ob, _ = b.reset(seed=4)
    for act in _actions(20):
        ra = a.step(act)
        rb = b.step(act)
        assert np.array_equal(ra[0], rb[0]) and ra[1] == rb[1]


def test_refused_action_leaves_the_queue_alone():
    env = AzimutEnv(action_latency=2)
    env.reset(seed=0)
    task = env.unwrapped.task
    fifo = task.commands.fifo.copy()
    bad = np.full(8, np.nan, dtype=np.float32)
    with pytest.raises(ValueError):
        env.step(bad)
    assert np.array_equal(task.commands.fifo, fifo)


def test_vector_env_with_latency_matches_single_envs():
    counts = _run_equivalence(3, 200, 60, seed=12, track="random", max_lateral_error=0.15, action_latency=2)
    assert counts["resets"] >= 3


def test_latency_is_validated():
    for bad in (-1, 1.5, "2"):
        with pytest.raises((ValueError, TypeError)):
            TaskConfig(action_latency=bad)
    with pytest.raises((ValueError, TypeError)):
        AzimutEnv(action_latency=-2)


def test_pickled_env_keeps_its_queue():
    import pickle

    env = AzimutEnv(action_latency=3)
    env.reset(seed=5)
    seq = _actions(12)
    for a in seq[:5]:
        env.step(a)
    clone = pickle.loads(pickle.dumps(env))
    for a in seq[5:]:
        r1, r2 = env.step(a), clone.step(a)
        assert np.array_equal(r1[0], r2[0]) and r1[1] == r2[1]
