"""The paper's phenomenon, attributed (``azimut sim-paper``, :mod:`jobs.phenomenon`): the departure
of the steering configuration from the constraining surface while moving, with one counterfactual
per cause (compliance, friction, quantisation, geometric imperfections, motor lag); under the
limit-blind feed-forward it is motor lag."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from azimut_env.imperfections import with_imperfections
from azimut_env.params import RobotParams
from control.rollout import run_episode
from estimation import steering_from_lambda
from jobs.cli import main
from jobs.phenomenon import (
    COUNTERFACTUALS,
    attribute,
    counterfactual,
    d2_separation,
    default_robot,
    departures_deg,
    it_over_ns,
    qua_of_angles,
    run_phenomenon,
    stable_substeps,
    stiff_params,
    sweep,
)

GEOM = RobotParams().geometry


@pytest.fixture(scope="module")
def icr_crab():
    return {r["case"]: r for r in run_phenomenon("icr", "crab", speeds=(1.0,))["rows"]}


def test_every_cause_has_a_counterfactual_and_the_robot_departs_most(icr_crab):
    robot = icr_crab["robot"]
    assert set(icr_crab) == {"robot", "stiff x100", *[v for k, v in COUNTERFACTUALS.items() if k != "compliance"]}
    for row in icr_crab.values():
        assert row["completed"] and row["error"] is None
        assert 0.0 < row["standstill_share"] < 1.0  # crab stops to reconfigure
        assert row["departure_motor_mean_deg"] < 0.1  # the motors alone stay on the surface
    stiff = icr_crab["stiff x100"]
    assert stiff["departure_meas_mean_deg"] < 0.3 * robot["departure_meas_mean_deg"]  # compliance dominates
    assert stiff["deflection_rms_deg"] < 0.1 * robot["deflection_rms_deg"]
    assert robot["departure_drop_deg"] == 0.0 and stiff["departure_drop_deg"] > 0.0
    assert icr_crab["no friction"]["departure_meas_mean_deg"] < robot["departure_meas_mean_deg"]
    assert 0.1 < robot["departure_meas_mean_deg"] < 5.0
    assert len(robot["departure_meas_p95_deg"]) == 4


def test_counterfactuals_remove_one_cause_each():
    p = default_robot()
    assert p == with_imperfections(RobotParams(), "paper")
    assert counterfactual(p, "friction").steering.friction_static == 0.0
    q = counterfactual(p, "quantisation").sensors
    assert q.steer_resolution == 0.0 and q.wheel_cpr == 0 and q.steer_noise == p.sensors.steer_noise
    assert counterfactual(p, "imperfections").imperfections.steer_offset == ()
    assert counterfactual(p, "motor lag").steering.position_gain == 10 * p.steering.position_gain
    assert counterfactual(p, "compliance") == stiff_params(p)
    with pytest.raises(ValueError, match="unknown cause"):
        counterfactual(p, "gravity")


def test_feedforward_phenomenon_is_motor_lag():
    """The limit-blind feed-forward commands steering jumps: its departures come with motor lag
    (tens of degrees), and the motor angles depart as much as the wheels."""
    log = run_episode("feedforward", "paper", seed=0)
    row = attribute(log, GEOM)
    assert row["completed"] and row["rms_lateral_m"] < 0.05
    assert row["motor_lag_max_deg"] > 20.0
    assert row["qua_meas_min"] < 0.8  # off the surface in transitions
    assert row["departure_motor_mean_deg"] > 0.5 * row["departure_true_mean_deg"]


def test_departures_and_qua_are_zero_and_one_on_the_surface():
    lam = np.random.default_rng(0).normal(size=(50, 3))
    q = steering_from_lambda(lam / np.linalg.norm(lam, axis=1, keepdims=True), GEOM)
    np.testing.assert_allclose(qua_of_angles(q, GEOM), 1.0, atol=1e-9)
    np.testing.assert_allclose(departures_deg(q, GEOM), 0.0, atol=1e-6)
    off = q + np.deg2rad([5.0, -5.0, 5.0, -5.0])
    assert np.all(qua_of_angles(off, GEOM) < 1.0)
    assert np.all(departures_deg(off, GEOM).max(axis=1) > 1.0)
    assert it_over_ns(q, GEOM) == 0.0 and math.isnan(it_over_ns(q[:0], GEOM))
    on = d2_separation(q, GEOM)
    assert on["d2_it_over_ns"] == 0.0 and on["d2_it_ge_ns"] == 1.0 and on["d2_points"] == 50
    assert on["d2_departure_mean_deg"] < 1e-6 and abs(on["d2_ns_ls_worst"]) < 1e-6
    sep = d2_separation(off, GEOM)
    assert sep["d2_it_ge_ns"] == 1.0 and sep["d2_departure_mean_deg"] > 1.0  # IT ≥ NS off the surface too


def test_stiff_params_keep_the_damping_ratio():
    p = default_robot()
    s = stiff_params(p, 100.0)
    assert s.steering.stiffness == pytest.approx(100 * p.steering.stiffness)
    ratio = lambda q: q.steering.damping / np.sqrt(q.steering.stiffness * q.steering.module_inertia)  # noqa: E731
    assert ratio(s) == pytest.approx(ratio(p))
    with pytest.raises(ValueError):
        stiff_params(p, 0.5)
    assert stable_substeps(p) == 8 and stable_substeps(s) > 8


def test_sweep_rejects_unknown_parameters():
    with pytest.raises(ValueError, match="unknown sweep"):
        sweep("mass", [1.0])


@pytest.mark.parametrize("argv", [["--driver", "pid"], ["--speeds", "0"], ["--speeds", "nan"], ["--track", "nope"],
                                  ["--stiffness-factor", "0.5"], ["--json", "/nonexistent/dir/x.json"],
                                  ["--causes", "gravity"], ["--sweep", "stiffness"], ["--values", "1"],
                                  ["--sweep", "stiffness", "--values", "0"], ["--causes", "none", "friction"],
                                  ["--imperfections", "real"], ["--d2"]])
def test_cli_rejects_bad_arguments(argv, capsys):
    try:
        code = main(["sim-paper", *argv])
    except SystemExit as exc:
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err and "Traceback" not in "".join(err)


def test_cli_json(tmp_path, capsys):
    out = tmp_path / "ph.json"
    assert main(["sim-paper", "--track", "circle", "--speeds", "1", "--causes", "friction", "--json", str(out)]) == 0
    data = json.loads(out.read_text())
    assert [r["case"] for r in data["rows"]] == ["robot", "no friction"]
    assert "dep. β_meas mean" in capsys.readouterr().out


@pytest.mark.slow
def test_sweep_d2_at_the_default_values_is_the_shipped_d2():
    """``sweep(..., d2=True)`` records D2 with each value: at the default robot's own friction it is
    ``azimut record-d2``'s file, so its figures are those of the shipped D2."""
    from estimation.datasets import dataset_d2

    rows = sweep("friction", [default_robot().steering.friction_coulomb], speeds=(1.0,), d2=True)
    q, source = dataset_d2(RobotParams().geometry)
    assert source == "recorded"
    expected = d2_separation(q, RobotParams().geometry)
    assert {k: rows[0][k] for k in expected} == expected
