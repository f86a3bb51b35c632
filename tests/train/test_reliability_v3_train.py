"""Issue 31 (reliability v3), training and tuning: nothing overwritten, nothing stale, no traceback.

``azimut tune`` keeps one study per ``--out`` and refuses another one there or a resume with other
defining arguments; the processes of a parallel study sample different hyperparameters; a trial
left RUNNING by a killed process is failed on the next start; ``azimut train --resume`` refuses a
budget below the steps done; SIGINT/SIGTERM end ``azimut train`` and ``azimut tune`` with one line,
exit 130/143 and the run saved; an SQLite storage that is a folder is refused in one line."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip("stable_baselines3")
optuna = pytest.importorskip("optuna")

from jobs.cli import main  # noqa: E402

#: a tune as small as it gets: 2 robots, one evaluation on crab, raw actions
TINY_TUNE = ["--steps", "256", "--num-robots", "2", "--evals", "1", "--eval-tracks", "crab", "--action", "raw"]
#: a training run that a signal stops long before its budget
LONG_TRAIN = ["--steps", "1000000", "--num-robots", "2", "--eval-every", "0", "--checkpoint-every", "64",
              "--eval-tracks", "crab", "--quiet"]


def _with(argv: list[str], flag: str, value: str) -> list[str]:
    """``argv`` with ``flag``'s value replaced, or the flag added."""
    if flag in argv:
        i = argv.index(flag)
        return argv[:i + 1] + [value] + argv[i + 2:]
    return argv + [flag, value]


def _errors(err: str) -> list[str]:
    """stderr's lines, less the numba compilation notice of a first run."""
    return [line for line in err.strip().splitlines() if line and "compiling the numba kernels" not in line]


def _start(argv: list[str]) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "jobs.cli", *argv], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd=Path(__file__).resolve().parents[2])


def _wait_for(proc: subprocess.Popen, ready, timeout: float = 240.0) -> None:
    start = time.monotonic()
    while not ready():
        if proc.poll() is not None:
            raise AssertionError(f"exited early ({proc.returncode}): {proc.communicate()[1][-2000:]}")
        if time.monotonic() - start > timeout:
            proc.kill()
            raise AssertionError("never started")
        time.sleep(0.05)


@pytest.fixture(scope="module")
def study_out(tmp_path_factory) -> Path:
    """A finished one-trial study (``--action raw``) in its --out."""
    out = tmp_path_factory.mktemp("tune") / "study"
    assert main(["tune", "--trials", "1", "--out", str(out), *TINY_TUNE]) == 0
    return out


# ----------------------------------------------------------------------------- 1, 2: one study per --out


@pytest.mark.parametrize("flags,match", [
    (["--action", "icr-rate"], "its --action raw, not --action icr-rate"),
    (["--algo", "sac"], "its --algo ppo, not --algo sac"),
    (["--study-name", "other"], "not 'other' (--study-name)"),
])
def test_tune_into_an_out_holding_another_study_is_refused(study_out, flags, match, capsys):
    before = {p: p.stat().st_mtime_ns for p in study_out.rglob("*") if p.is_file()}
    rc = main(_with(["tune", "--trials", "1", "--out", str(study_out), *TINY_TUNE], *flags))
    err = _errors(capsys.readouterr().err)
    assert rc == 2 and len(err) == 1 and match in err[0] and "another --out" in err[0], err
    assert {p: p.stat().st_mtime_ns for p in study_out.rglob("*") if p.is_file()} == before


@pytest.mark.parametrize("flags,match", [
    (["--steps", "128"], "was run with --steps 256, not --steps 128"),
    (["--track", "circle"], "--track random, not --track circle"),
    (["--robot", "swerve"], "--robot azimut3 (its own imperfections), not --robot swerve"),
    (["--eval-tracks", "circle"], "--eval-tracks crab, not --eval-tracks circle"),
])
def test_tune_resume_with_other_defining_arguments_is_refused(study_out, flags, match, capsys):
    argv = _with(["tune", "--trials", "1", "--out", str(study_out), *TINY_TUNE], *flags)
    rc = main(argv)
    err = _errors(capsys.readouterr().err)
    assert rc == 2 and len(err) == 1 and match in err[0], err
    # the storage keeps the record too: another --out on the same study is refused as well
    record = optuna.load_study(study_name="tune-ppo-raw", storage=f"sqlite:///{study_out / 'study.db'}").user_attrs
    assert record["azimut_study_args"]["--steps"] == 256
    rc = main(_with(_with(argv, "--out", str(study_out.parent / "elsewhere")),
                    "--storage", f"sqlite:///{study_out / 'study.db'}"))
    err = _errors(capsys.readouterr().err)
    assert rc == 2 and len(err) == 1 and match in err[0], err
    assert not (study_out.parent / "elsewhere").exists()


def test_study_file_and_trials_json_record_the_study(study_out):
    rec = json.loads((study_out / "study.json").read_text())
    assert rec["study"] == "tune-ppo-raw" and rec["args"]["--steps"] == 256 and rec["args"]["--action"] == "raw"
    trials = json.loads((study_out / "trials.json").read_text())
    assert trials["args"] == rec["args"] and trials["trials"][0]["state"] == "COMPLETE"
    assert trials["trials"][0]["process"]["pid"] == os.getpid()


# ----------------------------------------------------------------------------- 3: distinct samplers


def test_two_processes_of_a_parallel_study_propose_different_first_trials(tmp_path):
    from train.tuning import open_study, sample_hyperparams, trial_seed

    storage = f"sqlite:///{tmp_path / 'study.db'}"
    # two processes with the same command: each opens the study with the same --seed
    first = [open_study(storage, "s", 0, n_startup_trials=5, n_warmup_steps=1) for _ in range(2)]
    trials = [study.ask() for study in first]
    hps = [sample_hyperparams(t, "ppo", 16) for t in trials]
    assert [t.number for t in trials] == [0, 1] and hps[0] != hps[1]
    # reproducible: trial n of a study with --seed s draws from trial_seed(s, n), whichever process runs it
    again = open_study(f"sqlite:///{tmp_path / 'again.db'}", "s", 0, n_startup_trials=5, n_warmup_steps=1)
    assert sample_hyperparams(again.ask(), "ppo", 16) == hps[0]
    assert trial_seed(0, 0) != trial_seed(0, 1) and trial_seed(0, 1) == trial_seed(0, 1)


# ----------------------------------------------------------------------------- 4: a SIGKILLed trial


def test_a_trial_left_running_by_a_killed_process_is_failed_and_reported(tmp_path, capsys):
    out = tmp_path / "study"
    proc = _start(["tune", "--trials", "3", "--out", str(out), *TINY_TUNE])
    _wait_for(proc, lambda: (out / "trials" / "trial_0" / "train_args.json").is_file())
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    storage = f"sqlite:///{out / 'study.db'}"
    assert [t.state.name for t in optuna.load_study(study_name="tune-ppo-raw", storage=storage).trials] == ["RUNNING"]
    assert main(["tune", "--trials", "1", "--out", str(out), *TINY_TUNE]) == 0
    err = _errors(capsys.readouterr().err)
    assert len(err) == 1 and "trial 0 was left running by a process that is gone; marked failed" in err[0], err
    trials = json.loads((out / "trials.json").read_text())["trials"]
    assert [t["state"] for t in trials] == ["FAIL", "COMPLETE"]
    assert f"pid {proc.pid}" in trials[0]["fail_reason"] and "gone" in trials[0]["fail_reason"]
    assert json.loads((out / "best_hyperparams.json").read_text())["trial"] == 1


# ----------------------------------------------------------------------------- 5: --steps below the steps done


def test_resume_with_steps_below_the_steps_done_is_refused(tmp_path, capsys):
    from train.trainer import train

    out = tmp_path / "run"
    hp = {"n_steps": 32, "batch_size": 64, "n_epochs": 1}
    kw = dict(num_robots=2, eval_tracks=("crab",), eval_every=0, checkpoint_every=64, overrides=hp, quiet=True,
              env_kwargs={"time_limit_factor": 0.1}, eval_max_time=0.5)
    train("ppo", "raw", "crab", seed=0, steps=128, out=out, **kw)
    (out / "model.zip").unlink()  # a run stopped after its checkpoint at 128 steps
    rc = main(["train", "--out", str(out), "--resume", "--steps", "64", "--num-robots", "2", "--quiet"])
    err = _errors(capsys.readouterr().err)
    assert rc == 2 and len(err) == 1 and "has 128 steps already, --steps 64 is the run's total" in err[0], err
    with pytest.raises(ValueError, match="has 128 steps already"):  # the library too: never complete at 128 > 64
        train("ppo", "raw", "crab", seed=0, steps=64, out=out, resume=True, **kw)
    assert not (out / "model.zip").exists()


# ----------------------------------------------------------------------------- 6: SIGINT and SIGTERM


@pytest.mark.parametrize("sig,code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_ends_train_with_one_line_and_the_run_saved(tmp_path, sig, code, capsys):
    out = tmp_path / "run"
    proc = _start(["train", "--out", str(out), *LONG_TRAIN])
    _wait_for(proc, lambda: any((out / "checkpoints").glob("model_*_steps.zip")))
    proc.send_signal(sig)
    stdout, stderr = proc.communicate(timeout=120)
    err = _errors(stderr)
    name = signal.Signals(sig).name
    assert proc.returncode == code and len(err) == 1, (proc.returncode, stderr)
    assert err[0].startswith(f"azimut train: interrupted ({name}) at ") and "--resume continues" in err[0]
    assert "Traceback" not in stdout + stderr
    run = json.loads((out / "run.json").read_text())
    n = run["num_timesteps"]
    assert run["complete"] is False and run["interrupted"] == name and run["stopped"] == "interrupted"
    assert 0 < n < run["steps"] and f"{n} of 1000000 steps" in err[0]
    assert (out / "checkpoints" / f"model_{n}_steps.zip").is_file() and (out / "model.zip").is_file()
    if sig == signal.SIGINT:  # --resume continues from the interrupted run's checkpoint to its budget
        argv = ["train", "--out", str(out), "--resume", *LONG_TRAIN]
        argv[argv.index("--steps") + 1] = str(n + 64)
        assert main(argv) == 0
        run = json.loads((out / "run.json").read_text())
        assert run["complete"] and run["resumed_from"].endswith(f"model_{n}_steps.zip") and "interrupted" not in run


def test_sigint_ends_tune_with_one_line_and_trials_json(tmp_path):
    out = tmp_path / "study"
    proc = _start(["tune", "--trials", "3", "--out", str(out), *TINY_TUNE])
    _wait_for(proc, lambda: (out / "trials" / "trial_0" / "train_args.json").is_file())
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=120)
    err = _errors(stderr)
    assert proc.returncode == 130 and len(err) == 1, (proc.returncode, stderr)
    assert err[0].startswith("azimut tune: interrupted (SIGINT)") and "trials.json written" in err[0]
    assert "Traceback" not in stdout + stderr
    data = json.loads((out / "trials.json").read_text())
    assert data["interrupted"] == "SIGINT"
    last = data["trials"][-1]
    assert last["state"] == "FAIL" and last["interrupted"] == "SIGINT", data["trials"]
    run = json.loads((out / "trials" / f"trial_{last['number']}" / "run.json").read_text())
    assert run["interrupted"] == "SIGINT" and run["complete"] is False


# ----------------------------------------------------------------------------- 7: a storage that is a folder


@pytest.mark.parametrize("where", ["default", "given", "given with a query"])
def test_an_sqlite_storage_that_is_a_folder_is_refused_in_one_line(tmp_path, where, capsys):
    out = tmp_path / "study"
    folder = out / "study.db" if where == "default" else tmp_path / "a-folder"
    folder.mkdir(parents=True)
    url = f"sqlite:///{folder}" + ("?timeout=5" if "query" in where else "")
    argv = ["tune", "--out", str(out), *TINY_TUNE] + ([] if where == "default" else ["--storage", url])
    rc = main(argv)
    err = _errors(capsys.readouterr().err)
    assert rc == 2 and len(err) == 1 and "is a folder, not an SQLite file" in err[0], err
    assert (sorted(p.name for p in out.iterdir()) == ["study.db"]) if where == "default" else not out.exists()
