"""Regression tests of issue 10 for the ``azimut`` command line: every argument and output path is
checked before work starts; a mistake is exit status 2 and one line on stderr, never a traceback."""

from __future__ import annotations

import os
import site
import subprocess
import sys
import time
from pathlib import Path

import pytest

from jobs.args import check_output_path
from jobs.cli import COMMANDS, main

ROOT = Path(__file__).resolve().parents[2]  # the repository
UNWRITABLE = "/proc"  # creating a file there fails, even for root


def run_cli(argv, capsys):
    t0 = time.perf_counter()
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err, time.perf_counter() - t0


@pytest.fixture()
def a_file(tmp_path):
    f = tmp_path / "existing.txt"
    f.write_text("x")
    return str(f)


BAD = [
    # the list
    "eval --out {file}", "eval --out {file}/sub", "eval --seed -1", "bench-env --steps 0", "sim-paper --track nope",
    "bench-estimators --json " + UNWRITABLE + "/x.json", "sim-paper --plot " + UNWRITABLE + "/p.png",
    "eval --out " + UNWRITABLE + "/report", "bench-estimators --methods LS",
    # more found the same way
    "eval --tracks nope", "eval --tracks ''", "eval --controllers icr,icr", "eval --controllers ppo2",
    "eval --speed-scale nan", "eval --speed-scale 0", "eval --speed-scale -1", "eval --speed-scale inf",
    "eval --kick-runs -3", "eval --seed 1.5", "eval --seed x", "eval --max-time 0", "eval --max-time nan",
    "eval --bogus", "bench-env --track nope", "bench-env --substeps 0", "bench-env --num-envs 0",
    "bench-env --num-envs 1,x", "bench-env --vector-steps -1", "bench-env --episode-steps 0",
    "bench-env --solver-iterations 0", "bench-env --reference Nope-v9", "bench-env --seed -2",
    "sim-paper --seed -1", "sim-paper --max-steps 0", "sim-paper --plot {tmp}", "sim-paper --plot {file}/p.png",
    "bench-estimators --points 5", "bench-estimators --random 1", "bench-estimators --single-calls 0",
    "bench-estimators --methods NE,XX", "bench-estimators --methods NE,NE", "bench-estimators --d2 other",
    "bench-estimators --json {tmp}", "bench-estimators --json {tmp}/missing/x.json", "bench-estimators --seed -1",
    "record-d2 --points 0", "record-d2 --out {file}/x.npz", "record-d2 --speed-scale 0", "record-d2 --seed -5",
    "record-d2 --out {tmp}", "nope", "eval --out ''",
    "eval --controllers ppo:{file}", "eval --controllers sac:{tmp}/none.zip", "eval --workers 0", "eval --seeds 5-1",
    # the new-user trial: substeps outside the stability budget, an empty list entry
    "sim-paper --substeps 1", "sim-paper --substeps 4", "bench-env --substeps 1 --num-envs 1 --steps 10",
    "bench-env --num-envs 1,,2", "bench-env --num-envs ,1",
    # issue 19: the imperfections presets of bench-env, sim-paper's D2 sweep
    "bench-env --imperfections real", "bench-env --imperfections paper,paper", "bench-env --imperfections ''",
    "sim-paper --d2",
]


@pytest.mark.parametrize("line", BAD)
def test_bad_argument_is_one_line_and_exit_2_before_any_work(line, capsys, tmp_path, a_file):
    import shlex

    argv = [a.format(file=a_file, tmp=tmp_path) for a in shlex.split(line)]
    if argv[0] not in COMMANDS and argv[0] != "nope":
        pytest.skip(f"{argv[0]} not available")
    code, out, err, dt = run_cli(argv, capsys)
    assert code == 2, (line, code, err)
    assert len(err.strip().splitlines()) == 1, err
    assert "Traceback" not in err and "error" in err
    assert out == ""
    assert dt < 20.0  # refused before the work (imports and numba cache loads only)
    assert not (Path(a_file).parent / "missing").exists()


def test_eval_out_existing_file_is_untouched(capsys, a_file):
    code, *_ = run_cli(["eval", "--out", a_file], capsys)
    assert code == 2 and Path(a_file).read_text() == "x"


def test_check_output_path_accepts_good_paths(tmp_path, a_file):
    assert check_output_path(a_file) == a_file  # overwriting an existing writable file is fine
    assert check_output_path(tmp_path / "new.json") == str(tmp_path / "new.json")
    assert check_output_path(tmp_path / "a" / "b", directory=True)  # created with its parents later
    assert check_output_path(tmp_path, directory=True)
    for bad in ("", "a\0b"):
        with pytest.raises(ValueError):
            check_output_path(bad)
    with pytest.raises(TypeError):
        check_output_path(3)


def test_help_of_every_command_exits_0(capsys):
    for name in COMMANDS:
        code, out, err, _ = run_cli([name, "--help"], capsys) if name in _available() else (0, "x", "", 0)
        assert code == 0 and out and not err


def _available():
    from jobs.cli import _available as av

    return av()


def test_cli_starts_without_importlib_util_preloaded():
    """The wheel-install bug: ``importlib.util`` was used but never imported (an editable install
    imports it at start-up, a plain one does not). ``python -S`` skips site's imports likewise."""
    paths = [str(ROOT), *site.getsitepackages()]
    code = (f"import sys; sys.path[:0] = {paths!r}; assert 'importlib.util' not in sys.modules; "
            "from jobs.cli import main; sys.exit(main(['--help']))")
    proc = subprocess.run([sys.executable, "-S", "-c", code], capture_output=True, text=True, cwd=os.sep, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "eval" in proc.stdout


def test_subprocess_error_has_no_traceback(tmp_path, a_file):
    proc = subprocess.run([sys.executable, "-m", "jobs.cli", "eval", "--out", a_file], capture_output=True,
                          text=True, cwd=ROOT, timeout=120, env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1 and "Traceback" not in proc.stderr


@pytest.mark.parametrize("argv", [["bench-estimators", "--bogus", "\x1e0"], ["eval", "--seed", "1\n2"],
                                  ["eval", "--tracks", "a\rb"]])
def test_control_characters_in_arguments_still_give_one_line(argv, capsys):
    """Found by the property tests: a line break inside an argument split the error in two."""
    code, out, err, _ = run_cli(argv, capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1


def test_tiny_control_period_refused():
    """Found by the property tests: control_period=1.7e-27 overflowed the time-limit step count."""
    from azimut_env.env import AzimutEnv

    with pytest.raises(ValueError, match="control_period"):
        AzimutEnv(control_period=1.6846197063791808e-27)


def test_eval_refuses_an_unloadable_policy_before_the_other_episodes(tmp_path, capsys):
    """Found by hand: ``--controllers ppo:FILE`` with a file that is not a model ran every other
    episode first and failed at the end (exit 1)."""
    pytest.importorskip("stable_baselines3")
    import zipfile

    bad = tmp_path / "bad.zip"
    with zipfile.ZipFile(bad, "w") as z:
        z.writestr("x", "y")
    code, out, err, _ = run_cli(["eval", "--controllers", f"icr,sac:{bad}", "--no-plots", "--out",
                                 str(tmp_path / "r")], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "cannot load" in err and out == ""
    assert not (tmp_path / "r").exists()


def _eval_with_ray_address(address, tmp_path, capsys):
    return run_cli(["eval", "--ray-address", address, "--tracks", "crab", "--max-time", "2", "--no-plots",
                    "--out", str(tmp_path / "r")], capsys)


def test_unreachable_ray_address_refused_in_one_line_within_seconds(tmp_path, capsys):
    """New-user trial: ``--ray-address 127.0.0.1:1`` hung (Ray's GCS client retries for ever)."""
    pytest.importorskip("ray")
    code, out, err, dt = _eval_with_ray_address("127.0.0.1:1", tmp_path, capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "cannot reach" in err, err
    assert dt < 20.0 and not (tmp_path / "r").exists()


@pytest.mark.parametrize("address", ["nohostport", "host:notaport", "host:70000"])
def test_malformed_ray_address_refused(address, tmp_path, capsys):
    pytest.importorskip("ray")
    code, out, err, _ = _eval_with_ray_address(address, tmp_path, capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "HOST:PORT" in err, err


def test_ray_address_auto_without_a_cluster_is_one_line(tmp_path, capsys, monkeypatch):
    """New-user trial: ``--ray-address auto`` with no Ray running gave exit 1 and a 29-line traceback."""
    pytest.importorskip("ray")
    from ray._private.services import canonicalize_bootstrap_address

    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    try:
        canonicalize_bootstrap_address("auto")
        pytest.skip("a Ray cluster runs on this machine")
    except ConnectionError:
        pass
    code, out, err, dt = _eval_with_ray_address("auto", tmp_path, capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "no running Ray cluster" in err, err
    assert not (tmp_path / "r").exists()


def test_ray_init_failure_after_the_check_is_one_line(tmp_path, capsys, monkeypatch):
    """A port that accepts TCP but is no Ray head passes the socket check; ray.init's
    ConnectionError then ends the command with one line and status 2 (not a traceback)."""
    ray = pytest.importorskip("ray")
    import socket

    def refuse(*a, **k):
        raise ConnectionError("Failed to connect to Ray cluster")

    monkeypatch.setattr(ray, "init", refuse)
    monkeypatch.setattr(ray, "is_initialized", lambda: False)
    with socket.socket() as srv:
        srv.bind(("127.0.0.1", 0))
        srv.listen(4)
        code, out, err, _ = _eval_with_ray_address(f"127.0.0.1:{srv.getsockname()[1]}", tmp_path, capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "no Ray cluster answered" in err, err


def test_substeps_error_names_the_flag_and_the_smallest_stable_count(capsys):
    code, out, err, _ = run_cli(["sim-paper", "--substeps", "4"], capsys)
    assert code == 2 and "--substeps 4" in err and "use at least 5" in err, err
