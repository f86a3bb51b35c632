"""The follower's holds and the per-scenario metrics (control.episode.scenario_metrics)."""

import numpy as np
import pytest

from azimut_env.tracks import Track
from control.episode import EpisodeLog, scenario_metrics
from control.follow.batch import BatchFollower
from control.follow.path_follower import PathFollower
from control.rollout import run_episode


def test_follower_holds_exactly_zero_for_the_duration():
    tr = Track("h", [[0, 0], [2, 0]], 0.0, 0.5, holds=((1.0, 0.5),))
    f = PathFollower(tr, dt=0.02)
    f.reset(0.0)
    out = f.step(np.array([0.995, 0.0, 0.0]))
    assert out.holding and np.all(out.twist == 0.0) and out.mu == 0.0
    held = [f.step(np.array([0.995, 0.0, 0.0])).holding for _ in range(30)]
    assert sum(held) == 24  # 25 periods of 0.02 s in all, the first above
    assert not f.step(np.array([0.995, 0.0, 0.0])).holding  # once, then on


def test_batch_follower_holds_as_the_follower():
    tr = Track("h", [[0, 0], [2, 0]], 0.0, 0.5, holds=((1.0, 0.5),))
    batch = BatchFollower(1, dt=0.02)
    batch.reset(0, tr, 0.0)
    outs = [batch.step_all(np.array([[0.995, 0.0, 0.0]])) for _ in range(26)]
    assert all(o.holding[0] and np.all(o.twist == 0.0) and o.mu[0] == 0.0 for o in outs[:25])
    assert not outs[25].holding[0]


def _log(beta_cmd, phidot, beta_true=None, hold=None, pose=None, dt=0.02):
    T, n = beta_cmd.shape
    log = EpisodeLog("x", Track("t", [[0, 0], [1, 0]], 0.0, 0.5), dt)
    log.beta_cmd, log.phidot_cmd = beta_cmd, phidot
    log.beta_true = beta_cmd.copy() if beta_true is None else beta_true
    log.beta_rate = np.vstack([np.zeros((1, n)), np.diff(beta_cmd, axis=0) / dt])
    log.lateral = np.zeros(T)
    log.qua = np.ones(T)
    log.mu_true = np.ones(T)
    log.mode = np.zeros(T, dtype=int)
    log.hold = np.zeros(T, dtype=bool) if hold is None else hold
    log.pose = np.zeros((T, 3)) if pose is None else pose
    log.t = dt * np.arange(1, T + 1)
    return log


def test_flips_and_reversals_counted():
    T = 10
    beta = np.zeros((T, 2))
    beta[5:, 0] = np.pi  # module 0 flips its set-point by π (same axis) at step 5, speed negated
    ph = np.ones((T, 2))
    ph[5:, 0] = -1.0
    beta[:, 1] = np.linspace(0, 4 * np.pi, T)  # module 1 winds past ±π in steps < π/2: not a flip
    beta[:, 1] = np.cumsum(np.full(T, 0.3)) - 0.3
    m = scenario_metrics(_log(beta, ph))
    assert m["setpoint_flips"] == 1
    assert m["travel_reversals"] == 0  # flipped and negated: the module rolls the same way
    ph2 = ph.copy()
    ph2[5:, 1] = -1.0  # module 1 reverses its speed without turning: a reversal
    assert scenario_metrics(_log(beta, ph2))["travel_reversals"] == 1
    wound = np.zeros((T, 1))
    wound[:, 0] = np.linspace(3.0, 3.0 + 9 * 0.4, T)
    wound = np.pi - np.mod(np.pi - wound, 2 * np.pi)  # written in ]−π, π]: jumps by 2π across ±π
    assert scenario_metrics(_log(wound, np.ones((T, 1))))["setpoint_flips"] == 0
    assert scenario_metrics(_log(wound, np.ones((T, 1))))["peak_steer_rate"] == pytest.approx(0.4 / 0.02)


def test_hold_motion_metrics():
    T = 6
    hold = np.array([False, False, True, True, True, False])
    pose = np.zeros((T, 3))
    pose[3, 0] = 0.003  # the chassis creeps 3 mm during the hold
    pose[4, 0] = 0.003
    bt = np.zeros((T, 2))
    bt[3:, 1] = 0.01  # module 1 turns 0.01 rad while the command is zero
    m = scenario_metrics(_log(np.zeros((T, 2)), np.zeros((T, 2)), beta_true=bt, hold=hold, pose=pose))
    assert m["hold_steps"] == 3
    assert m["hold_chassis_m"] == pytest.approx(0.003)
    assert m["hold_steer_rad"] == pytest.approx(0.01) and m["hold_steer_cmd_rad"] == 0.0
    assert np.isnan(scenario_metrics(_log(np.zeros((T, 2)), np.zeros((T, 2))))["hold_chassis_m"])


def test_hold_scenario_episode():
    log = run_episode("twist", "hold", seed=0, max_time=7.0, env_kwargs={"imperfections": "ideal"})
    assert log.hold.sum() == 100  # 2 s of zero command
    m = scenario_metrics(log)
    assert m["hold_steer_cmd_rad"] == 0.0 and m["hold_chassis_m"] < 0.01
