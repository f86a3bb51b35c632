"""The follower's holds and the per-scenario metrics (control.episode.scenario_metrics)."""

import numpy as np
import pytest

from azimut_env.tracks import ALL_TRACK_NAMES, Track
from control.episode import EpisodeLog, scenario_metrics
from control.follow.batch import BatchFollower
from control.follow.path_follower import PathFollower
from control.path_controllers import ICRPathController
from control.rollout import run_episode, run_episodes


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


def _cusp_track():
    """Two legs meeting at a cusp (the second leg 20° off the way back, as ``reverse``'s), the
    speed falling to zero there; samples 2 cm apart."""
    from azimut_env.tracks.scenarios import _line

    p1 = np.array([1.0, 0.0])
    back = np.deg2rad(160.0)
    p2 = p1 + np.array([np.cos(back), np.sin(back)])
    xy = np.vstack([_line((0.0, 0.0), p1), _line(p1, p2), p2[None]])
    speed = np.minimum(1.0, np.abs(np.hypot(*(xy - p1).T)) * 5 + 0.02)
    return Track("cusp", xy, 0.0, speed)


def test_progress_past_a_cusp_is_the_cusp_and_the_preview_turns_to_the_next_leg():
    """A robot 6 mm past a cusp along the incoming leg is nearest to the cusp sample; the
    projection's refinement along the *outgoing* leg (pointing back) put its progress up to one
    segment before the cusp, where the follower's feed-forward and feedback balanced: the
    ``reverse`` scenario's stall. The projection now takes a pose past a corner on its outside as
    the corner (azimut_env.tracks.query.segment_step), the follower's progress is the cusp
    (control.follow.cusps), and once there the preview points along the outgoing leg; the
    compiled follower gives the same bits."""
    from control.follow.cusps import cusp_table

    tr = _cusp_track()
    table = cusp_table(tr)
    assert table.shape[0] == 1
    i = int(table[0, 0])
    s_cusp = tr.s[i]
    pose = np.array([1.006, 0.0, 0.0])
    assert tr.project(pose, s_hint=s_cusp - 0.05) == s_cusp  # the projection alone: the corner
    f = PathFollower(tr, dt=0.02)
    f.reset(s_cusp - 0.05)
    out = f.step(pose)
    assert out.progress == s_cusp
    batch = BatchFollower(1, dt=0.02)
    batch.reset(0, tr, s_cusp - 0.05)
    b = batch.step_all(pose[None])
    assert b.progress[0] == out.progress and np.array_equal(b.twist[0], out.twist)
    # at the cusp (reached): the feed-forward along the outgoing leg, not the legs' bisector
    f.reset(s_cusp)
    ff = f.step(np.array([*tr.xy[i], 0.0]))
    direction = np.arctan2(ff.twist[1], ff.twist[0])
    assert abs(direction - np.deg2rad(160.0)) < 1e-9
    # a smooth track has no cusp, and its follower is the projection's
    assert cusp_table(Track("line", [[0, 0], [1, 0], [2, 0.5]], 0.0, 0.5)).shape[0] == 0


@pytest.mark.parametrize("robot, tracks", [(None, ["reverse", "icr-axis"]), ("tri", ["strafe90"])])
def test_icr_controller_finishes_the_scenarios_it_stalled_on(robot, tracks):
    """Issue 19's not-done rows: on the default robot (AZIMUT-3 with the paper's imperfections)
    ``reverse`` (stalled at its second cusp, 20 stop-and-reconfigure events) and ``icr-axis``
    (wheel 0 flipped back and forth across its stop, 14 events); on ``tri``, ``strafe90`` (the
    front wheel at 90° along every X leg, flipped at each hold's end, 15 events). Each now
    finishes, within the actuator limits, with few stops."""
    logs = run_episodes(ICRPathController(), tracks, [0] * len(tracks),
                        env_kwargs=None if robot is None else {"robot": robot})
    for log in logs:
        assert log.completed, log.track.name
        assert not np.any(log.violations)
        assert log.events <= 11, (log.track.name, log.events)


def _cusps_every_sample(track):
    """:func:`control.follow.cusps.cusp_table`'s exact test (:func:`~control.follow.cusps.cusp_row`)
    run at every interior sample, without the pre-filter (the table's definition)."""
    from control.follow.cusps import cusp_row

    xy = track.xy
    pts = np.stack([xy[:, 0], xy[:, 1], track.progress_radius * track.heading], axis=1)
    rows = [row for i in range(1, len(xy) - 1) if (row := cusp_row(track, pts, i)) is not None]
    return np.array(rows, dtype=np.float64).reshape(-1, 9)


def test_the_cusp_table_is_the_test_at_every_sample():
    """The table examines only the samples its vectorised pre-filter keeps; it equals the test run
    at every sample on the built-in tracks, every scenario of every preset and random tracks."""
    from azimut_env.params import RobotParams
    from azimut_env.tracks import make_track
    from azimut_env.tracks.scenarios import SCENARIO_NAMES, scenario_track
    from control.follow.cusps import cusp_table

    tracks = [make_track(n) for n in ("paper", "circle", "figure8", "square", "crab")]
    tracks += [make_track("random", rng=np.random.default_rng(s)) for s in range(10)]
    tracks += [scenario_track(n, RobotParams.preset(p)) for p in ("azimut3", "swerve", "tri", "hex")
               for n in SCENARIO_NAMES]
    found = 0
    for track in tracks:
        table = cusp_table(track)
        assert np.array_equal(table, _cusps_every_sample(track))
        found += len(table)
    assert found > 0


def test_a_rotation_that_turns_back_is_a_cusp_only_when_asked():
    """``spin``'s drive-and-rotate leg (turning by −π) ends in a spin in place by +π/2: the path
    turns back by 118° in the projection's metric (x, y, ρθ), not in the plane. It is a cusp with
    ``rotation`` (the ICR path controller's followers) and on no other built-in track or scenario
    does ``rotation`` change the table; without it the twist baselines' follower is as before."""
    from azimut_env.task.config import robot_of
    from azimut_env.tracks.scenarios import named_track
    from control.follow.cusps import cusp_table

    for robot in ("azimut3", "hex", "swerve"):
        params = robot_of({"robot": robot})
        for name in ALL_TRACK_NAMES:
            track = named_track(name, params)
            plane, rotation = cusp_table(track), cusp_table(track, rotation=True)
            if name != "spin":
                np.testing.assert_array_equal(plane, rotation)
                continue
            assert plane.shape[0] == 0 and rotation.shape[0] == 1
            a, b = rotation[0, 3:6], rotation[0, 6:9]
            assert np.degrees(np.arccos(a @ b)) > 100.0  # turns back: 118° (azimut3), 106° (swerve)
            assert np.all(track.xy[int(rotation[0, 0]) + 1:] == track.xy[int(rotation[0, 0])])  # then in place


def test_the_icr_controller_passes_the_spin_junction():
    """Without the rotation cusp the ICR controller's follower stalled a few millimetres before
    ``spin``'s last spin (the heading feedback balancing the spin's feed-forward) and hex never
    finished at ×1.2 and ×1.4 on seed 0 (17 and 23 stop sequences there)."""
    for scale in (1.2, 1.4):
        log = run_episodes(ICRPathController(speed_scale=scale), ["spin"], [0], env_kwargs={"robot": "hex"})[0]
        assert log.completed and log.events <= 12, (scale, log.t[-1], log.events)
