"""The per-metre metrics of an episode (``control.episode.distance_metrics``) against closed forms
on synthetic traces: slip energy per metre, the distance-weighted antagonism, and the fighting at
standstill reported apart (the steps ``standstill_share`` counts)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from azimut_env.tracks import make_track
from control.episode import MIN_DISTANCE_M, EpisodeLog, episode_metrics, moving_mask
from control.icr.config import Mode

DT = 0.02


def _log(speed, slip_power, antagonism, mode=None, mu=None) -> EpisodeLog:
    """A synthetic log: chassis speed |v| [m/s] (along a direction that turns, so that both twist
    components count), slip power [W], antagonism [N] per step; ``mu`` (default: |v|) the |μ| that
    the moving steps are told by; ``mode`` (default RUNNING)."""
    speed = np.asarray(speed, dtype=float)
    T = speed.size
    heading = np.linspace(0.0, 2.0, T)
    twist = np.column_stack([speed * np.cos(heading), speed * np.sin(heading), np.zeros(T)])
    return EpisodeLog("synthetic", make_track("circle"), DT, t=DT * np.arange(1, T + 1), pose=np.zeros((T, 3)),
                      lateral=np.zeros(T), heading=np.zeros(T), qua=np.ones(T),
                      slip_power=np.broadcast_to(np.asarray(slip_power, dtype=float), (T,)).copy(),
                      antagonism=np.broadcast_to(np.asarray(antagonism, dtype=float), (T,)).copy(),
                      nullspace_force=np.zeros(T), mu_true=speed.copy() if mu is None else np.asarray(mu, float),
                      twist_true=twist, mode=np.full(T, int(Mode.RUNNING)) if mode is None else np.asarray(mode))


def test_constant_speed_and_slip_power_give_power_over_speed_joules_per_metre():
    """P = 3 W at |v| = 0.5 m/s for 4 s: 12 J over 2 m, 6 J/m = P/|v|; the antagonism weighted by
    distance is the constant; no standstill."""
    m = episode_metrics(_log(np.full(200, 0.5), 3.0, 7.0))
    assert m["distance_m"] == pytest.approx(2.0, rel=1e-12)
    assert m["slip_energy_J"] == pytest.approx(12.0, rel=1e-12)
    assert m["slip_energy_per_m"] == pytest.approx(3.0 / 0.5, rel=1e-12)
    assert m["antagonism_distance_weighted_N"] == pytest.approx(7.0, rel=1e-12)
    assert m["per_m_reason"] is None
    assert m["standstill_share"] == 0.0 and m["standstill_slip_energy_J"] == 0.0
    assert m["standstill_mean_antagonism_N"] is None


def test_a_standstill_only_episode_has_no_per_metre_value_and_its_fighting_is_at_standstill():
    """Never moved: per metre is None with the reason (never NaN or inf), and the standstill fields
    carry all the slip and antagonism."""
    m = episode_metrics(_log(np.zeros(100), 2.0, 9.0))
    assert m["distance_m"] == 0.0
    assert m["slip_energy_per_m"] is None and m["antagonism_distance_weighted_N"] is None
    assert "less than" in m["per_m_reason"] and str(MIN_DISTANCE_M) in m["per_m_reason"]
    assert m["standstill_share"] == 1.0
    assert m["standstill_slip_energy_J"] == pytest.approx(m["slip_energy_J"]) == pytest.approx(2.0 * 100 * DT)
    assert m["standstill_mean_antagonism_N"] == m["mean_antagonism_N"] == 9.0
    new = ("distance_m", "slip_energy_per_m", "antagonism_distance_weighted_N", "per_m_reason",
           "standstill_slip_energy_J", "standstill_mean_antagonism_N")
    json.dumps({k: m[k] for k in new}, allow_nan=False)  # no NaN, no Infinity in the new fields


def test_moving_and_standstill_split_as_standstill_share_does():
    """100 steps at 0.4 m/s (P = 1 W, A = 10 N), then 60 steps turning wheels in place (the
    controller RECONFIGURING, chassis at rest: P = 5 W, A = 40 N) and 40 steps STOPPING while still
    rolling at 0.2 m/s (P = 2 W, A = 20 N): the standstill is what moving_mask leaves out (the
    STOPPING steps too, though they roll); the distance counts every rolling step."""
    speed = np.r_[np.full(100, 0.4), np.zeros(60), np.full(40, 0.2)]
    power = np.r_[np.full(100, 1.0), np.full(60, 5.0), np.full(40, 2.0)]
    antag = np.r_[np.full(100, 10.0), np.full(60, 40.0), np.full(40, 20.0)]
    mode = np.r_[np.full(100, int(Mode.RUNNING)), np.full(60, int(Mode.RECONFIGURING)), np.full(40, int(Mode.STOPPING))]
    log = _log(speed, power, antag, mode=mode)
    m = episode_metrics(log)
    distance = (100 * 0.4 + 40 * 0.2) * DT
    assert m["distance_m"] == pytest.approx(distance, rel=1e-12)
    assert m["slip_energy_per_m"] == pytest.approx((100 * 1.0 + 60 * 5.0 + 40 * 2.0) * DT / distance, rel=1e-12)
    assert m["antagonism_distance_weighted_N"] == pytest.approx((100 * 0.4 * 10.0 + 40 * 0.2 * 20.0)
                                                                / (100 * 0.4 + 40 * 0.2), rel=1e-12)
    standstill = ~moving_mask(log)
    assert standstill.sum() == 100 and m["standstill_share"] == pytest.approx(0.5)
    assert m["standstill_slip_energy_J"] == pytest.approx((60 * 5.0 + 40 * 2.0) * DT, rel=1e-12)
    assert m["standstill_mean_antagonism_N"] == pytest.approx((60 * 40.0 + 40 * 20.0) / 100, rel=1e-12)


def test_distance_weighted_antagonism_is_the_integral_ratio_on_any_trace():
    rng = np.random.default_rng(0)
    speed, power, antag = rng.uniform(0, 1, 300), rng.uniform(0, 5, 300), rng.uniform(0, 50, 300)
    m = episode_metrics(_log(speed, power, antag))
    assert m["distance_m"] == pytest.approx(np.sum(speed) * DT, rel=1e-12)
    assert m["antagonism_distance_weighted_N"] == pytest.approx(np.sum(antag * speed) / np.sum(speed), rel=1e-12)
    assert m["slip_energy_per_m"] == pytest.approx(np.sum(power) / np.sum(speed), rel=1e-12)


def test_a_creep_below_the_least_distance_or_a_log_without_twist_has_no_per_metre_value():
    creep = episode_metrics(_log(np.full(10, 0.9 * MIN_DISTANCE_M / (10 * DT)), 1.0, 1.0))
    assert creep["slip_energy_per_m"] is None and "less than" in creep["per_m_reason"]
    log = _log(np.full(10, 0.5), 1.0, 1.0)
    log.twist_true = np.zeros((0, 3))
    m = episode_metrics(log)
    assert m["distance_m"] is None and m["slip_energy_per_m"] is None and "twist" in m["per_m_reason"]
    assert m["standstill_slip_energy_J"] == 0.0  # the moving steps are told by μ, not by the twist
    bad = _log(np.full(10, 0.5), [1.0] * 9 + [np.nan], 1.0)
    m = episode_metrics(bad)
    assert m["slip_energy_per_m"] is None and "not finite" in m["per_m_reason"]
