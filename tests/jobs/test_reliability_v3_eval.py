"""Issue 31 (reliability v3): ``azimut eval`` with a user's own controller, modules and path.

A package of the user's (``v3ctl``, written to a temporary folder on ``sys.path``): a controller
whose ``env_kwargs`` pick the ideal robot and whose speed comes from a helper module it imports,
and one whose ``act`` raises. Each test failed before the fix it names."""

from __future__ import annotations

import importlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from jobs.campaign.engine import Task, run_tasks
from jobs.cli import main

ROOT = Path(__file__).resolve().parents[2]

CONTROLLER = '''
import numpy as np

from control import WheelCommand
from estimation import steering_from_lambda, wheel_speeds

from . import helper


class Ideal:
    """Straight ahead (+X) at helper.SPEED [m/s], on the ideal robot (its env_kwargs)."""
    name = "ideal"
    env_kwargs = {"imperfections": "ideal"}

    def __init__(self, speed_scale=1.0):
        self.speed_scale = speed_scale

    def reset(self, env, rows):
        pass

    def act(self, env, obs):
        num = env.measured_beta.shape[0]
        lam = np.tile([0.0, 1.0, 0.0], (num, 1))
        beta = steering_from_lambda(lam, env.geometry)
        return WheelCommand(beta=beta, phidot=wheel_speeds(lam, np.full(num, helper.SPEED), env.geometry))


class Buggy(Ideal):
    name = "buggy"

    def act(self, env, obs):
        raise RuntimeError("my bug in act")


class Swerve(Ideal):
    """Another robot and a randomised one, by its env_kwargs."""
    name = "swerve"
    env_kwargs = {"robot": "swerve", "domain_randomization": 0.5}


class Exits(Ideal):
    name = "exits"

    def act(self, env, obs):
        raise SystemExit(3)


class ListKw(Ideal):
    name = "listkw"
    env_kwargs = ["robot", "swerve"]


class TrackKw(Ideal):
    name = "trackkw"
    env_kwargs = {"track": "paper"}
'''


_EDITS = [0]


def _write_helper(folder: Path, speed: str) -> None:
    path = folder / "v3ctl" / "helper.py"
    path.write_text(f"SPEED = {speed}\n")
    _EDITS[0] += 1
    stamp = time.time() + 10 * _EDITS[0]
    os.utime(path, (stamp, stamp))  # a new mtime each edit: Python's bytecode cache must not hide it


def _forget_user_modules() -> None:
    """A new ``azimut eval`` process imports the user's modules afresh; in this one, forget them."""
    for name in [m for m in sys.modules if m == "v3ctl" or m.startswith("v3ctl.")]:
        del sys.modules[name]
    importlib.invalidate_caches()


@pytest.fixture(scope="module")
def user(tmp_path_factory):
    """The user's folder: the package ``v3ctl`` (on sys.path) and ``line.csv``, a 1.5 m line."""
    folder = tmp_path_factory.mktemp("user")
    (folder / "v3ctl").mkdir()
    (folder / "v3ctl" / "__init__.py").write_text("")
    (folder / "v3ctl" / "ctl.py").write_text(CONTROLLER)
    _write_helper(folder, "0.30")
    (folder / "line.csv").write_text("# a path of mine\nx,y\n0,0\n1.5,0\n")
    sys.path.insert(0, str(folder))
    yield folder
    sys.path.remove(str(folder))
    _forget_user_modules()


@pytest.fixture(scope="module")
def mine(user, tmp_path_factory):
    """``azimut eval --controllers twist,v3ctl.ctl:Ideal --tracks <line.csv> --no-plots``."""
    out = tmp_path_factory.mktemp("eval") / "out"
    track = str(user / "line.csv")
    assert main(["eval", "--controllers", "twist,v3ctl.ctl:Ideal", "--tracks", track, "--max-time", "3",
                 "--no-plots", "--out", str(out)]) == 0
    return out, track


# ----------------------------------------------------------------- 1. the robot each controller ran


def test_the_report_names_the_robot_each_controller_ran(mine):
    """The controller's env_kwargs made its robot the ideal one: metrics.json and report.md said
    'azimut3 (imperfections: paper)' for all."""
    out, _ = mine
    m = json.loads((out / "metrics.json").read_text())
    assert m["campaign"]["robots"] == {"twist": {"robot": "azimut3", "imperfections": "paper"},
                                       "ideal": {"robot": "azimut3", "imperfections": "ideal"}}
    assert {(r["controller"], r["imperfections"]) for r in m["episodes"]} == {("twist", "paper"), ("ideal", "ideal")}
    assert {(c["controller"], c["imperfections"]) for c in m["summary"]} == {("twist", "paper"), ("ideal", "ideal")}
    report = (out / "report.md").read_text()
    assert "azimut3 (imperfections: paper) for twist; azimut3 (imperfections: ideal) for ideal" in report


# ----------------------------------------------------------------- 4. a path, a verdict, traces


def test_a_waypoint_file_is_a_track(mine):
    out, track = mine
    m = json.loads((out / "metrics.json").read_text())
    assert m["campaign"]["tracks"] == [track] and {r["track"] for r in m["episodes"]} == {track}
    assert all(r["status"] == "ok" and r["max_lateral_m"] < 0.05 for r in m["episodes"])


def test_the_report_opens_with_a_verdict_computed_from_the_metrics(mine):
    out, track = mine
    report = (out / "report.md").read_text()
    assert report.index("## Verdict") < report.index("## Summary")
    line = next(s for s in report.splitlines() if s.startswith(f"- **{track}**"))
    cells = {c["controller"]: c["metrics"] for c in json.loads((out / "metrics.json").read_text())["summary"]
             if c["metrics"]["completed"]["mean"] == 1.0}  # ranked among those that finished every episode
    if cells:
        least = {key: min(cells, key=lambda c: cells[c][key]["mean"]) for key in ("slip_energy_per_m",
                                                                                    "rms_lateral_m")}
        assert f"least slip per metre **{least['slip_energy_per_m']}**" in line
        assert f"least lateral error **{least['rms_lateral_m']}**" in line
    else:
        assert "least slip per metre: none (no controller finished every episode)" in line
    assert "fastest finisher" in line


def test_every_episode_has_its_trace_with_the_commands_under_no_plots(mine):
    """episodes/<id>.npz was written only for the plotted seed and never under --no-plots, and
    had neither the commands nor the measured steering."""
    out, _ = mine
    m = json.loads((out / "metrics.json").read_text())
    traces = sorted((out / "episodes").glob("*.npz"))
    assert len(traces) == len(m["episodes"]) == 2
    for path in traces:
        z = np.load(path)
        steps = z["t"].size
        assert steps > 0 and all(z[k].shape == (steps, 4) for k in ("beta_cmd", "phidot_cmd", "beta_meas"))
        if path.name.startswith("ideal-"):  # straight ahead: the command of a +X translation, every step
            assert np.allclose(z["beta_cmd"], z["beta_cmd"][0]) and np.allclose(z["phidot_cmd"], z["phidot_cmd"][0])
            assert np.all(np.abs(z["phidot_cmd"]) > 0)


# ----------------------------------------------------------------- 2. the user's code in the key


def test_resume_recomputes_after_an_edit_of_an_imported_module(mine, user, capsys):
    """An edit of the helper module the controller imports: --resume reused the stale episode (its
    key held the controller's own module only)."""
    from jobs.eval.campaign import episode_tasks

    out, track = mine
    before = {t.key["controller"]: t.id for t in episode_tasks(["twist", "v3ctl.ctl:Ideal"], [track], [0])}
    m0 = json.loads((out / "metrics.json").read_text())
    rms0 = next(r for r in m0["episodes"] if r["controller"] == "ideal")["rms_lateral_m"]
    _write_helper(user, "0.15")
    try:
        _forget_user_modules()
        after = {t.key["controller"]: t.id for t in episode_tasks(["twist", "v3ctl.ctl:Ideal"], [track], [0])}
        assert after["twist"] == before["twist"] and after["v3ctl.ctl:Ideal"] != before["v3ctl.ctl:Ideal"]
        assert main(["eval", "--controllers", "twist,v3ctl.ctl:Ideal", "--tracks", track, "--max-time", "3",
                     "--no-plots", "--out", str(out), "--resume"]) == 0
        m = json.loads((out / "metrics.json").read_text())
        assert m["campaign"]["computed"] >= 1  # the user's episode (twist's too if azimut's sources changed)
        assert f"ideal {track}" in capsys.readouterr().out
        rms = next(r for r in m["episodes"] if r["controller"] == "ideal")["rms_lateral_m"]
        assert rms != rms0  # the new speed drove it
    finally:
        _write_helper(user, "0.30")
        _forget_user_modules()


def test_the_key_holds_the_azimut_sources_and_the_user_modules(user):
    from jobs.eval.fingerprint import azimut_digest, controller_inputs

    inputs = controller_inputs("v3ctl.ctl:Ideal")
    assert inputs["azimut"] == azimut_digest() and controller_inputs("icr") == {"azimut": azimut_digest()}
    assert set(inputs["code"]) == {"v3ctl", "v3ctl.ctl", "v3ctl.helper"}  # not numpy, control, estimation


# ----------------------------------------------------------------- 3. the controller's own errors


def test_a_controller_error_is_not_retried_and_the_console_says_where_its_traceback_is(user, tmp_path, capsys):
    """'FAILED after 2 attempt(s): RuntimeError: my bug in act' with no word of the traceback, which
    was only in the record; two seeds (a batch that fails: each episode run alone once)."""
    out = tmp_path / "out"
    assert main(["eval", "--controllers", "v3ctl.ctl:Buggy", "--tracks", "crab", "--seeds", "0,1", "--max-time", "1",
                 "--no-plots", "--out", str(out)]) == 1
    lines = [s for s in capsys.readouterr().out.splitlines() if "FAILED" in s]
    assert len(lines) == 2
    for line in lines:
        assert "FAILED after 1 attempt(s): RuntimeError: my bug in act (at ctl.py:" in line and "not retried" in line
        record = Path(line.rsplit("traceback in ", 1)[1])
        assert record.parent == out / "episodes" and "my bug in act" in json.loads(record.read_text())["traceback"]
    assert "traceback in `" in (out / "report.md").read_text()


_RUNS: list[str] = []


def memory_once(seed: int, marker: str) -> dict:
    """Raises MemoryError on its first run (transient), then succeeds."""
    _RUNS.append("memory")
    if not Path(marker).exists():
        Path(marker).write_text("x")
        raise MemoryError("out of memory")
    return {"seed": seed}


def value_error(seed: int) -> dict:
    _RUNS.append("value")
    raise ValueError("a bug")


def test_transient_failures_are_retried_and_the_others_are_not(tmp_path):
    _RUNS.clear()
    tasks = [Task("test_reliability_v3_eval:memory_once", {"seed": 0, "marker": str(tmp_path / "m")}),
             Task("test_reliability_v3_eval:value_error", {"seed": 1})]
    recs = run_tasks(tasks, tmp_path / "store", retries=2, retry="transient")
    assert [r["status"] for r in recs] == ["ok", "failed"] and [r["attempts"] for r in recs] == [2, 1]
    assert recs[1]["transient"] is False and _RUNS.count("value") == 1
    _RUNS.clear()
    recs = run_tasks(tasks[1:], tmp_path / "store2", retries=1)  # the default: any failure retried
    assert recs[0]["attempts"] == 2 and _RUNS.count("value") == 2


# ----------------------------------------------------------------- 5. SIGTERM


def test_sigterm_stops_eval_as_ctrl_c_does_and_resume_finishes(user, tmp_path):
    """SIGTERM killed azimut eval with a traceback-less death (status -15), nothing said."""
    out = tmp_path / "out"
    argv = ["eval", "--controllers", "v3ctl.ctl:Ideal,twist", "--tracks", "crab", "--max-time", "3", "--no-plots",
            "--out", str(out)]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(user), str(ROOT), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, "-m", "jobs.cli", *argv], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env, cwd=tmp_path)
    first = proc.stdout.readline()  # the first finished episode
    assert first.startswith("[1/2]"), first + proc.stderr.read()
    proc.send_signal(signal.SIGTERM)
    rest, err = proc.communicate(timeout=120)
    assert proc.returncode == 143, (rest, err)
    err = [s for s in err.splitlines() if s.strip() and "compiling" not in s]
    assert len(err) == 1 and "terminated (SIGTERM): 1 of 2 episodes saved" in err[0] and "--resume" in err[0]
    assert len(list((out / "episodes").glob("*.json"))) == 1  # the record of what was done
    assert not (out / "report.md").exists()
    assert main(argv + ["--resume"]) == 0
    m = json.loads((out / "metrics.json").read_text())
    assert m["campaign"]["computed"] + m["campaign"]["resumed"] == 2 and m["campaign"]["computed"] >= 1


# ----------------------------------------------------------------- review of azimut eval (issue 31, round 2)


def test_each_controllers_robot_limits_and_env_kwargs_are_reported(user, tmp_path):
    """A controller's env_kwargs robot='swerve': the limits line showed azimut3's limits for all, and
    its domain_randomization=0.5 was said nowhere."""
    out = tmp_path / "out"
    assert main(["eval", "--controllers", "twist,v3ctl.ctl:Swerve", "--tracks", str(user / "line.csv"),
                 "--max-time", "1", "--no-plots", "--out", str(out)]) in (0, 1)
    m = json.loads((out / "metrics.json").read_text())
    limits = m["campaign"]["limits"]
    assert isinstance(limits, dict) and set(limits) == {"twist", "swerve"} and limits["twist"] != limits["swerve"]
    assert m["campaign"]["env_kwargs"] == {"twist": {}, "swerve": {"domain_randomization": 0.5}}
    assert m["campaign"]["robots"]["swerve"]["robot"] == "swerve"
    report = (out / "report.md").read_text()
    assert "swerve ran with env_kwargs domain_randomization=0.5" in report
    assert f"limits for twist: {limits['twist']}" in report and f"limits for swerve: {limits['swerve']}" in report


def test_params_of_no_preset_is_its_own_robot():
    import dataclasses

    from azimut_env.params import RobotParams
    from jobs.eval.robots import robot_text

    p = RobotParams.preset("swerve")
    assert robot_text({"params": p})[0] == "swerve"
    assert robot_text({"params": dataclasses.replace(p, gravity=2 * p.gravity)})[0] == "its own robot"


@pytest.mark.parametrize("cls, message", [
    ("ListKw", "controller 'v3ctl.ctl:ListKw': env_kwargs must be a dict, got list"),
    ("TrackKw", "controller 'v3ctl.ctl:TrackKw': env_kwargs may not set 'track'")])
def test_bad_env_kwargs_are_refused_in_one_line(user, tmp_path, capsys, cls, message):
    """env_kwargs = [...] was a traceback at start-up (robots.py: dict(list))."""
    assert main(["eval", "--controllers", f"v3ctl.ctl:{cls}", "--tracks", "crab", "--no-plots",
                 "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


@pytest.mark.parametrize("workers", [1, 2])
def test_a_controller_that_calls_sys_exit_fails_its_episode(user, tmp_path, capsys, workers):
    """SystemExit(3) from act: eval exited with 3 and no report (serial), or left nothing (--workers 2)."""
    out = tmp_path / "out"
    assert main(["eval", "--controllers", "v3ctl.ctl:Exits", "--tracks", "crab", "--max-time", "0.5",
                 "--no-plots", "--workers", str(workers), "--out", str(out)]) == 1
    lines = [s for s in capsys.readouterr().out.splitlines() if "FAILED" in s]
    assert len(lines) == 1 and "FAILED after 1 attempt(s): SystemExit: 3" in lines[0] and "not retried" in lines[0]
    assert (out / "report.md").is_file()


def test_the_verdict_ranks_only_the_controllers_that_finished():
    """A controller that never moves had the least slip and lateral error."""
    from jobs.eval.verdict import verdict_lines

    def cell(name, done, slip, lat, time_s):
        stats = {"completed": done, "slip_energy_per_m": slip, "rms_lateral_m": lat, "completion_time_s": time_s}
        return {"controller": name, "track": "line", "n": 1, "ok": 1, "failed": 0,
                "metrics": {k: {"mean": v, "lo": v, "hi": v, "n": 1} for k, v in stats.items()}}

    line = verdict_lines([cell("still", 0.0, 0.0, 0.0, float("nan")), cell("mover", 1.0, 2.0, 0.01, 5.0)],
                         ["line"], ["still", "mover"])[0]
    assert "least slip per metre **mover** (2.00 J/m" in line and "least lateral error **mover**" in line
    none = verdict_lines([cell("still", 0.0, 0.0, 0.0, float("nan"))] * 1, ["line"], ["still"])[0]
    assert "least slip per metre: none" in none


def test_a_closed_stdout_stops_the_progress_quietly():
    """azimut eval ... | head -1: a BrokenPipeError traceback."""
    from jobs.eval.console import say

    r, w = os.pipe()
    os.close(r)
    stream = os.fdopen(w, "w")
    try:
        assert say("one", stream) is False and say("two", stream) is False
    finally:
        stream.close()


@pytest.mark.parametrize("speeds, message", [("0,0", "line 2: the speed is 0 at every waypoint"),
                                              ("0.5,25", "line 3: speed 25 m/s is above 20 m/s")])
def test_a_track_file_speed_that_never_finishes_or_is_too_fast_is_refused(tmp_path, speeds, message):
    from jobs.eval.track_files import read_track_file

    a, b = speeds.split(",")
    path = tmp_path / "p.csv"
    path.write_text(f"x,y,speed\n0,0,{a}\n1,0,{b}\n")
    with pytest.raises(ValueError, match=message.replace(".", r"\.")) as exc:
        read_track_file(path)
    assert str(path) in str(exc.value)
