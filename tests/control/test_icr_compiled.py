"""The ICR controller's compiled step against the same code run as plain Python, bit for bit.

The step is written once (:mod:`control.icr.compiled` and its kernels); its reference is that code
with numba switched off (``NUMBA_DISABLE_JIT=1``, in a subprocess: the switch is read when numba is
imported). Closed-loop episodes are recorded with the compiled step driving the robots (path
following with stops, reconfigurations and a kick; holds at steering stops; unlimited steering;
the RL action spaces under random actions; ``coupling_from_measurement``, ``mu_own_scale`` and
stop commands), then the recorded calls are replayed through the compiled step here and through
the plain-Python step in the subprocess (this file run as a script), from the same resets, and
every command, ``info`` entry and state field must have the same bits.

The plain-Python kernels are slow (a few ms per robot and step), so the default episodes are a
few hundred steps of a few robots; the longer ones are marked ``slow``.
"""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import control.icr.batch as batch_module
from control.icr.compiled import compiled_constants, compiled_control_step_batch
from control.icr.config import ICRControllerConfig, Mode
from control.icr.controller import icr_control_step_batch
from control.icr.state import initial_state_batch


class _Recorder:
    """Records every reset and step of every BatchICRController (which still runs them)."""

    def __init__(self, monkeypatch):
        self.controllers: list = []
        self.calls: list = []  # ("reset", ctl, rows, (λ̂, β, φ̇), {}) and ("step", ctl, rows, inputs, kwargs)
        rec = self
        original_step = batch_module.BatchICRController.step
        original_reset = batch_module.BatchICRController.reset

        def _ctl(ctl) -> int:
            if ctl not in rec.controllers:
                rec.controllers.append(ctl)
            return rec.controllers.index(ctl)

        def step(ctl, rows, *args, **kwargs):
            keep = {k: None if v is None else np.array(v, dtype=np.float64) for k, v in kwargs.items()}
            rec.calls.append(("step", _ctl(ctl), None if rows is None else np.array(rows, dtype=np.int64),
                              tuple(np.array(a, dtype=np.float64) for a in args), keep))
            return original_step(ctl, rows, *args, **kwargs)

        def reset(ctl, rows, *args):
            rec.calls.append(("reset", _ctl(ctl), np.array(rows, dtype=np.int64),
                              tuple(np.array(a, dtype=np.float64) for a in args), {}))
            return original_reset(ctl, rows, *args)

        monkeypatch.setattr(batch_module.BatchICRController, "step", step)
        monkeypatch.setattr(batch_module.BatchICRController, "reset", reset)

    def episodes(self) -> dict:
        """What the subprocess needs: each controller's (N, geom, limits, config, dt), the calls."""
        return {"controllers": [(c.num, c.geom, c.limits, c.config, c.dt) for c in self.controllers],
                "calls": self.calls}


def _replay(episodes: dict) -> list[dict[str, np.ndarray]]:
    """Every recorded step replayed through :func:`compiled_control_step_batch`, from the recorded
    resets: per step, the new state's fields, the commands and their ``info``."""
    out = []
    states = [batch_module._blank_state(num, g.n) for num, g, *_ in episodes["controllers"]]
    consts = [compiled_constants(g, lim, cfg, dt) for _, g, lim, cfg, dt in episodes["controllers"]]
    for kind, i, rows, args, kwargs in episodes["calls"]:
        _, g, lim, cfg, dt = episodes["controllers"][i]
        if kind == "reset":
            states[i] = states[i].put(rows, initial_state_batch(*args, g, cfg))
            continue
        states[i], cmd = compiled_control_step_batch(states[i], *args, g, lim, cfg, dt, rows=rows, constants=consts[i],
                                                     **kwargs)
        step = {f"state.{name}": getattr(states[i], name) for name in states[i].__dataclass_fields__}
        step.update({name: getattr(cmd, name) for name in ("beta", "phidot", "beta_rate", "beta_accel", "phiddot")})
        step.update({f"info[{key!r}]": np.asarray(value) for key, value in cmd.info.items()})
        out.append(step)
    return out


def _assert_same_bits(fast, ref) -> dict:
    """Step by step, every array of ``fast`` has the dtype, shape and bytes of ``ref``'s. Returns
    counts of what the episodes went through."""
    assert len(fast) == len(ref) and len(ref) > 0
    for t, (a, b) in enumerate(zip(fast, ref)):
        assert a.keys() == b.keys(), t
        for name in b:
            x, y = a[name], b[name]
            if x.dtype != y.dtype or x.shape != y.shape or x.tobytes() != y.tobytes():
                np.testing.assert_array_equal(x, y, err_msg=f"step {t}: {name}")
                pytest.fail(f"step {t}: {name}: {x.dtype}{x.shape} {x!r} is not {y.dtype}{y.shape} {y!r} to the bit")
    info = lambda key: np.concatenate([s[f"info[{key!r}]"].ravel() for s in ref])  # noqa: E731
    return {"steps": len(ref), "modes": set(info("mode").tolist()), "events": int(np.sum(info("event") != 0)),
            "saturated": int(np.sum(info("saturated"))), "held": int(np.sum(info("held_at_stop")))}


def _without_jit(episodes: dict, tmp_path: Path) -> list[dict[str, np.ndarray]]:
    """:func:`_replay` in a subprocess with numba switched off (this file run as a script)."""
    calls, out = tmp_path / "episodes.pkl", tmp_path / "replayed.pkl"
    calls.write_bytes(pickle.dumps(episodes))
    env = {**os.environ, "NUMBA_DISABLE_JIT": "1"}
    done = subprocess.run([sys.executable, __file__, str(calls), str(out)], env=env, capture_output=True, text=True,
                          timeout=900)
    assert done.returncode == 0, done.stderr[-4000:]
    return pickle.loads(out.read_bytes())


def _compare(rec: _Recorder, tmp_path: Path, edit=None) -> dict:
    """Replay the recorded episodes compiled and as plain Python; assert the same bits. ``edit``
    changes the recorded calls first (both replays see the change)."""
    episodes = rec.episodes()
    if edit is not None:
        edit(episodes["calls"])
    return _assert_same_bits(_replay(episodes), _without_jit(episodes, tmp_path))


def _path_episodes(monkeypatch, tracks, seeds, max_time, **kwargs) -> _Recorder:
    from control.path_controllers import ICRPathController
    from control.rollout import run_episodes

    rec = _Recorder(monkeypatch)
    controller = ICRPathController(**kwargs.pop("controller_kwargs", {}))
    run_episodes(controller, tracks, seeds, max_time=max_time, **kwargs)
    return rec


ALL_MODES = {int(Mode.RUNNING), int(Mode.STOPPING), int(Mode.RECONFIGURING)}


def test_path_following_with_stops_and_a_kick(monkeypatch, tmp_path):
    """``azimut eval``'s icr controller on three tracks (one robot kicked at step 100): every mode,
    stops and reconfigurations."""
    rec = _path_episodes(monkeypatch, ["square", "crab", "paper"], [0, 1, 2], 12.0,
                         kicks=[{"step": 100, "wheels": [0, 2], "impulse": 0.8}, None, None])
    seen = _compare(rec, tmp_path)
    assert seen["steps"] == 600 and seen["modes"] == ALL_MODES and seen["events"] >= 3


@pytest.mark.parametrize("robot, tracks", [(None, ["icr-axis", "spin", "reverse"]), ("tri", ["strafe90", "icr-axis"])])
def test_holds_at_steering_stops(monkeypatch, tmp_path, robot, tracks):
    """The scenarios where targets graze or run along a steering stop: holds at the nearest point
    of the current cell (sliding along a stop circle), holds that run out of
    ``stop_hold_distance``, reconfigurations that do not chase a slow target."""
    rec = _path_episodes(monkeypatch, tracks, [0] * len(tracks), 12.0,
                         env_kwargs=None if robot is None else {"robot": robot})
    seen = _compare(rec, tmp_path)
    assert seen["steps"] == 600 and seen["held"] >= 50 and seen["events"] >= 2 and seen["modes"] == ALL_MODES


def test_unlimited_steering(monkeypatch, tmp_path):
    """The swerve preset (no steering stops: nearest axis angles, no stop room, no clipping)."""
    rec = _path_episodes(monkeypatch, ["square", "figure8"], [0, 1], 8.0, env_kwargs={"robot": "swerve"})
    assert _compare(rec, tmp_path)["steps"] == 400


@pytest.mark.parametrize("action", ["residual", "icr_rate", "icr_target"])
def test_rl_action_spaces_under_random_actions(monkeypatch, tmp_path, action):
    """Random actions through the RL action spaces (the residual, ICR-rate and shaped ICR-target
    controllers, the latter with ``mu_own_scale``; autoresets restart robots one by one)."""
    from gymnasium.vector import AutoresetMode

    from azimut_env.vector_env import AzimutVectorEnv
    from control.action_spaces.vector import VectorControllerAction

    rec = _Recorder(monkeypatch)
    env = VectorControllerAction(AzimutVectorEnv(num_envs=4, track="random", autoreset_mode=AutoresetMode.SAME_STEP,
                                                 max_episode_steps=60), action=action)
    env.reset(seed=3)
    rng = np.random.default_rng(0)
    for _ in range(150):
        env.step(rng.uniform(-1, 1, env.action_space.shape))
    env.close()
    seen = _compare(rec, tmp_path)
    assert seen["steps"] == 150 and seen["saturated"] > 0  # kappa_fallback's path is compared too


def _stop_commands(calls) -> None:
    """Every 7th step a stop command (μ_d = 0) for the first robot stepped."""
    for call in [c for c in calls if c[0] == "step"][::7]:
        call[3][5][0] = 0.0


def test_coupling_from_measurement_mu_own_scale_and_stop_commands(monkeypatch, tmp_path):
    """The tuning switches the defaults leave off (the measured steering rate in the coupling, μ
    with its own time scale), and stop commands in every mode."""
    cfg = ICRControllerConfig(coupling_from_measurement=True, mu_own_scale=True)
    rec = _path_episodes(monkeypatch, ["square", "figure8"], [4, 5], 6.0, controller_kwargs={"icr_config": cfg})
    seen = _compare(rec, tmp_path, edit=_stop_commands)
    assert seen["steps"] == 300 and int(Mode.RECONFIGURING) in seen["modes"]


@pytest.mark.slow
@pytest.mark.parametrize("robot", [None, "tri", "hex", "swerve"])
def test_whole_laps_on_every_kind_of_robot(monkeypatch, tmp_path, robot):
    """Longer episodes (40 s, every track and scenario but the random one) on the default robot,
    ``tri``, ``hex`` and ``swerve`` (20 s each without JIT)."""
    from azimut_env.tracks import ALL_TRACK_NAMES

    tracks = [name for name in ALL_TRACK_NAMES if name != "random"]
    rec = _path_episodes(monkeypatch, tracks, list(range(len(tracks))), 40.0,
                         env_kwargs=None if robot is None else {"robot": robot})
    assert _compare(rec, tmp_path)["steps"] >= 1500  # until the last robot finishes


def test_the_behaviour_tests_pass_without_jit():
    """``tests/control/test_icr.py`` (the formulas, the state machine on the kinematic bench, the
    holds at steering stops, the limits on random targets) passes on the plain-Python step too:
    what it pins is the step's code, which can be stepped through there."""
    root = Path(__file__).resolve().parents[2]
    done = subprocess.run([sys.executable, "-m", "pytest", "tests/control/test_icr.py", "-q", "-x", "-p",
                           "no:cacheprovider"], cwd=root, env={**os.environ, "NUMBA_DISABLE_JIT": "1"},
                          capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stdout[-4000:] + done.stderr[-2000:]
    assert " passed" in done.stdout and " failed" not in done.stdout


def test_the_public_step_and_the_compiled_step_refuse_alike():
    """:func:`icr_control_step_batch` checks its inputs before the compiled step; both refuse the
    same inputs with the same messages."""
    from control.limits import ActuatorLimits
    from estimation.geometry import RobotGeometry

    g, lim, cfg = RobotGeometry.azimut3(), ActuatorLimits(), ICRControllerConfig()
    state = initial_state_batch(np.tile([0.0, 0.0, 1.0], (2, 1)), np.zeros((2, 4)), np.zeros((2, 4)), g, cfg)
    good = [np.tile([0.0, 0.0, 1.0], (2, 1)), np.zeros(2), np.zeros((2, 4)), np.zeros((2, 4)),
            np.tile([1.0, 0.0, 0.0], (2, 1)), np.ones(2)]
    for i, bad in [(0, np.full((2, 3), np.nan)), (1, np.array([0.0, np.inf])), (2, np.full((2, 4), np.nan)),
                   (4, np.zeros((2, 3))), (5, np.array([np.nan, 1.0])), (2, np.zeros((2, 3)))]:
        args = list(good)
        args[i] = bad
        with pytest.raises(ValueError) as public_err:
            icr_control_step_batch(state, *args, g, lim, cfg, 0.02)
        with pytest.raises(ValueError) as fast_err:
            compiled_control_step_batch(state, *args, g, lim, cfg, 0.02)
        assert str(fast_err.value) == str(public_err.value)
    with pytest.raises(ValueError, match="dt"):
        compiled_control_step_batch(state, *good, g, lim, cfg, 0.0)


if __name__ == "__main__":  # the plain-Python replay of _without_jit: python test_icr_compiled.py IN OUT
    from numba.core import config as numba_config

    assert numba_config.DISABLE_JIT, "run with NUMBA_DISABLE_JIT=1: this is the reference without JIT"
    Path(sys.argv[2]).write_bytes(pickle.dumps(_replay(pickle.loads(Path(sys.argv[1]).read_bytes()))))
