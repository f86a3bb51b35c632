"""The reward as a table (``azimut_env.task.reward.REWARD_TERMS``): a term is one row and one
function, the weights are a mapping by term name (partial overrides, unknown names refused), the
deprecated per-term keywords still work, and the terms are their documented formulas."""

from __future__ import annotations

import math
import pickle
import textwrap

import numpy as np
import pytest
from numba import njit

from azimut_env.env import AzimutEnv
from azimut_env.task import reward
from azimut_env.task.config import TaskConfig
from azimut_env.task.reward import REWARD_TERMS, RewardInput, RewardTerm, RewardWeights, reward_table
from azimut_env.vector_env import AzimutVectorEnv

DEFAULTS = {t.name: t.weight for t in REWARD_TERMS}


# a term written as a developer would add one: this function and the row in test_a_term_is_one_row...
@njit
def _reward_crawl(x, k, w):
    return -w * max(0.0, x[RewardInput.SPEED_REF] - x[RewardInput.SPEED_ALONG])


def _steps(env, n=30, seed=4):
    env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        out.append(env.step(rng.uniform(-0.3, 0.3, size=8).astype(np.float32)))
    return out


def test_a_term_is_one_row_and_one_function(monkeypatch):
    row = RewardTerm("crawl", 0.5, "s/m", _reward_crawl, "−w·max(0, v_ref − v_along)")
    monkeypatch.setattr(reward, "REWARD_TERMS", REWARD_TERMS + (row,))
    env = AzimutEnv(track="circle", reward_weights={"crawl": 0.25})
    assert env.config.reward_weights["crawl"] == 0.25 and env.config.reward_weights["slip"] == DEFAULTS["slip"]
    moved = False
    for obs, r, _, _, info in _steps(env):
        terms = info["reward_terms"]
        assert list(terms) == [t.name for t in REWARD_TERMS] + ["crawl"]
        v_along = float(obs[env.observation_slices()["speed_along"]][0])  # float32 in the observation
        v_ref = float(obs[env.observation_slices()["speed_ref"]][0])
        assert terms["crawl"] == pytest.approx(-0.25 * max(0.0, v_ref - v_along), rel=1e-5, abs=1e-6)
        moved |= terms["crawl"] < 0
        total = 0.0
        for value in terms.values():  # the sum in the order of the table
            total += value
        assert r == total
    assert moved
    # the vector env carries it too, with the default weight of its row
    venv = AzimutVectorEnv(num_envs=2, track="circle")
    venv.reset(seed=0)
    _, _, _, _, info = venv.step(np.zeros((2, 8), dtype=np.float32))
    assert info["reward_terms"]["crawl"].shape == (2,) and venv.config.reward_weights["crawl"] == 0.5


def test_weights_by_name_merge_onto_the_defaults_and_scale_their_term():
    cfg = TaskConfig(reward_weights={"slip": 0.05})
    assert dict(cfg.reward_weights) == {**DEFAULTS, "slip": 0.05}
    assert TaskConfig().reward_weights == DEFAULTS and list(TaskConfig().reward_weights) == list(DEFAULTS)
    base = _steps(AzimutEnv(track="circle"))
    double = _steps(AzimutEnv(track="circle", reward_weights={"lateral": 1.0, "action_rate": 0.0}))
    for (_, _, _, _, a), (_, _, _, _, b) in zip(base, double):
        ta, tb = a["reward_terms"], b["reward_terms"]
        assert tb["lateral"] == 2.0 * ta["lateral"] and tb["action_rate"] == 0.0
        assert all(tb[k] == ta[k] for k in ta if k not in ("lateral", "action_rate"))


@pytest.mark.parametrize("weights, error, match", [
    ({"slipp": 0.1}, ValueError, r"unknown term\(s\) \['slipp'\]; the terms are \['progress'"),
    ({"slip": -0.1}, ValueError, r"reward_weights\['slip'\] must be finite and >= 0"),
    ({"slip": float("inf")}, ValueError, r"reward_weights\['slip'\] must be finite"),
    ({"slip": "0.1"}, TypeError, r"reward_weights\['slip'\] must be a real number"),
    ({"slip": True}, TypeError, r"reward_weights\['slip'\] must be a real number"),
    ([("slip", 0.1)], TypeError, "reward_weights must be a mapping"),
    ({"internal_force": 0.01}, ValueError, r"reward_weights: the term 'internal_force' is now 'antagonism'"),
])
def test_bad_weights_are_refused_with_one_line(weights, error, match):
    for make in (lambda: TaskConfig(reward_weights=weights), lambda: AzimutEnv(reward_weights=weights),
                 lambda: AzimutVectorEnv(num_envs=2, reward_weights=weights)):
        with pytest.raises(error, match=match) as info:
            make()
        assert "\n" not in str(info.value)


def test_the_internal_force_keyword_of_v1_is_refused_naming_the_new_term():
    for make in (lambda: AzimutEnv(internal_force_weight=0.01),
                 lambda: AzimutVectorEnv(num_envs=2, internal_force_weight=0.01)):
        with pytest.raises(ValueError, match=r"internal_force_weight: the term 'internal_force' is now 'antagonism'") \
                as info:
            make()
        assert "\n" not in str(info.value)


def test_deprecated_per_term_keywords_still_set_the_weights():
    with pytest.warns(DeprecationWarning) as caught:
        env = AzimutEnv(slip_weight=0.05, off_track_penalty=20.0)
    assert [str(w.message) for w in caught] == [
        "slip_weight=... is deprecated: pass reward_weights={'slip': ...}",
        "off_track_penalty=... is deprecated: pass reward_weights={'off_track': ...}"]
    assert all(w.filename == __file__ for w in caught)  # the warning points at the caller
    assert env.config == TaskConfig(reward_weights={"slip": 0.05, "off_track": 20.0})
    assert env.config.off_track_penalty == 20.0
    with pytest.warns(DeprecationWarning):
        venv = AzimutVectorEnv(num_envs=2, progress_weight=2.0, reward_weights={"heading": 0.1})
    assert venv.config.reward_weights["progress"] == 2.0 and venv.config.reward_weights["heading"] == 0.1
    with pytest.raises(TypeError, match="slip_weight and reward_weights\\['slip'\\] both set"):
        AzimutEnv(slip_weight=0.05, reward_weights={"slip": 0.1})
    with pytest.raises(TypeError, match="progress_wieght"):
        AzimutEnv(progress_wieght=2.0)


def test_the_weights_are_a_read_only_picklable_hashable_mapping():
    w = TaskConfig(reward_weights={"slip": 0.05}).reward_weights
    assert isinstance(w, RewardWeights) and w["slip"] == 0.05
    with pytest.raises(TypeError):
        w["slip"] = 1.0  # type: ignore[index]
    with pytest.raises(AttributeError):
        w._items = ()
    assert pickle.loads(pickle.dumps(w)) == w and hash(w) == hash(RewardWeights(dict(w)))
    assert hash(TaskConfig()) == hash(TaskConfig())
    with pytest.raises(KeyError):
        w["slipp"]


def test_terms_are_their_documented_formulas():
    env = AzimutEnv(track="paper")
    cfg = env.config
    w = cfg.reward_weights
    for _, r, _, _, info in _steps(env, n=40):
        t = info["reward_terms"]
        assert t["lateral"] == -w["lateral"] * (1.0 - math.exp(-abs(info["lateral_error"]) / cfg.lateral_scale))
        assert t["heading"] == -w["heading"] * (1.0 - math.exp(-abs(info["heading_error"]) / cfg.heading_scale))
        assert t["slip"] == -min(w["slip"] * info["slip_power"], cfg.antagonism_cap)
        assert t["antagonism"] == -min(w["antagonism"] * info["antagonism"], cfg.antagonism_cap)
        assert t["nullspace_force"] == -min(w["nullspace_force"] * info["nullspace_force"], cfg.antagonism_cap)
        assert t["off_track"] == 0.0 and t["overspeed"] <= 0.0 and t["action_rate"] <= 0.0
        assert r == sum(t.values())


def test_the_docstring_shows_the_table_and_bad_tables_are_refused():
    assert reward_table() in textwrap.dedent(AzimutEnv.__doc__)
    plain = RewardTerm("plain", 1.0, "-", lambda x, k, w: 0.0, "not compiled")
    with pytest.raises(TypeError, match="plain.*numba.njit"):
        reward.reward_kernel(REWARD_TERMS + (plain,))
    with pytest.raises(ValueError, match="distinct names"):
        reward.reward_kernel(REWARD_TERMS + (REWARD_TERMS[0],))
    with pytest.raises(ValueError, match="off_track"):
        reward.reward_kernel(REWARD_TERMS[:-1])
