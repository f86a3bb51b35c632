"""Closed loop in the simulator: short runs of both controllers, the report writer and the CLI."""

from __future__ import annotations

import json

import numpy as np
import pytest

from azimut_env.tracks import Track
from control.episode import episode_metrics
from control.rollout import run_episode
from jobs.cli import main
from jobs.eval.command import write_plots, write_report


@pytest.fixture(scope="module")
def corner_track():
    """2 m, a sharp 90° corner (stop and reconfigure), 2 m, at a fixed heading."""
    return Track.from_waypoints([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]], heading=0.0, speed=0.5, ramp=0.3, name="corner")


@pytest.fixture(scope="module")
def runs(corner_track):
    return {c: run_episode(c, corner_track, seed=1) for c in ("icr", "twist")}


def test_icr_completes_within_limits_and_reconfigures_at_the_corner(runs):
    m = episode_metrics(runs["icr"])
    assert m["completed"] and m["error"] is None
    assert m["limit_violation_steps"] == 0
    assert m["reconfigure_events"] >= 1
    assert m["rms_lateral_m"] < 0.01 and m["max_lateral_m"] < 0.03


def test_icr_scrubs_less_than_the_twist_baseline(runs):
    icr, twist = episode_metrics(runs["icr"]), episode_metrics(runs["twist"])
    assert twist["completed"]
    assert icr["slip_energy_J"] < 0.5 * twist["slip_energy_J"]
    assert icr["mean_antagonism_N"] < twist["mean_antagonism_N"]
    assert icr["mean_nullspace_force_N"] < twist["mean_nullspace_force_N"]


def test_qua_while_moving_leaves_out_stops_and_reconfigurations(runs):
    from control.episode import MOVING_MU, moving_mask
    from control.icr.controller import Mode

    log = runs["icr"]
    moving = moving_mask(log)
    assert not moving[log.mode != int(Mode.RUNNING)].any()
    assert not moving[log.mu_true <= MOVING_MU].any()
    m = episode_metrics(log)
    assert 0.0 < m["standstill_share"] < 1.0
    assert m["standstill_share"] == pytest.approx(1.0 - moving.mean())
    assert m["mean_qua_moving"] == pytest.approx(float(np.mean(log.qua[moving])))
    assert m["min_qua_moving"] >= m["min_qua"]


def test_report_and_plots(runs, tmp_path):
    from azimut_env.params import ActuatorLimits
    from estimation import RobotGeometry

    rows = [episode_metrics(log) for log in runs.values()]
    write_report(rows, tmp_path)
    data = json.loads((tmp_path / "metrics.json").read_text())
    assert [r["controller"] for r in data] == ["icr", "twist"]
    text = (tmp_path / "metrics.md").read_text()
    assert "| icr | corner |" in text and "mean qua moving" in text and "standstill share" in text
    files = write_plots(runs["icr"], tmp_path, RobotGeometry.azimut3(), ActuatorLimits())
    assert len(files) == 5 and all((tmp_path / f).stat().st_size > 1000 for f in files)


@pytest.mark.parametrize("argv", [["eval", "--tracks", "nope"], ["eval", "--controllers", "icr,foo"],
                                  ["eval", "--speed-scale", "-1"]])
def test_cli_rejects_bad_arguments(argv, capsys, tmp_path):
    assert main(argv + ["--out", str(tmp_path)]) == 2
    assert "error" in capsys.readouterr().err


def test_run_episode_rejects_unknown_names():
    with pytest.raises(ValueError):
        run_episode("pid", "paper")
    with pytest.raises(ValueError):
        run_episode("icr", "nope")


def test_cli_eval_writes_a_report(tmp_path):
    assert main(["eval", "--tracks", "circle", "--controllers", "icr", "--no-plots", "--out", str(tmp_path)]) == 0
    rows = json.loads((tmp_path / "metrics.json").read_text())["episodes"]
    assert rows[0]["completed"] and rows[0]["limit_violation_steps"] == 0
    assert np.isfinite(rows[0]["rms_lateral_m"])


def test_kick_trials_recover():
    from jobs.eval.robustness import kick_trial, summarize_kicks

    trials = [kick_trial(seed) for seed in (1003, 1005)]  # 3 and 4 wheels kicked by 45-70°
    summ = summarize_kicks(trials)
    assert summ["recovered"] == 2 and summ["limit_violation_steps"] == 0
    assert summ["peak_beta_error_rad"]["p100"] > 0.5


@pytest.mark.slow
def test_robustness_study_200_kicks(tmp_path):
    """The issue's bar: 200 kicked runs, all recover (no failure, no limit exceeded, < 5 cm in 3 s)."""
    from jobs.eval.robustness import kick_study, summarize_kicks

    summ = summarize_kicks(kick_study(200))
    (tmp_path / "kicks.json").write_text(json.dumps(summ, allow_nan=True))
    assert summ["failed_runs"] == 0
    assert summ["limit_violation_steps"] == 0
    assert summ["recovered"] == 200


def test_episode_runner_imports_none_of_its_users():
    """control.episode is below evaluate, robustness and phenomenon: no import circle."""
    import subprocess
    import sys

    code = ("import sys, control.episode; "
            "print(sorted(m for m in ('jobs.eval.command', 'jobs.eval.robustness', 'jobs.sim_paper', "
            "'jobs.eval.campaign') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
