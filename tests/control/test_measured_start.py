"""Controllers start from the measured steering angles, and a wheel measured a little past its stop
(the sensor's noise, the stop's compliance) is at that stop, not at the other one: wrapped modulo π
it was, and every controller's first command turned it by π (hex, seed 0: 3 mrad past −π/2 at
reset flagged the first two steps of `icr` and `twist-setpoint` as over the steering limits)."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from azimut_env.params import ActuatorLimits
from azimut_env.vector_env import AzimutVectorEnv
from control.icr.config import Mode
from control.icr.state import initial_state_batch
from control.limits import SetpointLimitCheck
from control.path_controllers import ICRPathController, SetpointPathController
from control.rollout import run_episodes
from control.twist.setpoint import SetpointBatch
from estimation import RobotGeometry

GEOM = RobotGeometry.azimut3()
HALF = math.pi / 2


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(-HALF - 0.05, HALF + 0.05), min_size=4, max_size=4))
def test_measured_angles_are_clipped_into_the_stops(beta):
    beta = np.array(beta)
    start = GEOM.measured_steering(beta)
    assert np.all(start >= GEOM.steer_max - math.pi) and np.all(start <= GEOM.steer_max)
    inside = (beta >= -HALF) & (beta <= HALF)
    assert np.array_equal(start[inside], beta[inside])  # in range: as measured
    assert np.allclose(np.abs(start - beta), np.maximum(np.abs(beta) - HALF, 0.0))  # else the nearer stop


def test_unlimited_steering_keeps_the_measured_angles():
    swerve = RobotGeometry.regular(4, unlimited_steering=True)
    beta = np.array([2.5, -3.0, 0.1, 7.0])
    assert np.array_equal(swerve.measured_steering(beta), beta)


def test_a_wheel_past_its_stop_starts_at_that_stop():
    past = np.array([[-HALF - 0.003, 0.2, -0.2, HALF + 0.002]])
    lam = np.array([[0.0, 0.0, 1.0]])
    state = initial_state_batch(lam, past, np.zeros((1, 4)), GEOM)
    assert np.allclose(state.beta, [[-HALF, 0.2, -0.2, HALF]])
    limits = ActuatorLimits()
    batch = SetpointBatch(1, GEOM, limits, 0.02)
    batch.reset(np.array([0]), past, np.zeros((1, 4)))
    assert np.allclose(batch.beta, [[-HALF, 0.2, -0.2, HALF]])
    check = SetpointLimitCheck(limits, 0.02, 1, 4)  # started as the rollout starts it: where the controllers start
    check.reset(np.array([0]), GEOM.measured_steering(past), np.zeros((1, 4)))
    assert not check.step(np.array([[-HALF + 0.001, 0.2, -0.2, HALF - 0.001]]), np.zeros((1, 4))).any()


def test_hex_episode_start_keeps_the_limits():
    """The hex episode that flagged its first steps (a wheel 3 mrad past −π/2 at reset) now keeps
    the steering limits from the first step, for both controllers that promise to."""
    env = AzimutVectorEnv(num_envs=1, robot="hex", track="figure8")
    env.reset(seed=0)
    assert np.min(env.measured_beta) < -HALF  # the start this test is about
    for controller in (ICRPathController(), SetpointPathController()):
        log = run_episodes(controller, ["figure8"], [0], env_kwargs={"robot": "hex"}, max_time=1.0)[0]
        assert not np.asarray(log.limit_flags).any(), controller.name


def test_a_start_beyond_a_stop_reconfigures_first():
    """hex ``icr-axis``, seed 3: a wheel 6 mrad past +π/2 at reset, and the estimated λ̂ needs it
    there. Modulo π the wheel looked at F(λ̂), so the ICR controller started RUNNING at a λ its
    wheel cannot reach and sat still for 20 s; compared as joint angles (no wrap with stops) it
    starts by reconfiguring, within the limits, and finishes."""
    env = AzimutVectorEnv(num_envs=1, robot="hex", track="icr-axis")
    env.reset(seed=3)
    assert np.max(env.measured_beta) > HALF
    log = run_episodes(ICRPathController(), ["icr-axis"], [3], env_kwargs={"robot": "hex"})[0]
    assert log.completed and log.t[-1] < 12.0, (log.error, log.t[-1])
    assert log.mode[0] == Mode.RECONFIGURING  # from the first step
    assert not np.asarray(log.limit_flags).any()
