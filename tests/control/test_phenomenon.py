"""The paper's phenomenon, attributed (``azimut sim-paper``): qua while moving under the ICR
controller is a compliance effect (the motor angles stay on the surface, a stiff spring removes
it); under the limit-blind feed-forward it is motor lag (the stiff spring changes nothing)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from azimut_env.params import RobotParams
from control.rollout import run_episode
from estimation import steering_from_lambda
from jobs.cli import main
from jobs.sim_paper import attribute, qua_of_angles, run_phenomenon, stable_substeps, stiff_params


@pytest.fixture(scope="module")
def icr_crab():
    return {r["steering"]: r for r in run_phenomenon("icr", "crab", speeds=(1.0,))["rows"]}


def test_icr_phenomenon_is_compliance(icr_crab):
    comp, stiff = icr_crab["compliant"], icr_crab["stiff x100"]
    for row in (comp, stiff):
        assert row["completed"] and row["error"] is None
        assert 0.0 < row["standstill_share"] < 1.0  # crab stops to reconfigure
        assert row["qua_motor_mean"] > 0.9995  # the motors alone stay on the surface
    assert comp["qua_true_mean"] < stiff["qua_true_mean"]
    assert comp["qua_true_min"] < stiff["qua_true_min"]
    assert stiff["deflection_rms_deg"] < 0.1 * comp["deflection_rms_deg"]
    assert 0.05 < comp["deflection_rms_deg"] < 5.0


def test_feedforward_phenomenon_is_motor_lag():
    geom = RobotParams().geometry
    rows = {}
    for name, params, sub in (("compliant", None, 8), ("stiff", stiff_params(), stable_substeps(stiff_params()))):
        kw = {"substeps": sub} | ({"params": params} if params is not None else {})
        log = run_episode("feedforward", "paper", seed=0, env_kwargs=kw)
        rows[name] = attribute(log, geom)
    comp, stiff = rows["compliant"], rows["stiff"]
    assert comp["completed"] and comp["rms_lateral_m"] < 0.05
    assert 0.95 < comp["qua_meas_mean"] < 0.9999 and comp["qua_meas_min"] < 0.8  # off the surface in transitions
    assert abs(comp["qua_motor_mean"] - comp["qua_true_mean"]) < 2e-3  # ... because the motors are
    assert abs(stiff["qua_true_mean"] - comp["qua_true_mean"]) < 2e-3  # and a stiff spring does not help
    assert comp["motor_lag_max_deg"] > 20.0


def test_qua_of_angles_is_one_on_the_surface():
    geom = RobotParams().geometry
    lam = np.random.default_rng(0).normal(size=(50, 3))
    q = steering_from_lambda(lam / np.linalg.norm(lam, axis=1, keepdims=True), geom)
    np.testing.assert_allclose(qua_of_angles(q, geom), 1.0, atol=1e-9)
    assert np.all(qua_of_angles(q + np.deg2rad([5.0, -5.0, 5.0, -5.0]), geom) < 1.0)


def test_stiff_params_keep_the_damping_ratio():
    p = RobotParams()
    s = stiff_params(p, 100.0)
    assert s.steering.stiffness == pytest.approx(100 * p.steering.stiffness)
    ratio = lambda q: q.steering.damping / np.sqrt(q.steering.stiffness * q.steering.module_inertia)  # noqa: E731
    assert ratio(s) == pytest.approx(ratio(p))
    with pytest.raises(ValueError):
        stiff_params(p, 0.5)
    assert stable_substeps(p) == 8 and stable_substeps(s) > 8


@pytest.mark.parametrize("argv", [["--driver", "pid"], ["--speeds", "0"], ["--speeds", "nan"], ["--track", "nope"],
                                  ["--stiffness-factor", "0.5"], ["--json", "/nonexistent/dir/x.json"]])
def test_cli_rejects_bad_arguments(argv, capsys):
    try:
        code = main(["sim-paper", *argv])
    except SystemExit as exc:
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err and "Traceback" not in "".join(err)


def test_cli_feedforward_json(tmp_path, capsys):
    out = tmp_path / "ph.json"
    assert main(["sim-paper", "--driver", "feedforward", "--track", "circle", "--speeds", "1", "--json", str(out)]) == 0
    data = json.loads(out.read_text())
    assert [r["steering"] for r in data["rows"]] == ["compliant", "stiff x100"]
    assert "qua θ_m mean" in capsys.readouterr().out
