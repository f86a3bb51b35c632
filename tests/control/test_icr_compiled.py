"""The compiled ICR controller step against its NumPy reference, bit for bit.

Episodes are recorded in closed loop with the NumPy reference (``icr_control_step_batch``) driving
the robots (path following with stops and reconfigurations, a kick, shaped RL targets and the
residual action space); then both implementations are stepped in lockstep on the recorded inputs,
from the same resets, and every command, ``info`` entry and state field must be equal to the bit
(the arithmetic is the same, operation by operation: ``control.icr.kernels``).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import control.icr.batch as batch_module
from control.icr.compiled import compiled_constants, compiled_control_step_batch
from control.icr.config import ICRControllerConfig, Mode
from control.icr.controller import icr_control_step_batch
from control.icr.state import initial_state_batch


class _Recorder:
    """Patches BatchICRController so that it steps with the NumPy reference and records its calls."""

    def __init__(self, monkeypatch):
        self.calls: list = []  # ("reset", rows, λ̂, β, φ̇) and ("step", rows, λ̂, μ̂, β, φ̇, λ_d, μ_d)
        self.controllers: list = []
        rec = self

        def step(ctl, rows, lam_hat, mu_hat, beta, phidot, lam_d, mu_d):
            if ctl not in rec.controllers:
                rec.controllers.append(ctl)
            every = rows is None
            idx = np.arange(ctl.num) if every else np.asarray(rows, dtype=np.intp)
            args = (np.array(a, dtype=np.float64) for a in (lam_hat, mu_hat, beta, phidot, lam_d, mu_d))
            rec.calls.append(("step", ctl, None if every else idx.copy(), *args))
            new, cmd = icr_control_step_batch(ctl.state.take(idx), lam_hat, mu_hat, beta, phidot, lam_d, mu_d,
                                              ctl.geom, ctl.limits, ctl.config, ctl.dt)
            ctl.state = ctl.state.put(idx, new)
            return replace(cmd, mode=cmd.info["mode"], events=cmd.info["events"])

        original_reset = batch_module.BatchICRController.reset

        def reset(ctl, rows, lam_hat, beta, phidot):
            rec.calls.append(("reset", ctl, np.array(rows), np.array(lam_hat), np.array(beta), np.array(phidot)))
            return original_reset(ctl, rows, lam_hat, beta, phidot)

        monkeypatch.setattr(batch_module.BatchICRController, "step", step)
        monkeypatch.setattr(batch_module.BatchICRController, "reset", reset)


def _replay(rec: _Recorder) -> dict:
    """Step the reference and the compiled step in lockstep on the recorded calls; assert equality.
    Returns counts of what the episodes went through."""
    seen = {"steps": 0, "modes": set(), "events": 0, "saturated": 0, "held": 0}
    for ctl in rec.controllers:
        g, lim, cfg, dt = ctl.geom, ctl.limits, ctl.config, ctl.dt
        const = compiled_constants(g, lim, cfg, dt)
        ref = fast = batch_module._blank_state(ctl.num, g.n)
        for call in rec.calls:
            if call[1] is not ctl:
                continue
            if call[0] == "reset":
                rows, lam_hat, beta, phidot = call[2:]
                fresh = initial_state_batch(lam_hat, beta, phidot, g, cfg)
                ref, fast = ref.put(rows, fresh), fast.put(rows, fresh)
                continue
            rows, args = call[2], call[3:]
            idx = np.arange(ctl.num) if rows is None else rows
            new_ref, cmd_ref = icr_control_step_batch(ref.take(idx), *args, g, lim, cfg, dt)
            ref = ref.put(idx, new_ref)
            fast, cmd_fast = compiled_control_step_batch(fast, *args, g, lim, cfg, dt, rows=rows, constants=const)
            where = f"step {seen['steps']}"
            for name in ref.__dataclass_fields__:
                np.testing.assert_array_equal(getattr(fast, name), getattr(ref, name), err_msg=f"{where}: state.{name}")
            for name in ("beta", "phidot", "beta_rate", "beta_accel", "phiddot"):
                np.testing.assert_array_equal(getattr(cmd_fast, name), getattr(cmd_ref, name),
                                              err_msg=f"{where}: {name}")
            assert set(cmd_fast.info) == set(cmd_ref.info)
            for key, value in cmd_ref.info.items():
                np.testing.assert_array_equal(cmd_fast.info[key], value, err_msg=f"{where}: info[{key!r}]")
            seen["steps"] += 1
            seen["modes"] |= set(cmd_ref.info["mode"].tolist())
            seen["events"] += int(np.sum(cmd_ref.info["event"] != 0))
            seen["saturated"] += int(np.sum(cmd_ref.info["saturated"]))
            seen["held"] += int(np.sum(cmd_ref.info["held_at_stop"]))
    return seen


def test_path_following_episodes_bit_for_bit(monkeypatch):
    """``azimut eval``'s icr controller on three tracks (one robot kicked): every mode, stops and
    reconfigurations, the compiled step equal to the reference at every step."""
    from control.path_controllers import ICRPathController
    from control.rollout import run_episodes

    rec = _Recorder(monkeypatch)
    run_episodes(ICRPathController(), ["square", "crab", "paper"], [0, 1, 2], max_time=12.0,
                 kicks=[{"step": 100, "wheels": [0, 2], "impulse": 0.8}, None, None])
    seen = _replay(rec)
    assert seen["steps"] == 600
    assert seen["modes"] == {int(Mode.RUNNING), int(Mode.STOPPING), int(Mode.RECONFIGURING)}
    assert seen["events"] >= 3


@pytest.mark.parametrize("robot, tracks", [(None, ["icr-axis", "spin", "reverse"]), ("tri", ["strafe90", "icr-axis"])])
def test_holds_at_steering_stops_bit_for_bit(monkeypatch, robot, tracks):
    """The scenarios where targets graze or run along a steering stop: holds at the nearest point
    of the current cell (sliding along a stop circle), holds that run out of
    ``stop_hold_distance``, reconfigurations that do not chase a slow target."""
    from control.path_controllers import ICRPathController
    from control.rollout import run_episodes

    rec = _Recorder(monkeypatch)
    run_episodes(ICRPathController(), tracks, [0] * len(tracks), max_time=12.0,
                 env_kwargs=None if robot is None else {"robot": robot})
    seen = _replay(rec)
    assert seen["steps"] == 600
    assert seen["held"] >= 50 and seen["events"] >= 2
    assert seen["modes"] == {int(Mode.RUNNING), int(Mode.STOPPING), int(Mode.RECONFIGURING)}


def test_unlimited_steering_bit_for_bit(monkeypatch):
    """The swerve preset (no steering stops: nearest axis angles, no stop room, no clipping)."""
    from control.path_controllers import ICRPathController
    from control.rollout import run_episodes

    rec = _Recorder(monkeypatch)
    run_episodes(ICRPathController(), ["square", "figure8"], [0, 1], max_time=8.0, env_kwargs={"robot": "swerve"})
    assert _replay(rec)["steps"] == 400


@pytest.mark.parametrize("action", ["residual", "icr_rate", "icr_target"])
def test_rl_action_spaces_bit_for_bit(monkeypatch, action):
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
    seen = _replay(rec)
    assert seen["steps"] == 150 and seen["saturated"] > 0  # kappa_fallback's path is compared too


def test_coupling_from_measurement_and_a_stop_command(monkeypatch):
    """The tuning switches the defaults leave off: the measured steering rate in the coupling, and
    stop commands (μ_d = 0) in every mode."""
    from control.path_controllers import ICRPathController
    from control.rollout import run_episodes

    rec = _Recorder(monkeypatch)
    cfg = ICRControllerConfig(coupling_from_measurement=True, mu_own_scale=True)
    run_episodes(ICRPathController(icr_config=cfg), ["square", "figure8"], [4, 5], max_time=6.0)
    calls = [c for c in rec.calls if c[0] == "step"]
    for c in calls[::7]:  # every 7th step a stop command for robot 0
        c[8][0] = 0.0
    assert _replay(rec)["steps"] == 300


def test_the_compiled_step_refuses_what_the_reference_refuses():
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
        with pytest.raises(ValueError) as ref_err:
            icr_control_step_batch(state, *args, g, lim, cfg, 0.02)
        with pytest.raises(ValueError) as fast_err:
            compiled_control_step_batch(state, *args, g, lim, cfg, 0.02)
        assert str(fast_err.value) == str(ref_err.value)
    with pytest.raises(ValueError, match="dt"):
        compiled_control_step_batch(state, *good, g, lim, cfg, 0.0)
