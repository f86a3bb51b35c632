"""Issue 31 (reliability v3), control: the numbers a user can trust.

* ``limit_violation_steps`` is measured on the set-points themselves (their differences over the
  control period, the first against the measured state at the reset; the steering angle against
  its stops; φ̇ against its limit), whatever rates a controller declares, also for a controller
  that sends its own action (:class:`control.limits.SetpointLimitCheck`);
* set-points that are not real numbers (strings, complex, booleans), NaN set-points and NaN
  declared rates are refused, naming the controller and the field
  (:func:`control.commands.checked_command`);
* a controller that is not independent across the robots of a batch is found by
  :func:`control.checks.check_batch_independence`.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from azimut_env.params import ActuatorLimits, action_from_setpoints, setpoints_from_action
from control.checks import BatchDependenceError, check_batch_independence
from control.commands import WheelCommand, checked_command
from control.controller import make_controller
from control.episode import episode_metrics
from control.feedforward import FeedForwardController
from control.limits import LIMIT_KINDS, RTOL, SetpointLimitCheck
from control.rollout import run_episode, run_episodes

LIM = ActuatorLimits()
DT = 0.02


def _recount(log, limits: ActuatorLimits = LIM) -> np.ndarray:
    """(T,) bool from the log alone for the steps k >= 2 (whose previous two set-points are in the
    log): the finite differences of the logged set-points against the limits."""
    b, p = log.beta_cmd, log.phidot_cmd
    rate = np.diff(b, axis=0) / log.dt
    acc = np.diff(rate, axis=0) / log.dt
    wacc = np.diff(p, axis=0) / log.dt
    s = 1.0 + RTOL
    over = (np.any(np.abs(rate[1:]) > limits.steer_rate_max * s, axis=1)
            | np.any(np.abs(acc) > limits.steer_accel_max * s, axis=1)
            | np.any(np.abs(p[2:]) > limits.wheel_speed_max * s, axis=1)
            | np.any(np.abs(wacc[1:]) > limits.wheel_accel_max * s, axis=1)
            | np.any((b[2:] > limits.steer_max * s) | (b[2:] < limits.steer_min * s), axis=1))
    return over


class SetpointsOnly:
    """A user's controller: the feed-forward driver's β and φ̇ with no rates declared (or, with
    ``lie``, rates declared zero)."""

    def __init__(self, lie: bool = False) -> None:
        self.name, self.lie, self.inner = "setpoints-only", lie, FeedForwardController()

    def reset(self, env, rows):
        self.inner.reset(env, rows)

    def act(self, env, obs):
        cmd = self.inner.act(env, obs)
        zero = np.zeros_like(cmd.beta) if self.lie else None
        return WheelCommand(beta=cmd.beta, phidot=cmd.phidot, beta_rate=zero, beta_accel=zero, phiddot=zero)


# ------------------------------------------------------------------ 1. the set-points are checked


@pytest.mark.parametrize("lie", [False, True])
def test_a_controller_that_declares_no_rates_or_zero_rates_is_checked_on_its_setpoints(lie):
    """A controller returning β and φ̇ alone scored 0 on ``square`` while its set-points moved at
    over 150 rad/s against a 4 rad/s limit (and so did one declaring zero rates)."""
    log = run_episode(SetpointsOnly(lie=lie), "square", seed=0)
    m = episode_metrics(log)
    rate = np.abs(np.diff(log.beta_cmd, axis=0)) / log.dt
    assert rate.max() > 150.0
    assert m["limit_violation_steps"] >= 100
    np.testing.assert_array_equal(log.violations[2:], _recount(log))
    steer = log.limit_flags[:, LIMIT_KINDS.index("steer_rate")]
    assert steer.sum() >= 100 and steer[1:].tolist() == np.any(rate > LIM.steer_rate_max, axis=1).tolist()


def test_feedforward_on_paper_counts_the_steps_its_setpoints_exceed():
    """The built-in feed-forward driver scored 49 on ``paper`` (its φ̇ alone) where its set-points'
    differences exceed a limit on 93 steps from the third on (|dβ/dt| up to 157 rad/s)."""
    log = run_episode("feedforward", "paper", seed=0)
    assert np.abs(np.diff(log.beta_cmd, axis=0)).max() / log.dt > 150.0
    assert int(np.sum(_recount(log))) == 93
    np.testing.assert_array_equal(log.violations[2:], _recount(log))
    assert episode_metrics(log)["limit_violation_steps"] == int(np.sum(log.violations)) >= 93


class Fixed:
    """Every robot's set-points are ``beta`` (one value for all wheels) and φ̇ = 0; optionally
    declares ``rate`` as its β̇."""

    def __init__(self, beta, rate=None, name="fixed") -> None:
        self.beta, self.rate, self.name = beta, rate, name

    def reset(self, env, rows):
        pass

    def act(self, env, obs):
        shape = env.measured_beta.shape
        rate = None if self.rate is None else np.full(shape, self.rate)
        return WheelCommand(beta=np.full(shape, self.beta), phidot=np.zeros(shape), beta_rate=rate)


def test_a_setpoint_beyond_the_stop_counts_every_step():
    """β = 45 rad was clipped to the stop by the env and not counted."""
    log = run_episode(Fixed(45.0), "paper", seed=0, max_time=0.2)
    assert log.violations.all() and log.limit_flags[:, LIMIT_KINDS.index("steer_range")].all()
    assert episode_metrics(log)["limit_violation_steps"] == log.t.size == 10


def test_a_nan_declared_rate_is_refused_naming_the_controller_and_the_field():
    """A NaN β̇ passed the check (NaN > limit is False)."""
    with pytest.raises(ValueError, match=r"controller 'nan-rate' returned beta_rate with NaN"):
        run_episode(Fixed(0.5, rate=math.nan, name="nan-rate"), "paper", seed=0, max_time=0.1)
    log = run_episode(Fixed(0.5, rate=math.inf, name="inf-rate"), "paper", seed=0, max_time=0.1)
    assert log.limit_flags[:, LIMIT_KINDS.index("steer_rate")].all()  # an infinite rate is over its limit


class OwnAction:
    """Sends its own action (full steering one way then the other, full wheel speed) and declares
    harmless set-points: what the env applies was never checked."""

    name = "own-action"

    def __init__(self, action_scale: float = 1.0) -> None:
        self.k, self.scale = 0, action_scale

    def reset(self, env, rows):
        self.k = 0

    def act(self, env, obs):
        num, n = env.measured_beta.shape
        sign = 1.0 if self.k % 2 == 0 else -1.0
        self.k += 1
        action = np.full((num, 2 * n), sign * self.scale, dtype=np.float32)
        return WheelCommand(beta=env.measured_beta.copy(), phidot=np.zeros((num, n)), action=action)


def test_a_controller_that_sends_its_own_action_is_checked_on_what_the_env_applies():
    log = run_episode(OwnAction(), "paper", seed=0, max_time=0.2)
    assert log.violations.all()
    flags = log.limit_flags
    assert flags[:, LIMIT_KINDS.index("steer_rate")].all() and flags[:, LIMIT_KINDS.index("wheel_accel")].all()
    assert not flags[:, LIMIT_KINDS.index("wheel_speed")].any()  # read back from the action: within [−1, 1]
    assert not flags[:, LIMIT_KINDS.index("steer_range")].any()
    # the trace records what the env applied (read back from the action), not the claimed set-points
    # (found by the repeated review: the trace held 0 while the env steered to ±β_max)
    assert np.abs(log.beta_cmd).max() > 1.0 and np.abs(log.phidot_cmd).min() > 1.0


class HoldMeasured:
    """Holds the measured steering angles of the reset and φ̇ = 0 (``jump``: plus that, in rad, on
    the first period only)."""

    name = "hold"

    def __init__(self, jump: float = 0.0) -> None:
        self.jump, self.beta, self.k = jump, None, 0

    def reset(self, env, rows):
        self.beta, self.k = env.measured_beta.copy(), 0

    def act(self, env, obs):
        beta = self.beta + (self.jump if self.k == 0 else 0.0)
        self.k += 1
        return WheelCommand(beta=beta, phidot=np.zeros_like(beta))


def test_the_first_period_is_differenced_against_the_measured_state_at_the_reset():
    assert not run_episode(HoldMeasured(), "paper", seed=3, max_time=0.2).violations.any()
    # a step of 0.2 rad in the first period: 10 rad/s; back to the hold: −10 rad/s; then the rate's
    # return to 0 (500 rad/s²)
    log = run_episode(HoldMeasured(jump=0.2), "paper", seed=3, max_time=0.2)
    assert log.violations[:3].all() and not log.violations[3:].any()
    assert log.limit_flags[0, LIMIT_KINDS.index("steer_rate")]


def test_the_builtin_controllers_within_their_limits_stay_at_zero():
    """The ICR controller and the setpoint generator reach the limits exactly (to 1e-14 relative):
    the set-points' own differences count no step."""
    logs = [log for spec in ("icr", "twist-setpoint")
            for log in run_episodes(make_controller(spec), ["square", "paper"], [0, 1], max_time=12.0)]
    for log in logs:
        assert not log.violations.any(), (log.controller, log.track.name)


# ------------------------------------------------------------------ the check, property tests


def _within_limits(draws, limits: ActuatorLimits, beta0: np.ndarray) -> list:
    """Set-points whose differences are within the limits: accelerations of [−1, 1] × their limit,
    integrated, the rates and speeds clipped to theirs; a module beyond 1.1 rad turning outward
    brakes at the full acceleration (it stops before its stop at π/2)."""
    beta, phidot, rate = beta0.copy(), np.zeros_like(beta0), np.zeros_like(beta0)
    out = []
    for a_beta, a_phi in draws:
        a_beta = np.where((np.abs(beta) > 1.1) & (beta * rate > 0), -np.sign(rate), a_beta)
        rate = np.clip(rate + a_beta * limits.steer_accel_max * DT, -limits.steer_rate_max, limits.steer_rate_max)
        beta = beta + rate * DT
        phidot = np.clip(phidot + a_phi * limits.wheel_accel_max * DT, -limits.wheel_speed_max, limits.wheel_speed_max)
        out.append((beta.copy(), phidot.copy()))
    return out


accels = st.lists(st.tuples(st.lists(st.sampled_from([-1.0, -0.5, 0.0, 0.5, 1.0]), min_size=4, max_size=4)
                            .map(np.array),
                            st.lists(st.sampled_from([-1.0, 0.0, 1.0]), min_size=4, max_size=4).map(np.array)),
                  min_size=2, max_size=60)


@settings(max_examples=60, deadline=None)
@given(accels, st.floats(-1.1, 1.1), st.booleans())
def test_setpoints_within_the_limits_are_never_counted(draws, start, through_action):
    """Set-points that use the limits to the full, exactly (and as read back from the float32 action
    the env applies), count no step; the same scaled 1 % faster count some."""
    beta0, phidot0 = np.full(4, start), np.zeros(4)
    seq = _within_limits(draws, LIM, beta0)
    check = SetpointLimitCheck(LIM, DT, 1, 4)
    check.reset([0], beta0[None], phidot0[None])
    for beta, phidot in seq:
        if through_action:
            b, p = setpoints_from_action(action_from_setpoints(beta[None], phidot[None], LIM), LIM, 4)
            flags = check.step(b, p, from_action=True)
        else:
            flags = check.step(beta[None], phidot[None])
        assert not flags.any(), flags


@settings(max_examples=60, deadline=None)
@given(st.floats(1.02, 18.0), st.sampled_from(LIMIT_KINDS[:4]), st.booleans())
def test_setpoints_beyond_a_limit_are_counted_by_that_limit(factor, kind, through_action):
    """One period from rest that exceeds one limit by ``factor`` (2 % or more): that limit's flag,
    also through the action."""
    n, zero = 4, np.zeros((1, 4))
    beta, phidot, start_phidot = zero.copy(), zero.copy(), zero.copy()
    if kind == "steer_rate":
        beta[0, 0] = factor * LIM.steer_rate_max * DT  # at most 1.44 rad: within the stop
    elif kind == "steer_accel":
        beta[0, 0] = min(factor, 6.0) * LIM.steer_accel_max * DT * DT  # the rate within its limit
    elif kind == "wheel_speed":
        if through_action:  # an action cannot command beyond the wheel-speed scale
            return
        start_phidot[:] = phidot[:] = factor * LIM.wheel_speed_max  # as fast at the reset: no acceleration
    else:
        phidot[0, 1] = min(factor * LIM.wheel_accel_max * DT, LIM.wheel_speed_max)
    check = SetpointLimitCheck(LIM, DT, 1, n)
    check.reset([0], zero, start_phidot)
    if through_action:
        flags = check.step(*setpoints_from_action(action_from_setpoints(beta, phidot, LIM), LIM, n), from_action=True)
    else:
        flags = check.step(beta, phidot)
    assert flags[0, LIMIT_KINDS.index(kind)], (kind, factor)
    assert not flags[0, LIMIT_KINDS.index("steer_range")]


def test_unlimited_steering_differences_the_short_way_round():
    lim = ActuatorLimits(steer_min=-math.inf, steer_max=math.inf)
    check = SetpointLimitCheck(lim, DT, 1, 1)
    check.reset([0], [[math.pi - 0.01]], [[0.0]])
    flags = check.step([[-math.pi + 0.01]], [[0.0]])  # 0.02 rad across ±π: 1 rad/s, 50 rad/s²
    assert flags[0].tolist() == [False, True, False, False, False]
    check.rate[:] = 1.0
    check.beta[:] = math.pi - 0.01
    assert not check.step([[-math.pi + 0.01 + 4 * math.pi]], [[0.0]]).any()  # another turn of the same angle


# ------------------------------------------------------------------ 2. set-points that are not numbers


BAD_VALUES = {
    "complex": (lambda shape: np.full(shape, 0.5 + 0.25j), "dtype complex128"),
    "bool": (lambda shape: np.ones(shape, dtype=bool), "dtype bool"),
    "strings": (lambda shape: np.full(shape, "0.5"), "dtype <U3"),
    "object": (lambda shape: np.full(shape, None, dtype=object), "dtype object"),
    "a string": (lambda shape: "0.5", "type str"),
    "ragged": (lambda shape: [[0.0] * (shape[1] + 1)] + [[0.0] * shape[1]] * (shape[0] - 1) if shape[0] > 1
               else [[0.0], [0.0, 0.0]], "not an array of real numbers"),
}


class Bad:
    """Returns a bad value for one field (the others fine)."""

    def __init__(self, field: str, kind: str, name: str = "mypkg:My") -> None:
        self.field, self.kind, self.name = field, kind, name

    def reset(self, env, rows):
        pass

    def act(self, env, obs):
        shape = env.measured_beta.shape
        fields = {"beta": env.measured_beta.copy(), "phidot": np.zeros(shape)}
        if self.kind == "nan":
            value = np.zeros(shape)
            value[-1, 1] = math.nan
        elif self.kind == "inf":
            value = np.zeros(shape)
            value[0, 2] = math.inf
        else:
            value = BAD_VALUES[self.kind][0](shape)
        fields[self.field] = value
        return WheelCommand(**fields)


@pytest.mark.parametrize("field", ["beta", "phidot", "beta_rate", "beta_accel", "phiddot"])
@pytest.mark.parametrize("kind", list(BAD_VALUES))
def test_setpoints_that_are_not_real_numbers_are_refused_naming_the_controller_and_the_field(field, kind):
    """Complex set-points lost their imaginary part, ``True`` was read as 1 rad, strings were
    parsed."""
    with pytest.raises(TypeError, match=rf"controller 'mypkg:My' returned {field} (of|that).*"):
        run_episode(Bad(field, kind), "paper", seed=0, max_time=0.1)
    with pytest.raises(TypeError, match=rf"controller 'mypkg:My' returned {field} .*{BAD_VALUES[kind][1]}"):
        checked_command(Bad(field, kind).act(_FakeEnv(2), None), "mypkg:My", 2, 4)


class _FakeEnv:
    def __init__(self, num: int) -> None:
        self.measured_beta = np.zeros((num, 4))


@pytest.mark.parametrize("field", ["beta", "phidot"])
@pytest.mark.parametrize("kind", ["nan", "inf"])
def test_nan_and_inf_setpoints_are_refused_naming_the_controller_and_the_field(field, kind):
    """A NaN set-point was refused as 'set-points contain NaN or inf', naming neither."""
    with pytest.raises(ValueError, match=rf"controller 'mypkg:My' returned {field} with NaN or inf \((nan|inf) "
                                         r"at robot \d, wheel \d"):
        run_episodes(Bad(field, kind), ["paper", "square"], [0, 1], max_time=0.1)


@settings(max_examples=80, deadline=None)
@given(st.sampled_from(["beta", "phidot", "beta_rate", "beta_accel", "phiddot"]),
       st.sampled_from(list(BAD_VALUES) + ["nan"]), st.integers(1, 3))
def test_checked_command_refuses_every_bad_field_and_names_it(field, kind, num):
    cmd = Bad(field, kind, name="x").act(_FakeEnv(num), None)
    with pytest.raises((TypeError, ValueError), match=rf"controller 'x'.*{field}"):
        checked_command(cmd, "x", num, 4)


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 3), st.sampled_from([np.float32, np.float64, np.int64, np.int8]))
def test_checked_command_passes_real_arrays_as_float64_copies(num, dtype):
    beta = np.arange(num * 4).reshape(num, 4).astype(dtype)
    cmd = checked_command(WheelCommand(beta=beta, phidot=beta.tolist()), "x", num, 4)
    assert cmd.beta.dtype == cmd.phidot.dtype == np.float64 and cmd.beta is not beta
    np.testing.assert_array_equal(cmd.beta, beta.astype(np.float64))
    np.testing.assert_array_equal(cmd.phidot, beta.astype(np.float64))


def test_an_action_that_is_not_real_numbers_is_refused_naming_the_controller():
    class ComplexAction(OwnAction):
        def act(self, env, obs):
            cmd = super().act(env, obs)
            return WheelCommand(beta=cmd.beta, phidot=cmd.phidot, action=cmd.action.astype(np.complex64))

    with pytest.raises(TypeError, match="controller 'own-action' returned action of dtype complex64"):
        run_episode(ComplexAction(), "paper", seed=0, max_time=0.1)


# ------------------------------------------------------------------ 3. independence across a batch


class BatchMean:
    """Steers every robot by the batch's mean measured steering (one shared value for all robots)."""

    name = "batch-mean"

    def reset(self, env, rows):
        pass

    def act(self, env, obs):
        beta = np.broadcast_to(env.measured_beta.mean(axis=0), env.measured_beta.shape).copy()
        return WheelCommand(beta=beta, phidot=np.full_like(beta, 2.0))


class SharedNoise:
    """Draws one random generator's numbers for its robots in turn: robot i's draws depend on how
    many robots come before it."""

    name = "shared-noise"

    def reset(self, env, rows):
        self.rng = np.random.default_rng(0)

    def act(self, env, obs):
        beta = env.measured_beta + self.rng.normal(0.0, 1e-3, env.measured_beta.shape)
        return WheelCommand(beta=beta, phidot=np.zeros_like(beta))


@pytest.mark.parametrize("ctl", [BatchMean, SharedNoise])
def test_check_batch_independence_finds_a_dependent_controller(ctl):
    with pytest.raises(BatchDependenceError, match=rf"controller '{ctl.name}' is not independent across the robots "
                                                   r"of a batch: robot \d \(track '\w+', seed \d\)"):
        check_batch_independence(ctl(), max_time=0.2)


@pytest.mark.parametrize("spec", ["feedforward", "twist"])
def test_check_batch_independence_passes_the_builtins(spec):
    check_batch_independence(spec, max_time=0.5)
    check_batch_independence(FeedForwardController(), tracks=("circle", "crab", "paper"), seeds=(4, 5, 6), max_time=0.3)


def test_check_batch_independence_checks_its_arguments():
    with pytest.raises(ValueError, match="at least two robots"):
        check_batch_independence("feedforward", tracks=("paper",), seeds=(0,))
    with pytest.raises(ValueError, match="atol"):
        check_batch_independence("feedforward", atol=math.nan)


def test_mode_events_and_missing_setpoints_refused_naming_controller_and_field():
    """Found by the repeated review: NaN events printed as -9223372036854775808 stops, a mode of 99
    was accepted, and beta=None failed later without naming the controller."""
    from control.commands import WheelCommand, checked_command

    ok = dict(beta=np.zeros((2, 4)), phidot=np.zeros((2, 4)))
    got = checked_command(WheelCommand(**ok, mode=np.array([0, 2]), events=np.array([0, 3])), "mine", 2, 4)
    assert got.mode.dtype == np.int64 and got.events.tolist() == [0, 3]
    for bad, err, words in (
            (dict(events=np.array([np.nan, 0.0])), TypeError, "events of dtype float64"),
            (dict(events=np.array(["7", "0"])), TypeError, "events of dtype"),
            (dict(events=np.array([-5, 0])), ValueError, "events -5 at robot 0"),
            (dict(mode=np.array([0, 99])), ValueError, "mode 99 at robot 1"),
            (dict(mode=np.array([0.0, 1.0])), TypeError, "mode of dtype float64")):
        with pytest.raises(err, match=words):
            checked_command(WheelCommand(**ok, **bad), "mine", 2, 4)
    with pytest.raises(TypeError, match="'mine' returned beta None"):
        checked_command(WheelCommand(beta=None, phidot=np.zeros((2, 4))), "mine", 2, 4)
