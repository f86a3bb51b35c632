"""The controller interface (``control.controller``), its registry, and the one episode loop
(``control.rollout``): a controller written here runs through ``azimut eval``; N episodes stepped
as one batch are the N episodes run alone, bit for bit; every way an episode ends."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from azimut_env.tracks import Track
from control.commands import WheelCommand
from control.controller import (
    Controller,
    ControllerSpecError,
    check_spec,
    controller_names,
    make_controller,
    register_controller,
)
from control.episode import EpisodeLog, episode_metrics
from control.feedforward import FeedForwardController
from control.icr.config import Mode
from control.path_controllers import ICRPathController, TwistPathController
from control.rollout import run_episode, run_episodes
from estimation import eta_from_twist, steering_from_lambda, wheel_speeds
from jobs.cli import main

# ------------------------------------------------------------------ controllers written here


class TrackFeedForward:
    """A user's controller: the track's reference twist at the robot's progress, with a
    proportional pull back to the path, straight into wheel set-points (no rates: the loop then
    checks φ̇ only)."""

    name = "mine"

    def __init__(self, gain: float = 1.0, speed_scale: float = 1.0) -> None:
        self.gain, self.speed_scale = gain, speed_scale

    def reset(self, env, rows) -> None:
        self.resets = getattr(self, "resets", 0) + len(rows)

    def act(self, env, obs) -> WheelCommand:
        geom, poses, progress = env.geometry, env.estimated_pose, env.progress
        beta, phidot = env.measured_beta.copy(), np.zeros_like(env.measured_beta)
        for i, track in enumerate(env.tracks):
            x, y, th = poses[i]
            ref = track.sample(float(progress[i]))
            tw = track.reference_twist(float(progress[i])) * self.speed_scale
            vx, vy = tw[0] + self.gain * (ref[0] - x), tw[1] + self.gain * (ref[1] - y)
            body = np.array([math.cos(th) * vx + math.sin(th) * vy, -math.sin(th) * vx + math.cos(th) * vy, tw[2]])
            if np.linalg.norm(body) > 1e-6:
                lam, mu = eta_from_twist(body)
                beta[i] = steering_from_lambda(lam, geom)
                phidot[i] = wheel_speeds(lam, mu, geom, beta=beta[i])
        return WheelCommand(beta=beta, phidot=phidot)


class Drive:
    """Each robot a pure translation along its chassis x axis at its ``speed`` [m/s] (one for
    all, or one per robot; β = F(λ) of that motion, φ̇ its wheel speeds, no rates): it leaves
    any track that turns. ``poison``: robot -> step at which its chassis velocity becomes NaN (a
    physics blow-up, for the error path)."""

    def __init__(self, speed=0.3, poison: dict | None = None) -> None:
        self.name, self.speed, self.poison = "drive", speed, poison or {}
        self.steps: np.ndarray | None = None

    def reset(self, env, rows) -> None:
        if self.steps is None:
            self.steps = np.zeros(len(env.tracks), dtype=int)
        self.steps[np.asarray(rows)] = 0

    def act(self, env, obs) -> WheelCommand:
        for i, k in self.poison.items():
            if self.steps[i] == k:
                env.physics.chassis[i].velocity = (float("nan"), 0.0)
        self.steps += 1
        geom, num = env.geometry, len(env.tracks)
        lam, mu = eta_from_twist(np.array([1.0, 0.0, 0.0]))
        beta = np.tile(steering_from_lambda(lam, geom), (num, 1))
        speed = np.broadcast_to(np.asarray(self.speed, dtype=float), (num,))
        return WheelCommand(beta=beta, phidot=np.outer(speed, wheel_speeds(lam, mu, geom, beta=beta[0])))


def make_mine(**options):
    """A factory (not a class) for the registry."""
    return TrackFeedForward(**options)


class NotAController:
    name = "nope"


@pytest.fixture(scope="module")
def short_track():
    return Track.from_waypoints([[0.0, 0.0], [0.6, 0.0]], heading=0.0, speed=0.5, ramp=0.2, name="short")


# ------------------------------------------------------------------ protocol and registry


def test_builtins_are_controllers_with_their_names():
    for spec, kind in (("icr", ICRPathController), ("twist", TwistPathController),
                       ("feedforward", FeedForwardController)):
        ctl = make_controller(spec)
        assert isinstance(ctl, kind) and isinstance(ctl, Controller) and ctl.name == spec
    assert make_controller("icr", speed_scale=0.5).speed_scale == 0.5
    assert {"icr", "twist", "feedforward"} <= set(controller_names())
    assert isinstance(TrackFeedForward(), Controller) and not isinstance(NotAController(), Controller)


@pytest.mark.parametrize("spec, match", [
    ("pid", "unknown controller 'pid'"),
    ("", "non-empty"),
    ("no_such_module_xyz:Thing", "cannot import 'no_such_module_xyz'"),
    ("test_controller_api:Missing", "has no attribute 'Missing'"),
    ("test_controller_api:NotAController", "not a Controller \\(missing reset, act\\)"),
])
def test_bad_specs_are_refused_in_one_line(spec, match):
    with pytest.raises(ControllerSpecError, match=match) as info:
        make_controller(spec)
    assert "\n" not in str(info.value) and isinstance(info.value, ValueError)


def test_options_a_factory_does_not_take_are_refused():
    with pytest.raises(ControllerSpecError, match="does not take color"):
        make_controller("icr", color="red")
    with pytest.raises(ControllerSpecError, match="speed_scale must be a finite number > 0"):
        make_controller("icr", speed_scale=-1.0)


def test_register_names_factories_and_prefixes():
    register_controller("mine-test", make_mine)
    ctl = make_controller("mine-test", gain=2.0)
    assert isinstance(ctl, TrackFeedForward) and ctl.gain == 2.0
    register_controller("gain", lambda arg, **kw: TrackFeedForward(gain=float(arg), **kw), prefix=True)
    assert make_controller("gain:3.5").gain == 3.5
    check_spec("gain:1")
    with pytest.raises(ControllerSpecError, match="give gain:ARG"):
        make_controller("gain:")
    with pytest.raises(ValueError, match="controller name"):
        register_controller("has space", make_mine)
    with pytest.raises(TypeError, match="callable"):
        register_controller("x", 3)


def test_module_attr_spec_imports_the_users_class():
    ctl = make_controller("test_controller_api:TrackFeedForward", gain=0.5)
    assert isinstance(ctl, TrackFeedForward) and ctl.gain == 0.5


# ------------------------------------------------------------------ through azimut eval


def _eval(tmp_path, controllers: str, *extra: str) -> list[dict]:
    out = tmp_path / "report"
    rc = main(["eval", "--controllers", controllers, "--tracks", "crab", "--max-time", "1.5", "--no-plots",
               "--out", str(out), *extra])
    assert rc == 0
    return json.loads((out / "metrics.json").read_text())["episodes"]


def test_a_registered_controller_runs_through_azimut_eval(tmp_path):
    register_controller("mine-test", make_mine)
    rows = _eval(tmp_path, "icr,mine-test")
    assert [r["controller"] for r in rows] == ["icr", "mine"]
    mine = rows[1]
    assert mine["status"] == "ok" and mine["error"] is None and not mine["completed"]
    assert mine["rms_lateral_m"] < 0.05 and mine["return"] > 0
    assert mine["reconfigure_events"] == 0 and 0.0 <= mine["standstill_share"] < 1.0


def test_a_module_class_spec_runs_through_azimut_eval(tmp_path):
    rows = _eval(tmp_path, "test_controller_api:TrackFeedForward", "--speed-scale", "0.5")
    assert [r["controller"] for r in rows] == ["mine"] and rows[0]["status"] == "ok"
    assert rows[0]["rms_lateral_m"] < 0.05


@pytest.mark.parametrize("controllers, match", [
    ("icr,pid", "unknown controller 'pid'"),
    ("no_such_module_xyz:Thing", "cannot import"),
    ("test_controller_api:NotAController", "not a Controller"),
    ("icr,icr", "repeated entries"),
    ("test_controller_api:Drive", "does not take speed_scale"),
])
def test_azimut_eval_refuses_bad_controllers_with_exit_2(tmp_path, capsys, controllers, match):
    argv = ["eval", "--controllers", controllers, "--no-plots", "--out", str(tmp_path / "r")]
    if "Drive" in controllers:
        argv += ["--speed-scale", "0.5"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert match in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "r").exists()


def test_two_controllers_with_one_name_are_refused(tmp_path, capsys):
    register_controller("mine-test", make_mine)
    assert main(["eval", "--controllers", "mine-test,test_controller_api:TrackFeedForward", "--no-plots",
                 "--out", str(tmp_path / "r")]) == 2
    assert "both named 'mine'" in capsys.readouterr().err


# ------------------------------------------------------------------ the loop: batch = alone


_FIELDS = [f for f in EpisodeLog.__dataclass_fields__ if f not in ("controller", "track", "dt")]


def _same(a: EpisodeLog, b: EpisodeLog) -> None:
    assert a.track is b.track or a.track.name == b.track.name
    for f in _FIELDS:
        x, y = getattr(a, f), getattr(b, f)
        if isinstance(x, np.ndarray):
            assert x.shape == y.shape and x.dtype == y.dtype and np.array_equal(x, y), f
        elif isinstance(x, float) and math.isnan(x):
            assert math.isnan(y), f
        else:
            assert x == y, f


@pytest.mark.parametrize("spec", ["icr", "twist", "feedforward"])
def test_a_batch_is_its_episodes_run_alone_bit_for_bit(spec, short_track):
    """Four robots, each its own track and seed, ending at different steps (the short track is
    completed first, then the robot runs on unlogged while the others go on)."""
    tracks, seeds, kicks = [short_track, "crab", "random", "circle"], [3, 0, 7, 1], [None, None, None, None]
    kicks[3] = {"step": 20, "wheels": [0, 2], "impulse": 0.5}
    logs = run_episodes(make_controller(spec), tracks, seeds, kicks=kicks, max_time=3.0)
    assert logs[0].completed and logs[0].t.size < logs[1].t.size
    for i, (track, seed) in enumerate(zip(tracks, seeds)):
        _same(logs[i], run_episode(spec, track, seed=seed, kick=kicks[i], max_time=3.0))


def test_each_end_of_an_episode(short_track):
    """Finished, off the track, stalled, env error and max_time in one batch, each log stopping
    at its end (the error step is not logged), and the env's time limit."""
    ctl = Drive(speed=[0.3, 0.6, 0.0, 0.3, 0.08], poison={3: 10})
    logs = run_episodes(ctl, [short_track, "circle", "crab", "circle", short_track], [0, 1, 2, 3, 4],
                        max_time=6.0, env_kwargs={"stall_time": 1.0})
    done, off, stalled, error, capped = logs
    assert done.completed and done.error is None
    assert off.error == "off track" and abs(off.lateral[-1]) > abs(off.lateral[-2]) and not off.completed
    assert stalled.error == "stalled" and stalled.t[-1] == pytest.approx(1.0) and not stalled.completed
    assert error.error is not None and "non-finite" in error.error and error.t.size == 10
    assert capped.error is None and not capped.completed and capped.t.size == 300
    assert capped.t[-1] == pytest.approx(6.0)
    assert done.t.size < off.t.size < capped.t.size and stalled.t.size < capped.t.size
    for log in logs:
        assert all(getattr(log, f).shape[0] == log.t.size for f in ("pose", "lateral", "qua", "beta_cmd", "mode"))
    limited = run_episode(Drive(speed=0.0), "circle", seed=0, env_kwargs={"time_limit_factor": 0.01})
    assert limited.error == "time limit" and 0 < limited.t.size < 100


def test_the_loop_checks_what_the_command_gives(short_track):
    """No rates declared: the set-points themselves are checked (issue 31: differenced over the
    period, the first against the measured state at the reset); a mode: moving only while RUNNING."""
    fast = run_episode(Drive(speed=1e3), short_track, seed=0, max_time=0.2)
    assert fast.violations.all() and fast.beta_rate.size == 0 and (fast.mode == int(Mode.RUNNING)).all()
    assert fast.limit_flags[:, 2].all()  # the wheel speed, every step
    slow = run_episode(Drive(speed=0.3), short_track, seed=0, max_time=0.2)
    # the jump from rest to 0.3 m/s (φ̈ = 3.75 rad/s / 0.02 s) and to the steering of a straight line
    # (β̈ out of the start noise, and back): the first two periods only
    assert slow.violations[:2].all() and not slow.violations[2:].any()
    assert slow.limit_flags[0].tolist() == [False, True, False, True, False]
    m = episode_metrics(fast)
    assert m["limit_violation_steps"] == fast.t.size and m["reconfigure_events"] == 0


def test_the_loop_refuses_what_is_not_a_controller_or_a_command():
    with pytest.raises(TypeError, match="must implement control.controller.Controller"):
        run_episodes(NotAController(), "circle", [0])

    class Wrong(Drive):
        def act(self, env, obs):
            return WheelCommand(beta=np.zeros(4), phidot=np.zeros(4))

    with pytest.raises(ValueError, match="command beta must have shape \\(1, 4\\)"):
        run_episode(Wrong(), "circle", seed=0, max_time=0.1)
    with pytest.raises(ValueError, match="one entry per seed"):
        run_episodes(Drive(), ["circle", "crab"], [0, 1, 2])
    with pytest.raises(TypeError, match="already made"):
        run_episode(Drive(), "circle", speed_scale=0.5)


@pytest.mark.parametrize("action", ["residual", "twist"])
def test_bench_env_times_the_action_controller(action):
    """``azimut bench-env --action`` splits a step into the action controller's stages."""
    from jobs.bench_threads import bench_controller_action

    r = bench_controller_action(action, num_envs=2, calls=5, track="circle")
    assert r["steps_per_s"] > 0 and r["targets_us"] > 0 and r["controller_us"] > 0 and r["env_us"] > 0
