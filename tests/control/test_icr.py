"""ICR controller: the algebra of docs/icr-controller.md against finite differences, limits, singular targets and the
RUNNING -> STOPPING -> RECONFIGURING state machine (on the kinematic test bench)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from kinematic_model import KinematicRobot, twist_from_wheels

from control.icr.compiled import compiled_constants
from control.icr.controller import (
    ICRController,
    ICRControllerConfig,
    Mode,
    arc_blocked,
    icr_control_step,
    initial_state,
    nearer_target,
    project_off_axes,
)
from control.icr.feasibility import stop_hold_point_batch
from control.icr.kernel_constants import N_WS
from control.icr.kernels import stop_normals
from control.icr.kernels_motion import coordinated_row
from control.limits import ActuatorLimits, limit_violations
from estimation import RobotGeometry, eta_from_twist, lambda_distance, steering_from_lambda, twist_from_eta
from estimation.kinematics import s_perp, steering_path_derivatives, wheel_speed_coefficients, wheel_speeds

GEOM = RobotGeometry.azimut3()
LIM = ActuatorLimits()
DT = 0.02


def _unit(x):
    x = np.asarray(x, dtype=float)
    return x / np.linalg.norm(x)


def _path(lam0, axis, s):
    """λ(s) on a great circle: rotation of λ0 about ``axis`` by angle s."""
    axis = _unit(axis)
    return (np.cos(s) * lam0 + np.sin(s) * np.cross(axis, lam0) + (1 - np.cos(s)) * np.dot(axis, lam0) * axis)


# ------------------------------------------------------------------ algebra vs finite differences


@pytest.mark.parametrize("seed", range(5))
def test_beta_path_derivatives_match_finite_differences(seed):
    rng = np.random.default_rng(seed)
    lam0 = _unit(rng.normal(size=3))
    axis = rng.normal(size=3)
    h = 1e-5
    lams = np.array([_path(lam0, axis, s) for s in (-h, 0.0, h)])
    dlam = (lams[2] - lams[0]) / (2 * h)
    ddlam = (lams[2] - 2 * lams[1] + lams[0]) / h**2
    b = steering_from_lambda(lams, GEOM)
    d1, d2 = steering_path_derivatives(lams[1], dlam, ddlam, GEOM)
    fd1 = np.mod((b[2] - b[0]) + np.pi / 2, np.pi) - np.pi / 2
    ok = np.abs(fd1) < 0.1  # skip wheels that wrap across the stop inside the stencil
    np.testing.assert_allclose(d1[ok], fd1[ok] / (2 * h), rtol=1e-4, atol=1e-4)
    fd2 = (b[2] - 2 * b[1] + b[0]) / h**2
    np.testing.assert_allclose(d2[ok], fd2[ok], rtol=1e-3, atol=1e-2)


@pytest.mark.parametrize("seed", range(5))
def test_wheel_speed_formula_is_rolling_without_slip(seed):
    """r φ̇ = μ(s⊥2 − b ẑ)·λ − b β̇ makes the kinematic robot's least-squares slip vanish and
    reproduces the twist ξ̇ = μ (v, −u, w), with the steering moving at β̇."""
    rng = np.random.default_rng(seed)
    lam = _unit(rng.normal(size=3))
    mu = rng.uniform(-1, 1)
    beta = steering_from_lambda(lam, GEOM)
    beta_rate = rng.uniform(-2, 2, size=GEOM.n)
    phidot = wheel_speeds(lam, mu, GEOM, beta_rate=beta_rate)
    twist, slip = twist_from_wheels(beta, beta_rate, phidot, GEOM)
    assert slip < 1e-9
    np.testing.assert_allclose(twist, twist_from_eta(lam, mu), atol=1e-9)


@pytest.mark.parametrize("seed", range(5))
def test_wheel_acceleration_formula_matches_finite_differences(seed):
    """d/dt of r φ̇ along λ(t), μ(t): (s⊥2 − b ẑ)·(μ λ̇ + μ̇ λ) − b β̈ (the s⊥2′ term vanishes)."""
    rng = np.random.default_rng(seed)
    lam0 = _unit(rng.normal(size=3))
    axis = rng.normal(size=3)
    w, mu0, mudot = 0.3, rng.uniform(-1, 1), rng.uniform(-1, 1)
    h = 1e-5

    def rphi(t):
        lam = _path(lam0, axis, w * t)
        lamd = _path(lam0, axis, w * (t + 1e-6))
        lamm = _path(lam0, axis, w * (t - 1e-6))
        bd = (steering_from_lambda(lamd, GEOM) - steering_from_lambda(lamm, GEOM)) / 2e-6
        return GEOM.r * wheel_speeds(lam, mu0 + mudot * t, GEOM, beta_rate=bd)

    fd = (rphi(h) - rphi(-h)) / (2 * h)
    lam = lam0
    dlam = (_path(lam0, axis, w * h) - _path(lam0, axis, -w * h)) / (2 * h)
    ddlam = (_path(lam0, axis, w * h) - 2 * lam0 + _path(lam0, axis, -w * h)) / h**2
    _, bdd = steering_path_derivatives(lam, dlam, ddlam, GEOM)
    _, s2 = s_perp(steering_from_lambda(lam, GEOM), GEOM)
    s2b = s2.copy()
    s2b[:, 2] -= GEOM.b
    analytic = s2b @ (mu0 * dlam + mudot * lam) - GEOM.b * bdd
    np.testing.assert_allclose(analytic, fd, rtol=1e-3, atol=1e-3)


# ------------------------------------------------------------------ building blocks


def test_nearer_target_flips_both():
    lam, mu = nearer_target([0, 0, 1], [0, 0.1, -1], 0.5)
    np.testing.assert_allclose(lam, [0, -0.1, 1])
    assert mu == -0.5


def test_target_mu_is_clamped_to_every_wheels_speed_limit():
    """μ_d is clamped at λ_d to the largest |μ| for which every wheel's |φ̇| stays within
    ``mu_headroom`` of its limit (``info["mu_target"]``); a feasible μ_d passes as it is."""
    lam = _unit([0.2, 1.0, 0.3])
    beta = steering_from_lambda(lam, GEOM)
    st0 = initial_state(lam, beta, np.zeros(GEOM.n), GEOM)
    cfg = ICRControllerConfig()

    def target(mu_d):
        return icr_control_step(st0, lam, 0.0, beta, np.zeros(GEOM.n), lam, mu_d, GEOM, LIM, cfg, DT)[1].info

    info = target(100.0)
    np.testing.assert_allclose(info["lam_target"], lam, rtol=0, atol=1e-15)  # the target as it is
    mu = info["mu_target"]
    assert np.max(np.abs(wheel_speeds(lam, mu, GEOM))) == pytest.approx(cfg.mu_headroom * LIM.wheel_speed_max)
    assert target(-100.0)["mu_target"] == -mu
    assert target(0.1)["mu_target"] == 0.1


def _coordinated(lam, mu, lam_d, mu_d, config):
    """:func:`control.icr.kernels_motion.coordinated_row` of each row, from rest in λ at μ (the
    wheels at F(λ), rolling): (λ, μ, κ, β̇_c, φ̇_c, φ̇ before)."""
    c = compiled_constants(GEOM, LIM, config, DT)
    out = []
    for lam_i, mu_i, lam_d_i, mu_d_i in zip(lam, mu, lam_d, mu_d):
        beta = steering_from_lambda(lam_i, GEOM)
        phidot = mu_i * wheel_speed_coefficients(lam_i, GEOM, beta) / GEOM.r
        lam_o, lam_rate_o, beta_o, rate_o, phidot_o = np.empty(3), np.empty(3), *np.empty((3, GEOM.n))
        mu_o, kappa, _ = coordinated_row(c, np.zeros((N_WS, max(GEOM.n, 3))), lam_i, mu_i, np.zeros(3), beta,
                                         np.zeros(GEOM.n), phidot, lam_d_i, mu_d_i, False, lam_o, lam_rate_o, beta_o,
                                         rate_o, phidot_o)
        out.append((lam_o, mu_o, kappa, rate_o, phidot_o, phidot))
    return [np.array(x) for x in zip(*out)]


def test_mu_own_scale_lets_mu_ramp_while_lambda_turns():
    """``mu_own_scale``: when the steering limits slow a quick turn of λ (κ < 1), μ still takes
    its ramp step as far as the wheel speed and acceleration limits allow; the commands stay
    within every limit and λ moves exactly as without it."""
    lam = np.array([[1.0, 0.0, 0.0], [0.6, 0.0, 0.8]])
    lam_d = np.array([[0.0, 1.0, 0.0], [0.0, 0.6, 0.8]])
    mu, mu_d = np.array([0.2, 0.3]), np.array([1.0, 1.0])
    off = _coordinated(lam, mu, lam_d, mu_d, ICRControllerConfig())
    on = _coordinated(lam, mu, lam_d, mu_d, ICRControllerConfig(mu_own_scale=True))
    assert np.all(off[2] < 1.0)  # κ: the steering limits slow the turn
    np.testing.assert_array_equal(on[0], off[0])  # λ moves the same
    assert np.all(on[1] > off[1] + 1e-3)  # μ further toward μ_d
    rate_c, phidot_c, phidot = on[3], on[4], on[5]
    assert not limit_violations(rate_c, rate_c / DT, phidot_c, (phidot_c - phidot) / DT, LIM).any()


@pytest.mark.parametrize("k", range(4))
def test_project_off_axes_keeps_wheel_k_still(k):
    lam = _unit([0.3, 1.0, 0.1])
    for target in (GEOM.s_unit[k], -GEOM.s_unit[k]):
        out, hit = project_off_axes(target, lam, GEOM, np.deg2rad(3))
        assert hit == k
        assert lambda_distance(out, GEOM.s_unit[k]) == pytest.approx(np.deg2rad(3), abs=1e-9)
    # along the great circle through s_k, β_k does not change
    out, _ = project_off_axes(GEOM.s_unit[k], lam, GEOM, np.deg2rad(3))
    d = steering_from_lambda(out, GEOM)[k] - steering_from_lambda(lam, GEOM)[k]
    assert abs(np.mod(d + np.pi / 2, np.pi) - np.pi / 2) < 1e-9


def test_arc_blocked_detects_stop_crossing():
    x, y = eta_from_twist(np.array([1.0, 0, 0]))[0], eta_from_twist(np.array([0, 1.0, 0]))[0]
    assert arc_blocked(x, y, GEOM, np.deg2rad(3), np.deg2rad(0.5)) == "stop"
    small = eta_from_twist(np.array([1.0, 0.2, 0]))[0]
    assert arc_blocked(x, small, GEOM, np.deg2rad(3), np.deg2rad(0.5)) is None


# ------------------------------------------------------------------ closed loop on the bench


def _run(targets, ctl=None, robot=None, kick=None):
    """Drive the kinematic robot through [(λ_d, μ_d, steps)], checking every command."""
    ctl = ctl or ICRController(GEOM, LIM, DT)
    robot = robot or KinematicRobot.at_rest(GEOM)
    log = []
    i = 0
    for lam_d, mu_d, steps in targets:
        for _ in range(steps):
            lam_hat = ctl.state.lam if ctl.state is not None else np.array([0, 0, 1.0])
            mu_hat = ctl.state.mu if ctl.state is not None else 0.0
            beta_meas = robot.beta.copy()
            if kick is not None and i == kick[0]:
                beta_meas = kick[1](beta_meas)
            cmd = ctl.step(lam_hat, mu_hat, beta_meas, robot.phidot, lam_d, mu_d)
            assert all(np.all(np.isfinite(x)) for x in (cmd.beta, cmd.phidot, cmd.beta_rate, cmd.phiddot))
            assert not limit_violations(cmd.beta_rate, cmd.beta_accel, cmd.phidot, cmd.phiddot, LIM).any(), i
            assert np.all(cmd.beta > GEOM.steer_min) and np.all(cmd.beta <= GEOM.steer_max)
            twist, slip = robot.step(cmd.beta, cmd.phidot, DT)
            log.append((cmd.info["mode"], slip, twist, cmd))
            i += 1
    return ctl, robot, log


def test_straight_then_turn_no_slip_and_reaches_target():
    x = eta_from_twist(np.array([1.0, 0, 0]))[0]
    turn = eta_from_twist(np.array([0.8, 0.1, 0.5]))[0]
    ctl, robot, log = _run([(x, 0.8, 150), (turn, 0.7, 150)])
    assert ctl.mode == Mode.RUNNING
    assert lambda_distance(ctl.state.lam, turn) < 1e-6
    assert ctl.state.mu == pytest.approx(0.7, abs=1e-9)
    # coordinated: wheels never fight while running
    assert max(s for m, s, *_ in log if m == Mode.RUNNING) < 1e-6


@pytest.mark.parametrize("k", range(4))
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_icr_exactly_on_each_steering_axis(k, sign):
    start = eta_from_twist(np.array([0.5, 0.2, 0.4]))[0]
    ctl, robot, log = _run([(start, 0.5, 100), (sign * GEOM.s_unit[k], sign * 0.5, 150)])
    assert lambda_distance(ctl.state.lam, GEOM.s_unit[k]) == pytest.approx(np.deg2rad(3), abs=1e-6)
    assert ctl.mode == Mode.RUNNING


def test_lambda_sign_swap_is_the_same_motion():
    lam = eta_from_twist(np.array([0.6, 0.3, 0.2]))[0]
    ctl, robot, log = _run([(lam, 0.6, 100)] + [(s * lam, s * 0.6, 1) for s in (-1, 1) * 20])
    assert all(m == Mode.RUNNING for m, *_ in log[90:])
    betas = np.array([c.beta for *_, c in log[100:]])
    assert np.ptp(betas, axis=0).max() < 1e-9  # wheels do not move
    assert ctl.state.mu * np.sign(np.dot(ctl.state.lam, lam)) == pytest.approx(0.6)


def test_mu_beyond_limits_is_clamped():
    lam = eta_from_twist(np.array([0.3, 0.0, 1.0]))[0]
    ctl, robot, log = _run([(lam, 1e6, 300), (lam, -1e6, 300)])
    phid = np.array([c.phidot for *_, c in log])
    assert np.max(np.abs(phid)) <= LIM.wheel_speed_max
    assert np.max(np.abs(phid)) == pytest.approx(LIM.wheel_speed_max * ICRControllerConfig().mu_headroom, rel=1e-3)


def test_zero_command_does_not_swing_wheels():
    lam = eta_from_twist(np.array([0.6, 0.3, 0.2]))[0]
    ctl, robot, log = _run([(lam, 0.6, 100), (lam, 0.0, 100)])
    beta_stop = log[100][3].beta
    for target in ([0, 0, 1.0], [1.0, 0, 0], GEOM.s_unit[0]):
        ctl, robot, log2 = _run([(target, 0.0, 50)], ctl, robot)
        np.testing.assert_allclose([c.beta for *_, c in log2], np.broadcast_to(beta_stop, (50, 4)), atol=1e-12)
        assert all(m == Mode.RUNNING for m, *_ in log2)
    assert abs(ctl.state.mu) == 0.0


def test_state_machine_on_stop_crossing():
    x = eta_from_twist(np.array([1.0, 0, 0]))[0]
    y = eta_from_twist(np.array([0, 1.0, 0]))[0]
    ctl, robot, log = _run([(x, 1.0, 150), (y, 1.0, 250)])
    modes = [m for m, *_ in log[150:]]
    seq = [modes[0]] + [b for a, b in zip(modes, modes[1:]) if a != b]
    assert seq == [Mode.STOPPING, Mode.RECONFIGURING, Mode.RUNNING]
    assert ctl.state.events == 2  # the start (rotation -> translation crosses a stop) and the corner
    # stopped before reconfiguring: no motion while the wheels turn in place
    speeds = [np.linalg.norm(t) for m, s, t, c in log if m == Mode.RECONFIGURING]
    assert max(speeds) < 1e-9
    assert lambda_distance(ctl.state.lam, y) < 1e-9


def _side_target(radius):
    """λ of a turn about a point ``radius`` [m] to the side at unit forward speed (the paper
    track's rounded corner is 0.40 m: wheels 1 and 2 3.5° inside their stops)."""
    return eta_from_twist(np.array([0.0, 1.0, 1.0 / radius]))[0]


def _hold_run(targets, config=None):
    """_run, with the state's held_miss and the step's held flag after every period."""
    ctl = ICRController(GEOM, LIM, DT, config)
    robot = KinematicRobot.at_rest(GEOM)
    out = []
    for lam_d, mu_d, steps in targets:
        for _ in range(steps):
            lam_hat = ctl.state.lam if ctl.state is not None else np.array([0, 0, 1.0])
            mu_hat = ctl.state.mu if ctl.state is not None else 0.0
            prev = 0.0 if ctl.state is None else ctl.state.held_miss
            lam_before = None if ctl.state is None else ctl.state.lam.copy()
            cmd = ctl.step(lam_hat, mu_hat, robot.beta.copy(), robot.phidot, lam_d, mu_d)
            assert not limit_violations(cmd.beta_rate, cmd.beta_accel, cmd.phidot, cmd.phiddot, LIM).any()
            robot.step(cmd.beta, cmd.phidot, DT)
            out.append((cmd.info["mode"], bool(cmd.info.get("held_at_stop")), prev, ctl.state.held_miss, lam_before,
                        cmd.info["mu_target"]))
    return ctl, out


def test_target_past_a_stop_is_held_until_it_has_missed_the_hold_distance():
    """Past its stop by more than a graze (a 0.5 m turn after the 0.40 m one, at 1 m/s: 3.6° from
    the nearest point of the current cell's boundary, ~3.8° from the hold point ``stop_hold_margin``
    inside it, a twist difference of 0.066 m/s > ``stop_hold_speed``),
    the target is held at the cell's nearest point while the motion the hold misses,
    max(|μ_d|, |μ|)·‖λ_hold − λ_d‖ per second, adds up to ``stop_hold_distance``; the period that
    would exceed it stops the robot, which reconfigures and reaches the target."""
    cfg = ICRControllerConfig()
    lam_in, lam_past = _side_target(0.40), _side_target(0.50)
    assert arc_blocked(lam_in, lam_past, GEOM, cfg.axis_margin, cfg.arc_step) == "stop"
    ctl, out = _hold_run([(lam_in, 1.0, 150), (lam_past, 1.0, 250)])
    run = out[150:]
    first_stop = [m for m, *_ in run].index(Mode.STOPPING)
    assert first_stop > 0 and all(held for _, held, *_ in run[:first_stop])
    for _, _, prev, now, lam_before, mu_t in run[:first_stop]:
        point, angle = stop_hold_point_batch(lam_before[None], lam_past[None], GEOM, cfg.stop_hold_margin)
        assert 3.57 < np.rad2deg(angle[0]) < 3.59 + 2 * np.rad2deg(cfg.stop_hold_margin)  # 3.58° on the circle
        miss = max(abs(mu_t), 1.0) * np.linalg.norm(point[0] - lam_past) * DT  # μ = 1 m/s on the 0.40 m turn
        assert now == pytest.approx(prev + miss, rel=1e-9) and now <= cfg.stop_hold_distance
    # stopped in the period that would have taken the missed motion past the distance
    assert run[first_stop - 1][3] + miss > cfg.stop_hold_distance
    assert first_stop == int(cfg.stop_hold_distance // miss)
    assert ctl.mode == Mode.RUNNING and lambda_distance(ctl.state.lam, lam_past) < 1e-6


def test_grazing_target_is_held_for_good_and_jitter_never_stops():
    """A target that only grazes a stop (a 0.45 m turn: 1.2° beyond, 0.022 m/s of missed motion at
    1 m/s, below ``stop_hold_speed``) is held at the stop for as long as it stays: the wheels are
    not turned by π for it; a target jittering across the stop never stops the robot either; the
    held λ sits on the current side of the stop, within 1e-6 of the cell's nearest point."""
    lam_in, lam_graze = _side_target(0.40), _side_target(0.45)
    ctl, out = _hold_run([(lam_in, 1.0, 150), (lam_graze, 1.0, 300)])
    assert all(m == Mode.RUNNING for m, *_ in out[1:]) and all(held for _, held, *_ in out[150:])
    assert all(prev == 0.0 and now == 0.0 for _, _, prev, now, *_ in out[150:])
    point, _ = stop_hold_point_batch(ctl.state.lam[None], lam_graze[None], GEOM, ICRControllerConfig().stop_hold_margin)
    assert lambda_distance(ctl.state.lam, point[0]) < 1e-6
    assert np.all(np.abs(steering_from_lambda(ctl.state.lam, GEOM) - steering_from_lambda(lam_in, GEOM)) < np.pi / 2)
    jitter = [(lam_in, 1.0, 150)] + [(t, 1.0, 2) for t in (_side_target(0.5), lam_in) * 50]
    _, out = _hold_run(jitter)
    assert all(m == Mode.RUNNING for m, *_ in out[1:])


def test_target_far_beyond_a_stop_stops_at_once():
    """Beyond ``stop_hold_angle`` (a 0.8 m turn: 15.7° beyond, with the angle at 10°) no hold:
    the robot stops in the first period."""
    cfg = ICRControllerConfig(stop_hold_angle=np.deg2rad(10.0))
    _, out = _hold_run([(_side_target(0.40), 1.0, 150), (_side_target(0.8), 1.0, 5)], cfg)
    assert out[150][0] == Mode.STOPPING and not out[150][1]
    _, out = _hold_run([(_side_target(0.40), 1.0, 150), (_side_target(0.8), 1.0, 5)])
    assert out[150][0] == Mode.RUNNING and out[150][1]  # 15.7° < 30°: held, within the distance


def test_hold_slides_along_a_stop_circle():
    """A target just outside wheel 0's stop circle and moving along it (a path that keeps a wheel
    at ±90°, as a tri robot's translation along X or the icr-axis scenario does) is followed along
    the circle: held throughout, never stopped, λ within 1e-3 rad of the target's foot on the
    circle, ``stop_hold_margin`` inside it. (Held at one point of the circle, as the arc's last
    sample was, the λ would stay behind: the drift that made the controller flip that wheel back
    and forth.)"""
    normals = np.empty((GEOM.n, 3))
    stop_normals(GEOM.a_minus_l, GEOM.a_perp, float(GEOM.steer_max), normals)
    n0 = normals[0]
    u0 = _unit(np.cross(n0, GEOM.s_unit[0]))
    v0 = _unit(np.cross(n0, u0))
    on_circle = lambda a: np.cos(a) * u0 + np.sin(a) * v0  # noqa: E731
    # a stretch of the circle far from the other wheels' stop circles and from the axes
    grid = np.linspace(0.0, 2 * np.pi, 721)
    clear = np.array([min(np.min(np.abs(normals[1:] @ on_circle(a))),
                          np.min(np.linalg.norm(np.cross(on_circle(a), GEOM.s_unit), axis=1))) for a in grid])
    a0 = grid[int(np.argmax(clear))]
    assert clear.max() > 0.2
    start = _unit(on_circle(a0) + 0.01 * n0)
    assert arc_blocked(start, _unit(on_circle(a0) - 0.01 * n0), GEOM, np.deg2rad(3), np.deg2rad(0.5)) == "stop"
    path = [_unit(on_circle(a) - 0.004 * n0) for a in a0 + np.linspace(0.0, 0.1, 60)]
    ctl, out = _hold_run([(start, 0.5, 150)] + [(t, 0.5, 3) for t in path])
    assert all(m == Mode.RUNNING for m, *_ in out[150:])
    assert sum(held for _, held, *_ in out[150:]) > 150
    foot = _unit(path[-1] - np.dot(path[-1], n0) * n0)
    assert lambda_distance(ctl.state.lam, foot) < ICRControllerConfig().stop_hold_margin + 1e-3


@settings(max_examples=200, deadline=None)
@given(st.tuples(*[st.floats(-1, 1)] * 3).filter(lambda v: np.linalg.norm(v) > 0.1),
       st.tuples(*[st.floats(-1, 1)] * 3).filter(lambda v: np.linalg.norm(v) > 0.1),
       st.integers(0, 2**31 - 1))
def test_hold_point_is_the_nearest_point_of_the_cell(lam, lam_d, seed):
    """Where λ_d is outside λ's cell (the region no stop circle cuts), the hold point is strictly
    inside it, and no point of the cell near λ_d is nearer to λ_d (random samples) by more than
    the hold's margin into the cell (at a vertex it is moved off two circles)."""
    lam, lam_d = _unit(lam), _unit(lam_d)
    normals = np.empty((GEOM.n, 3))
    stop_normals(GEOM.a_minus_l, GEOM.a_perp, float(GEOM.steer_max), normals)
    # on a stop circle (λ = (1, 0, 0), λ_d = (0.75, 0.75, 2e-16): hypothesis found both) the side,
    # and so whether λ_d is outside, is decided by rounding, which differs with and without JIT
    assume(np.all(np.abs(normals @ lam) > 1e-9) and np.all(np.abs(normals @ lam_d) > 1e-9))
    side = np.where(normals @ lam >= 0, 1.0, -1.0)
    margin = ICRControllerConfig().stop_hold_margin
    point, angle = stop_hold_point_batch(lam[None], lam_d[None], GEOM, margin)
    outside = np.any(side * (normals @ lam_d) < 0)
    if not outside:
        assert angle[0] == -1.0
        return
    assert angle[0] >= 0.0
    assert np.all(side * (normals @ point[0]) > 0)
    rng = np.random.default_rng(seed)
    q = lam_d + rng.normal(scale=rng.uniform(0.01, 1.0), size=(500, 3))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    inside = np.all(side * (q @ normals.T) > 0, axis=1)
    if np.any(inside):
        assert angle[0] <= np.min(np.arccos(np.clip(q[inside] @ lam_d, -1, 1))) + 2 * margin + 1e-6


def test_reconfiguration_follows_a_new_target_only_for_a_motion_that_matters():
    """While the wheels turn in place, a new target that would need another stop replaces the one
    being reached only if its motion differs from it by ``stop_hold_speed`` or more (|μ_d| times
    the chord between the two λ): a slow target's λ_d, which feedback noise swings anywhere, does
    not make the reconfiguration chase it."""
    x = eta_from_twist(np.array([1.0, 0, 0]))[0]
    y = eta_from_twist(np.array([0, 1.0, 0]))[0]
    for mu_d, follows in ((0.02, False), (0.5, True)):
        ctl = ICRController(GEOM, LIM, DT)
        robot = KinematicRobot.at_rest(GEOM)
        ctl.reset(x, robot.beta + 1.0, robot.phidot)  # wheels far from F(x): starts RECONFIGURING for x
        assert ctl.mode == Mode.RECONFIGURING
        ctl.step(x, 0.0, robot.beta + 1.0, robot.phidot, x, mu_d)
        assert lambda_distance(ctl.state.reconfig_lam, x) < 1e-12
        ctl.step(x, 0.0, robot.beta + 1.0, robot.phidot, y, mu_d)  # y needs a stop from x
        assert (lambda_distance(ctl.state.reconfig_lam, y) < 1e-12) == follows


def test_kicked_wheel_triggers_stop_and_reconfigure():
    x = eta_from_twist(np.array([1.0, 0.1, 0]))[0]

    def kick(beta):
        beta = beta.copy()
        beta[2] = GEOM.wrap_steering(beta[2] + 1.0)
        return beta

    ctl, robot, log = _run([(x, 1.0, 300)], kick=(150, kick))
    assert log[150][0] == Mode.STOPPING
    assert log[150][3].info["event"] == "kick"
    assert ctl.mode == Mode.RUNNING


def test_random_start_reconfigures_first():
    rng = np.random.default_rng(3)
    beta0 = rng.uniform(-1.5, 1.5, size=4)
    st0 = initial_state([0, 0, 1.0], beta0, np.zeros(4), GEOM)
    assert st0.mode == Mode.RECONFIGURING


def test_bad_input_raises():
    ctl = ICRController(GEOM, LIM, DT)
    with pytest.raises(ValueError):
        ctl.step([0, 0, 1.0], 0.0, np.zeros(4), np.zeros(4), [0, 0, 0.0], 1.0)
    with pytest.raises(ValueError):
        ctl.step([0, 0, 1.0], 0.0, np.zeros(4), np.zeros(4), [0, 0, 1.0], np.nan)
    with pytest.raises(ValueError):
        ctl.step([0, 0, 1.0], 0.0, np.zeros(3), np.zeros(4), [0, 0, 1.0], 1.0)
    with pytest.raises(ValueError):
        ActuatorLimits(steer_rate_max=-1.0)
    with pytest.raises(ValueError):
        ICRController(GEOM, LIM, 0.0)


@pytest.mark.parametrize("args", [(None,), ("geom",), (GEOM, "limits"), (GEOM, LIM, "0.02"), (GEOM, LIM, True),
                                  (GEOM, LIM, DT, {"stop_hold_distance": 1.0}), (LIM, GEOM)])
def test_constructor_refuses_wrong_types(args):
    """New-user trial: ``ICRController(None)`` was accepted and failed at the first step()."""
    with pytest.raises(TypeError, match="geom|limits|config|dt"):
        ICRController(*args)


lam_strategy = st.tuples(*[st.floats(-1, 1)] * 3).filter(lambda v: np.linalg.norm(v) > 1e-3)


@settings(max_examples=15, deadline=None)
@given(st.lists(st.tuples(st.one_of(lam_strategy, st.sampled_from([tuple(s) for s in GEOM.s_unit])),
                          st.floats(-5, 5), st.integers(1, 30)), min_size=1, max_size=5))
def test_limits_never_exceeded_on_random_target_sequences(seq):
    _run([(np.array(lam), mu, n) for lam, mu, n in seq])


def test_great_circle_second_derivative_by_finite_differences():
    """λ′ = k(λ_d − (λ·λ_d)λ) gives λ″ = k²((2c² − 1)λ − c λ_d), c = λ·λ_d, by finite differences
    of the integrated flow; the form k²(c λ_d − λ) once circulated for it is wrong."""
    rng = np.random.default_rng(0)
    lam, lam_d, k = _unit(rng.normal(size=3)), _unit(rng.normal(size=3)), 0.7

    def flow(x, h):
        f = lambda y: k * (lam_d - np.dot(y, lam_d) * y)  # noqa: E731
        k1 = f(x)
        k2 = f(x + h / 2 * k1)
        k3 = f(x + h / 2 * k2)
        k4 = f(x + h * k3)
        return x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)

    h = 1e-4
    fd = (flow(lam, h) - 2 * lam + flow(lam, -h)) / h**2
    c = np.dot(lam, lam_d)
    np.testing.assert_allclose(fd, k * k * ((2 * c * c - 1) * lam - c * lam_d), atol=1e-5)
    assert np.linalg.norm(fd - k * k * (c * lam_d - lam)) > 0.1


def test_time_scaled_wheel_acceleration_includes_the_coupling_terms():
    """With s(t), r φ̇ = μ(s) c(λ(s)) − b β′ ṡ, so r φ̈ = (s⊥2 − b ẑ)·(μλ′ + μ′λ) ṡ − b(β″ṡ² + β′s̈):
    φ̈ = φ̇′ ṡ holds only for ṡ = 1, s̈ = 0 (checked by finite differences)."""
    rng = np.random.default_rng(1)
    lam0, axis = _unit(rng.normal(size=3)), rng.normal(size=3)
    mu0, dmu = 0.4, -0.3
    s_of_t = lambda t: 0.3 * t + 0.4 * t * t  # noqa: E731

    def rphi(t, h=1e-6):
        s = s_of_t(t)
        sdot = 0.3 + 0.8 * t
        bp = (steering_from_lambda(_path(lam0, axis, s + h), GEOM)
              - steering_from_lambda(_path(lam0, axis, s - h), GEOM)) / (2 * h)
        return GEOM.r * wheel_speeds(_path(lam0, axis, s), mu0 + dmu * s, GEOM, beta_rate=bp * sdot)

    t, h = 0.5, 1e-4
    fd = (rphi(t + h) - rphi(t - h)) / (2 * h)
    s, sdot, sddot = s_of_t(t), 0.3 + 0.8 * t, 0.8
    e = 1e-4
    lam = _path(lam0, axis, s)
    dlam = (_path(lam0, axis, s + e) - _path(lam0, axis, s - e)) / (2 * e)
    ddlam = (_path(lam0, axis, s + e) - 2 * lam + _path(lam0, axis, s - e)) / e**2
    bp, bpp = steering_path_derivatives(lam, dlam, ddlam, GEOM)
    _, s2 = s_perp(steering_from_lambda(lam, GEOM), GEOM)
    s2b = s2.copy()
    s2b[:, 2] -= GEOM.b
    mu = mu0 + dmu * s
    analytic = (s2b @ (mu * dlam + dmu * lam)) * sdot - GEOM.b * (bpp * sdot**2 + bp * sddot)
    np.testing.assert_allclose(analytic, fd, rtol=2e-3, atol=2e-3)
    path_form = ((s2b @ (mu * dlam + dmu * lam)) - GEOM.b * bpp) * sdot
    assert np.max(np.abs(path_form - fd)) > 1e-2


def test_reconfigurations_end_when_wheels_stop_where_stiction_holds_them():
    """On the default ("paper") robot the steering's stiction and the tread hold a wheel at rest
    up to a few degrees from its target, beyond reconfig_tol: the controller resumes once the
    measured wheels have stopped within reconfig_hold_tol instead of waiting for the timeout."""
    from numba.core import config as numba_config

    from control.icr.config import ICRControllerConfig, Mode
    from control.rollout import run_episode

    if numba_config.DISABLE_JIT:  # test_icr_compiled.py runs this file without JIT
        pytest.skip("the env runs only compiled (its reward terms must be numba functions)")
    from control.path_controllers import ICRPathController

    # without look-ahead: paper's excursions are stops (with it, the plan holds through them)
    log = run_episode(ICRPathController(lookahead=None), "paper", seed=0, max_time=40.0)
    recon = np.r_[0, (log.mode == int(Mode.RECONFIGURING)).astype(int), 0]
    edges = np.flatnonzero(np.diff(recon))
    lengths = (edges[1::2] - edges[::2]) * log.dt
    assert lengths.size >= 3
    assert np.all(lengths < ICRControllerConfig().reconfig_timeout - 0.1), lengths
