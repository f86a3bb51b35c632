"""Issue 20 (reliability v2), the files the ``azimut`` command line reads and writes: every path
it writes is checked before work (what exists there and of what kind), every record it reads back
is validated and recomputed when invalid, ``--resume`` of ``azimut train`` reads its checkpoint
before any work. Each refusal: exit status 2 and one line on stderr."""

from __future__ import annotations

import argparse
import json
import os
import pickle
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import pytest

from jobs.args import check_output_layout
from jobs.campaign.engine import Task, TaskStore, run_tasks
from jobs.campaign.store import record_problem
from jobs.cli import main

TINY_EVAL = ["eval", "--controllers", "icr", "--tracks", "paper", "--max-time", "0.2", "--no-plots"]


def run_cli(argv, capsys):
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def _one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


# ---------------------------------------------------------------------- output folders


@pytest.mark.parametrize("name, kind", [("episodes", "file"), ("plots", "file"), ("metrics.json", "dir"),
                                        ("report.md", "dir"), ("episodes/x.json", "dir")])
def test_eval_output_folder_of_the_wrong_kind_refused_before_work(tmp_path, capsys, name, kind):
    """An output folder whose ``episodes/`` or ``plots/`` is a file, or whose ``metrics.json`` or
    ``report.md`` is a directory, crashed ``azimut eval``, some only after every episode had run."""
    out = tmp_path / "out"
    (out / "episodes").mkdir(parents=True)
    target = out / name
    if kind == "file":
        if target.is_dir():
            target.rmdir()
        target.write_text("x")
    else:
        target.mkdir()
    argv = [a for a in TINY_EVAL if a != "--no-plots"] if name == "plots" else TINY_EVAL
    code, _, err = run_cli(argv + ["--out", str(out)], capsys)
    assert code == 2 and str(target) in _one_line(err)
    assert sorted(p.name for p in out.iterdir()) == sorted({"episodes", name.split("/")[0]})  # nothing written


def test_layout_names_videos_and_kicks(tmp_path):
    from jobs.eval.outputs import output_layout

    args = argparse.Namespace(no_plots=False, video="gif", kick_runs=3, controllers=["icr", "twist"], export="mcap",
                              tracks=["paper"])
    files, dirs = output_layout(args, [0, 1])
    assert {"metrics.json", "report.md", "kicks_icr.json", "kicks_twist.json"} <= set(files)
    assert {"episodes", "plots", "videos", "kicks/icr", "kicks/twist", "exports", "exports/icr-paper-s0",
            "exports/twist-paper-s1"} <= set(dirs)
    (tmp_path / "videos").write_text("x")
    with pytest.raises(ValueError, match="videos: exists and is not a directory"):
        check_output_layout(tmp_path, files, dirs)
    (tmp_path / "videos").unlink()
    (tmp_path / "kicks").write_text("x")
    with pytest.raises(ValueError, match="kicks: exists and is not a directory"):
        check_output_layout(tmp_path, files, dirs)


def test_train_output_folder_checked(tmp_path, capsys):
    pytest.importorskip("stable_baselines3")
    (tmp_path / "run.json").mkdir()
    code, _, err = run_cli(["train", "--steps", "2048", "--out", str(tmp_path)], capsys)
    assert code == 2 and "run.json: is a directory" in _one_line(err)
    (tmp_path / "run.json").rmdir()
    (tmp_path / "seed_1").mkdir()
    (tmp_path / "seed_1" / "checkpoints").write_text("x")
    code, _, err = run_cli(["train", "--steps", "2048", "--seeds", "0-2", "--out", str(tmp_path)], capsys)
    assert code == 2 and "seed_1/checkpoints: exists and is not a directory" in _one_line(err)


# ---------------------------------------------------------------------- records read back


@pytest.fixture(scope="module")
def finished_eval(tmp_path_factory):
    """A finished one-episode eval folder and its record's text."""
    out = tmp_path_factory.mktemp("eval")
    assert main(TINY_EVAL + ["--out", str(out)]) == 0
    (record,) = (out / "episodes").glob("*.json")
    return out, record, record.read_text()


def _corrupt(record: Path, text: str, how: str) -> None:
    rec = json.loads(text)
    if how == "missing result":
        del rec["result"]
    elif how == "missing metric":
        del rec["result"]["metrics"]["rms_lateral_m"]
    elif how == "metric of another kind":
        rec["result"]["metrics"]["rms_lateral_m"] = "0.1"
    elif how == "another seed":
        rec["result"]["metrics"]["seed"] = 7
    elif how == "status":
        rec["status"] = "done"
    record.write_text({"[]": "[]", "null": "null", "torn": text[: len(text) // 2]}.get(how) or json.dumps(rec))


@pytest.mark.parametrize("how", ["[]", "null", "torn", "missing result", "missing metric", "metric of another kind",
                                 "another seed", "status"])
def test_eval_resume_recomputes_an_invalid_record(finished_eval, capsys, how):
    """A corrupted episode record of the wrong shape (valid JSON: ``[]``, ``null``, a missing
    result) crashed ``eval --resume``."""
    out, record, text = finished_eval
    capsys.readouterr()
    _corrupt(record, text, how)
    code, stdout, err = run_cli(TINY_EVAL + ["--out", str(out), "--resume"], capsys)
    assert code == 0, err
    assert f"{record}: not a valid episode record" in _one_line(err) and "recomputing it" in err
    assert "[1/1]" in stdout  # recomputed
    assert json.loads(record.read_text()) == json.loads(text) | {k: json.loads(record.read_text())[k]
                                                                 for k in ("elapsed_s", "cpu_s", "worker")}
    code, stdout, err = run_cli(TINY_EVAL + ["--out", str(out), "--resume"], capsys)
    assert code == 0 and not err and "[1/1]" not in stdout  # valid again: reused


def test_eval_resume_with_a_record_that_is_a_directory_is_refused(finished_eval, capsys):
    out, record, text = finished_eval
    record.unlink()
    record.mkdir()
    try:
        code, _, err = run_cli(TINY_EVAL + ["--out", str(out), "--resume"], capsys)
        assert code == 2 and f"{record}: is a directory" in _one_line(err)
    finally:
        record.rmdir()
        record.write_text(text)


def test_record_problem_envelope():
    task = Task("jobs.eval.campaign:episode_task", {"a": 1})
    good = {"id": task.id, "fn": task.fn, "key": {"a": 1}, "status": "failed", "attempts": 2}
    assert record_problem(good, task) is None
    for bad in ([], None, 3, {**good, "key": {"a": 2}}, {**good, "id": "x"}, {**good, "attempts": True},
                {**good, "attempts": 0}, {**good, "status": "ok"}, {**good, "status": "ok", "result": []}):
        assert record_problem(bad, task) is not None, bad


def test_run_tasks_refuses_a_record_path_that_is_a_directory_before_running(tmp_path):
    task = Task("builtins:dict", {"a": 1})
    store = TaskStore(tmp_path)
    store.path(task).mkdir()
    with pytest.raises(ValueError, match="is not a regular file"):
        run_tasks([task], store)


# ---------------------------------------------------------------------- azimut train --resume


@pytest.fixture()
def checkpoint_folder(tmp_path):
    """A run folder whose checkpoint passes the checks: a model archive of SB3's layout and real
    VecNormalize statistics beside it."""
    pytest.importorskip("stable_baselines3")
    import gymnasium as gym
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    ckpts = tmp_path / "checkpoints"
    ckpts.mkdir()
    with zipfile.ZipFile(ckpts / "model_2048_steps.zip", "w") as z:
        z.writestr("data", json.dumps({"n": 1}))
        z.writestr("policy.pth", b"\0" * 4096)
    VecNormalize(DummyVecEnv([lambda: gym.make("Pendulum-v1")])).save(str(ckpts / "model_vecnormalize_2048_steps.pkl"))
    return tmp_path


@pytest.mark.parametrize("how, message", [
    ("truncated", "corrupted or truncated"), ("garbage", "corrupted or truncated"), ("crc", "fails its CRC check"),
    ("not sb3", "not a saved SB3 model"), ("no statistics", "no VecNormalize statistics beside it"),
    ("bad statistics", "unreadable VecNormalize statistics"), ("other pickle", "holds a dict"),
])
def test_train_resume_reads_its_checkpoint_before_any_work(checkpoint_folder, capsys, monkeypatch, how, message):
    """``azimut train --resume`` with a corrupted or truncated checkpoint, or a missing checkpoint
    vecnormalize, gave a traceback."""
    import jobs.training.command as command

    ran = []
    monkeypatch.setattr(command, "run", lambda args: ran.append(args) or 0)
    argv = ["train", "--steps", "4096", "--resume", "--out", str(checkpoint_folder)]
    assert run_cli(argv, capsys)[0] == 0 and ran  # the intact folder passes
    ckpt = checkpoint_folder / "checkpoints" / "model_2048_steps.zip"
    stats = checkpoint_folder / "checkpoints" / "model_vecnormalize_2048_steps.pkl"
    data = ckpt.read_bytes()
    if how == "truncated":
        ckpt.write_bytes(data[: len(data) // 2])
    elif how == "garbage":
        ckpt.write_bytes(b"garbage")
    elif how == "crc":
        with zipfile.ZipFile(ckpt) as z:
            offset = z.getinfo("policy.pth").header_offset + 30 + len("policy.pth") + 10
        ckpt.write_bytes(data[:offset] + bytes([data[offset] ^ 0xFF]) + data[offset + 1:])
    elif how == "not sb3":
        with zipfile.ZipFile(ckpt, "w") as z:
            z.writestr("other", "x")
    elif how == "no statistics":
        stats.unlink()
    elif how == "bad statistics":
        stats.write_bytes(b"x")
    else:
        stats.write_bytes(pickle.dumps({"a": 1}))
    ran.clear()
    code, _, err = run_cli(argv, capsys)
    assert code == 2 and not ran
    line = _one_line(err)
    assert line.startswith("azimut train: error: --resume: ") and message in line


# ---------------------------------------------------------------------- no orphaned workers


def _process_group(pgid: int) -> list[tuple[int, str]]:
    """(pid, command line) of the live processes of process group ``pgid`` (Linux /proc)."""
    out = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            stat = Path(f"/proc/{entry}/stat").read_text()
            cmd = Path(f"/proc/{entry}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        fields = stat.rsplit(")", 1)[1].split()
        if fields[0] != "Z" and int(fields[2]) == pgid:
            out.append((int(entry), cmd))
    return out


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads /proc")
def test_sigkill_of_eval_with_workers_leaves_no_process(tmp_path):
    """SIGKILL of the ``azimut eval --workers 2`` process left its spawn workers and the resource
    tracker alive indefinitely, holding the caller's pipes."""
    root = Path(__file__).resolve().parents[2]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, "-m", "jobs.cli", "eval", "--controllers", "icr,twist", "--tracks",
                             "paper,circle", "--seeds", "0-3", "--workers", "2", "--no-plots", "--out",
                             str(tmp_path / "out")], start_new_session=True, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, env=env, cwd=root)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:  # the driver, the resource tracker and two spawn workers
            workers = [p for p in _process_group(proc.pid) if "multiprocessing.spawn" in p[1]]
            if len(workers) == 2:
                break
            time.sleep(0.2)
        assert len(workers) == 2, _process_group(proc.pid)
        time.sleep(1.0)  # the workers initialised (their watchdog runs)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        deadline = time.monotonic() + 15
        while _process_group(proc.pid) and time.monotonic() < deadline:
            time.sleep(0.2)
        left = _process_group(proc.pid)
        assert not left, left
        proc.stdout.read()  # EOF: nobody holds the pipe any more
    finally:
        for pid, _ in _process_group(proc.pid):  # only what this test started
            os.kill(pid, signal.SIGKILL)
        proc.stdout.close()


def test_eval_resume_after_editing_the_robot_file_recomputes(tmp_path, capsys):
    import azimut_env

    robot = tmp_path / "robot.toml"
    text = (Path(azimut_env.__file__).parent / "robots" / "azimut3.toml").read_text()
    robot.write_text(text)
    argv = TINY_EVAL + ["--robot-file", str(robot), "--out", str(tmp_path / "out")]
    assert main(argv) == 0 and "[1/1]" in capsys.readouterr().out
    assert main(argv + ["--resume"]) == 0 and "[1/1]" not in capsys.readouterr().out
    robot.write_text(text + "\n# edited: the same parameters, another file content\n")
    assert main(argv + ["--resume"]) == 0 and "[1/1]" in capsys.readouterr().out


def test_controller_files_by_kind():
    import json as json_module

    from jobs.eval.controllers import controller_files

    assert controller_files("icr") == {} and controller_files("twist") == {}
    assert controller_files("json:dumps") == {"module": json_module.__file__}  # a user's module: its source


def test_azimut_without_a_command_is_refused_in_one_line(capsys):
    """``azimut`` alone exits 2 with one line naming the commands (it printed the help and exited 0)."""
    from jobs.cli import main as cli_main

    assert cli_main([]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "a command is required" in err[0] and "eval" in err[0]


def test_integer_flags_take_whole_numbers_in_scientific_notation():
    """``--steps 1e6`` is how step budgets are written; a fraction stays refused."""
    from jobs.args import arg_int

    convert = arg_int(1)
    assert convert("1e6") == 1_000_000 and convert("2.5E5") == 250_000 and convert("300000") == 300_000
    for bad in ("1.5e0", "1e400", "1e6x", "nan", "0.5"):
        with pytest.raises(argparse.ArgumentTypeError):
            convert(bad)


@pytest.mark.parametrize("spec", ["ppo:", "ppo:NAME=", "sac: "])
def test_a_policy_without_a_path_is_refused_by_what_is_missing(spec, tmp_path, capsys):
    from jobs.cli import main as cli_main

    assert cli_main(["eval", "--controllers", spec, "--tracks", "circle", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no model path" in err[0]


@pytest.mark.parametrize("spec,said", [("ppo:=/tmp/x", "no name before '='"), ("ppo:{empty}", "no model.zip in"),
                                       ("sac:{empty}/model.zip", "no model file")])
def test_a_policy_spec_names_what_is_wrong(spec, said, tmp_path, capsys):
    from jobs.cli import main as cli_main

    (tmp_path / "empty").mkdir()
    spec = spec.format(empty=tmp_path / "empty")
    assert cli_main(["eval", "--controllers", spec, "--tracks", "circle", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and said in err[0], err


def test_an_incomplete_single_run_is_evaluated_with_a_note(tmp_path):
    import io
    import json

    from jobs.eval.agents import expand_seed_folders

    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "model.zip").write_text("x")
    (tmp_path / "run" / "run.json").write_text(json.dumps({"complete": False, "stopped": "time_limit"}))
    stream = io.StringIO()
    spec = f"ppo:{tmp_path / 'run'}"
    assert expand_seed_folders([spec, "icr"], stream=stream) == [spec, "icr"]
    assert "incomplete run (stopped by time_limit" in stream.getvalue()
