"""The compiled batch follower (``BatchFollower``) against the NumPy reference (one
``PathFollower`` per robot), bit for bit: on random poses along every built-in track, and on
recorded closed-loop episodes (``azimut eval``'s icr and twist controllers on tracks and
scenarios, kicks, holds, odometry poses, another robot; the residual action space)."""

from __future__ import annotations

import functools

import numpy as np
import pytest

from azimut_env.tracks import TRACK_NAMES, Track, make_track
from control.follow.batch import BatchFollower
from control.follow.path_follower import PathFollower, PathFollowerConfig
from control.icr.controller import reference_stop_mask
from estimation.geometry import RobotGeometry

_FIELDS = ("twist", "lam", "mu", "progress", "finished", "holding")


def _assert_same(got, k: int, want, where: str) -> None:
    for name in _FIELDS:
        np.testing.assert_array_equal(getattr(got, name)[k], getattr(want, name), err_msg=f"{name} {where}")


@pytest.mark.parametrize("with_stops", [False, True])
def test_random_poses_on_every_track_bit_for_bit(with_stops):
    geom = RobotGeometry.azimut3()
    mask = functools.partial(reference_stop_mask, geom=geom) if with_stops else None
    tracks = [make_track(name, rng=np.random.default_rng(3)) for name in TRACK_NAMES]
    tracks.append(Track("held", [[0, 0], [1, 0], [2, 0.5]], 0.0, 0.4, holds=((0.8, 0.3), (1.5, 0.1))))
    config = PathFollowerConfig(speed_scale=1.3, k_int=0.0)
    singles = [PathFollower(t, config if i % 2 else None, stop_mask=mask) for i, t in enumerate(tracks)]
    batch = BatchFollower(len(tracks), stop_mask=mask)
    rng = np.random.default_rng(0)
    for i, (t, f) in enumerate(zip(tracks, singles)):
        start = None if i == 0 else 0.0  # no progress: the first step searches the whole track
        f.reset(start)
        batch.reset(i, t, start, config if i % 2 else None)
    for k in range(400):
        poses = np.array([np.asarray(t.sample(min(0.01 * k, 0.999 * t.length)))[:3] for t in tracks])
        poses += rng.normal(0.0, 0.02, poses.shape)
        rows = np.arange(len(tracks)) if k % 3 else np.arange(1, len(tracks), 2)  # some steps: some robots
        got = batch.step_all(poses, rows)
        for j, i in enumerate(rows):
            _assert_same(got, j, singles[i].step(poses[i]), f"robot {i} step {k}")
    np.testing.assert_array_equal(batch.progress, [f.progress for f in singles])


class _Recorder:
    """Records every reset and step of the BatchFollowers created while it is installed."""

    def __init__(self, monkeypatch):
        self.calls: list = []
        rec = self
        run, reset = BatchFollower._run, BatchFollower.reset

        def recording_step(batch, poses, rows=None):  # every step (step_all and step) runs the kernel here
            out = run(batch, poses, rows)
            rec.calls.append(("step", batch, np.array(poses), None if rows is None else np.array(rows),
                              BatchFollower.outputs(out.copy())))
            return out

        def recording_reset(batch, i, track, progress, config=None, extra_stops=None):
            rec.calls.append(("reset", batch, i, track, progress, config or batch.config, extra_stops))
            return reset(batch, i, track, progress, config, extra_stops=extra_stops)

        monkeypatch.setattr(BatchFollower, "_run", recording_step)
        monkeypatch.setattr(BatchFollower, "reset", recording_reset)

    def check(self) -> int:
        """Replay every robot's calls through its own PathFollower; return the steps checked."""
        refs: dict = {}
        checked = 0
        for call in self.calls:
            batch = call[1]
            if call[0] == "reset":
                _, _, i, track, progress, config, extra = call
                f = PathFollower(track, config, stop_mask=batch.stop_mask, dt=batch.dt, extra_stops=extra)
                f.reset(progress)
                refs[(id(batch), i)] = f
                continue
            _, _, poses, rows, out = call
            idx = np.arange(batch.num) if rows is None else rows
            for k, i in enumerate(idx):
                _assert_same(out, k, refs[(id(batch), int(i))].step(poses[i]), f"robot {i}")
                checked += 1
        return checked


@pytest.mark.parametrize("controller", ["icr", "twist"])
def test_eval_episodes_bit_for_bit(monkeypatch, controller):
    from control.path_controllers import ICRPathController, TwistPathController
    from control.rollout import run_episodes

    rec = _Recorder(monkeypatch)
    ctl = ICRPathController() if controller == "icr" else TwistPathController()
    logs = run_episodes(ctl, ["paper", "square", "crab", "random"], [0, 1, 2, 3], max_time=6.0,
                        kicks=[None, {"step": 60, "wheels": [1, 2], "impulse": 0.9}, None, None])
    assert rec.check() >= sum(log.t.size for log in logs) >= 4 * 250


def test_scenarios_holds_odometry_and_another_robot_bit_for_bit(monkeypatch):
    from control.path_controllers import ICRPathController, TwistPathController
    from control.rollout import run_episodes

    rec = _Recorder(monkeypatch)
    logs = run_episodes(TwistPathController(), ["hold", "reverse", "slalom"], [0, 1, 2], max_time=5.0)
    assert any(log.hold.any() for log in logs)  # a hold was followed
    logs += run_episodes(ICRPathController(speed_scale=0.7), ["circle", "hold"], [4, 5], max_time=5.0,
                         env_kwargs={"robot": "swerve", "pose_source": "odometry"})
    assert rec.check() >= sum(log.t.size for log in logs)


def test_residual_action_space_bit_for_bit(monkeypatch):
    from azimut_env.vector_env import AzimutVectorEnv
    from control.action_spaces.vector import VectorControllerAction

    rec = _Recorder(monkeypatch)
    env = VectorControllerAction(AzimutVectorEnv(num_envs=4, track="random", max_episode_steps=120),
                                 action="residual")
    env.reset(seed=7)
    rng = np.random.default_rng(7)
    for _ in range(300):  # autoresets on the way: followers restarted on new random tracks
        env.step(rng.uniform(-1, 1, (4, 3)).astype(np.float32))
    env.close()
    assert rec.check() >= 4 * 250  # the steps of the robots not being reset


def test_rotation_cusps_bit_for_bit(monkeypatch):
    """The ICR path controller's followers take ``spin``'s junction of its drive-and-rotate leg
    and its last spin, where the path turns back in (x, y, ρθ), as a cusp
    (``PathFollowerConfig.rotation_cusps``): there too the batch equals one follower per robot."""
    from control.path_controllers import ICRPathController
    from control.rollout import run_episodes

    rec = _Recorder(monkeypatch)
    logs = run_episodes(ICRPathController(), ["spin", "spin"], [0, 1], env_kwargs={"robot": "hex"})
    assert all(log.completed for log in logs)  # past the junction
    assert any(call[0] == "reset" and call[5].rotation_cusps for call in rec.calls)
    assert rec.check() >= sum(log.t.size for log in logs)
