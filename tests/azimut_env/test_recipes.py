"""ARCHITECTURE.md's "Where to add" recipes, each followed in a temporary copy of its table (the
module attribute extended for the test): what the recipe promises then holds: the env's spaces,
observation, info, reward and termination change, with nothing else edited. A recipe that goes
stale fails here."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit, types

from azimut_env import doc_tables
from azimut_env.env import AzimutEnv
from azimut_env.physics.layout import RS
from azimut_env.task import arrays, observation, reward, sensors, termination
from azimut_env.task.observation import ObservationField
from azimut_env.task.reward import RewardInput, RewardTerm
from azimut_env.task.termination import EndCondition
from azimut_env.vector_env import AzimutVectorEnv

_W = int(RS.W)


def _run(env, n=40, seed=3, scale=0.5):
    obs, info = env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    out = [(obs, 0.0, False, False, info)]
    for _ in range(n):
        out.append(env.step((scale * rng.uniform(-1, 1, env.action_space.shape)).astype(np.float32)))
        if out[-1][2] or out[-1][3]:
            break
    return out


def _stale_docs() -> bool:
    return bool(doc_tables.stale_files())


# ---------------------------------------------------------------- a reward term: a function and a row


@njit
def _reward_spin(x, k, w):
    return -w * x[RewardInput.ACTION_CHANGE] * 0.5


def test_recipe_reward_term(monkeypatch):
    row = RewardTerm("spin", 0.4, "-", _reward_spin, "−w·‖a − a_prev‖²/2")
    monkeypatch.setattr(reward, "REWARD_TERMS", reward.REWARD_TERMS + (row,))
    env = AzimutEnv(track="circle")
    for _, r, _, _, info in _run(env)[1:]:
        terms = info["reward_terms"]
        assert terms["spin"] == pytest.approx(0.5 * 0.4 / 0.05 * terms["action_rate"])
        assert r == sum(terms.values())
    assert AzimutEnv(track="circle", reward_weights={"spin": 2.0}).config.reward_weights["spin"] == 2.0
    assert "spin" in reward.reward_table() and _stale_docs()  # the docs follow with --write


# ---------------------------------------------------------------- an observation field: a function and a row


@njit
def _obs_qua(ta, i, obs, j):
    obs[i, j] = ta.qua[i]


def test_recipe_observation_field(monkeypatch):
    base = AzimutEnv(track="paper")
    row = ObservationField("qua", (1, 0, 0), (1.0,), True, False, "-", "qua of the readings (eq. 28–29)", _obs_qua)
    monkeypatch.setattr(observation, "OBSERVATION_FIELDS", observation.OBSERVATION_FIELDS + (row,))
    env = AzimutEnv(track="paper")
    assert env.observation_space.shape[0] == base.observation_space.shape[0] + 1
    sl = env.observation_slices()["qua"]
    assert env.observation_space.low[sl] == 0.0 and env.observation_space.high[sl] == 1.0
    for obs, _, _, _, info in _run(env):
        assert obs[sl][0] == np.float32(info["qua"])
    venv = AzimutVectorEnv(num_envs=2, track="paper")
    obs, info = venv.reset(seed=1)
    assert np.array_equal(obs[:, sl][:, 0], info["qua"].astype(np.float32))
    assert "qua" in observation.observation_table() and _stale_docs()


# ---------------------------------------------------------------- an end condition: a function and a row


@njit
def _end_late(ta, i):
    return ta.steps[i] >= 5


def test_recipe_end_condition(monkeypatch):
    row = EndCondition("late", True, _end_late, "5 steps since the reset")
    monkeypatch.setattr(termination, "TERMINATION_TERMS", termination.TERMINATION_TERMS + (row,))
    env = AzimutEnv(track="paper")
    steps = _run(env, n=200)
    *_, (_, r, terminated, _, info) = steps
    assert "late" in steps[0][4] and not steps[0][4]["late"] and len(steps) == 6
    assert terminated and info["late"] and r == sum(info["reward_terms"].values())
    assert info["reward_terms"]["off_track"] == -env.config.reward_weights["off_track"]  # a failure: penalised
    venv = AzimutVectorEnv(num_envs=2, track="paper")
    venv.reset(seed=0)
    _, _, _, _, vinfo = venv.step(np.zeros((2, 8), dtype=np.float32))
    assert vinfo["late"].shape == (2,) and "late" in termination.termination_table() and _stale_docs()


# ---------------------------------------------------------------- a sensor: a model, its readings, an observation row


@njit
def _sense_gyro(ta, rows, action):
    for i in range(rows.shape[0]):
        if rows[i]:
            ta.gyro_m[i] = ta.summary[i, _W]  # a perfect yaw-rate gyro


@njit
def _obs_gyro(ta, i, obs, j):
    obs[i, j] = ta.gyro_m[i]


def test_recipe_sensor(monkeypatch):
    field = arrays.Field("gyro_m", types.float64[::1], lambda t: np.zeros(t.n_robots), "yaw rate read (N,) [rad/s]",
                         True)
    monkeypatch.setattr(arrays, "FIELDS", arrays.FIELDS + (field,))
    monkeypatch.setattr(sensors, "SENSOR_STAGES", sensors.SENSOR_STAGES + (_sense_gyro,))
    row = ObservationField("gyro", (1, 0, 0), (5.0,), False, False, "rad/s", "measured yaw rate", _obs_gyro)
    monkeypatch.setattr(observation, "OBSERVATION_FIELDS", observation.OBSERVATION_FIELDS + (row,))
    env = AzimutEnv(track="circle")
    sl = env.observation_slices()["gyro"]
    steps = _run(env)
    for obs, _, _, _, info in steps:
        assert obs[sl][0] == np.float32(info["twist"][2])
    assert env.unwrapped.task.gyro_m[0] == steps[-1][4]["twist"][2]  # the task's attribute, from its row


# ---------------------------------------------------------------- a robot preset, a track


def test_recipe_robot_preset(monkeypatch, tmp_path):
    from azimut_env import robot_file

    text = robot_file.preset_source("tri")  # a new file: here the tri preset's text
    monkeypatch.setattr(robot_file, "PRESET_NAMES", robot_file.PRESET_NAMES + ("mybot",))
    source = robot_file.preset_source
    monkeypatch.setattr(robot_file, "preset_source", lambda name: text if name == "mybot" else source(name))
    env = AzimutEnv(robot="mybot", track="circle")
    assert env.action_space.shape == (6,) and len(_run(env, n=5)) == 6
    path = tmp_path / "mybot.toml"  # the same file, given by its path
    path.write_text(text, encoding="utf-8")
    assert AzimutEnv(robot=str(path)).action_space.shape == (6,)


def test_recipe_track(monkeypatch):
    from azimut_env.tracks import library

    def oval_track():
        return library.circle_track(radius=2.0)

    monkeypatch.setattr(library, "TRACK_NAMES", library.TRACK_NAMES + ("oval",))
    monkeypatch.setitem(library._BUILDERS, "oval", oval_track)
    env = AzimutEnv(track="oval")
    assert env.unwrapped.track.length == pytest.approx(oval_track().length)
    assert len(_run(env, n=5)) == 6
    env.reset(seed=0, options={"track": "oval"})


# ---------------------------------------------------------------- a randomisation, a perturbation: events


def _bias_jitter(task, i, rng, episode):
    task.sensors.steer_bias[i] += rng.uniform(-0.01, 0.01, task.n)


def _push(task):
    for i in np.flatnonzero(task.steps == 3):
        task.physics.kick(int(i), [0, 1], 0.3)


def test_recipe_events(monkeypatch):
    from azimut_env.task import events

    base = _run(AzimutEnv(track="paper"), n=6)
    monkeypatch.setattr(events, "RESET_EVENTS", events.RESET_EVENTS + (events.Event("jitter", _bias_jitter, ""),))
    jittered = _run(AzimutEnv(track="paper"), n=6)
    beta = AzimutEnv(track="paper").observation_slices()["beta"]
    assert not np.array_equal(base[0][0][beta], jittered[0][0][beta])  # the reset drew it
    venv = AzimutVectorEnv(num_envs=2, track="paper")
    obs, _ = venv.reset(seed=[3, 4])
    assert np.array_equal(obs[0], jittered[0][0])  # robot 0 replays the single env seeded alike
    monkeypatch.setattr(events, "RESET_EVENTS", events.RESET_EVENTS[:-1])
    monkeypatch.setattr(events, "INTERVAL_EVENTS", events.INTERVAL_EVENTS + (events.Event("push", _push, ""),))
    pushed = _run(AzimutEnv(track="paper"), n=6)
    assert all(np.array_equal(a[0], b[0]) for a, b in zip(base[:4], pushed[:4]))  # before the push: the same
    assert not np.array_equal(base[4][4]["twist"], pushed[4][4]["twist"])  # the step of the push differs
