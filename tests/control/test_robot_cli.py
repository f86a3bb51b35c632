"""--robot / --robot-file and --tracks scenarios on the command line: refusals in one line (exit
2), a short run on a preset and a scenario."""

import json

import pytest

from jobs.cli import main


@pytest.mark.parametrize("argv, needle", [
    (["eval", "--robot", "quad"], "unknown robot 'quad'"),
    (["train", "--robot", "quad", "--out", "x"], "unknown robot 'quad'"),
    (["bench-env", "--robot", "quad"], "unknown robot 'quad'"),
    (["sim-paper", "--robot", "quad"], "unknown robot 'quad'"),
    (["eval", "--robot", "tri", "--robot-file", "{toml}"], "not allowed with argument"),
    (["eval", "--robot-file", "{missing}"], "no such file"),
    (["eval", "--robot-file", "{bad}"], "missing table [geometry]"),
    (["eval", "--tracks", "suite,hold"], "repeated entries"),
    (["eval", "--tracks", "zigzag"], "unknown 'zigzag'"),
    (["eval", "--robot", "swerve", "--kick-runs", "3", "--no-plots"], "default robot (azimut3) only"),
])
def test_refused_in_one_line(tmp_path, capsys, argv, needle):
    good = tmp_path / "r.toml"
    from azimut_env.robot_file import preset_source

    good.write_text(preset_source("tri"))
    bad = tmp_path / "bad.toml"
    bad.write_text("schema = 1\n")
    argv = [a.format(toml=good, missing=tmp_path / "no.toml", bad=bad) for a in argv]
    assert main(argv + ["--out", str(tmp_path / "o")] if argv[0] == "eval" else argv) == 2
    err = capsys.readouterr().err
    assert needle in err and err.count("\n") == 1 and "Traceback" not in err


def test_eval_on_a_robot_file_and_a_scenario(tmp_path):
    from azimut_env.robot_file import preset_source

    robot = tmp_path / "tri.toml"
    robot.write_text(preset_source("tri"))
    out = tmp_path / "eval"
    assert main(["eval", "--robot-file", str(robot), "--tracks", "hold", "--controllers", "twist", "--max-time", "2",
                 "--no-plots", "--out", str(out)]) in (0, 1)
    m = json.loads((out / "metrics.json").read_text())
    row = m["episodes"][0]
    assert row["track"] == "hold" and "peak_steer_rate" in row and "hold_steps" in row
    assert m["campaign"]["robot"] == f"file {robot}"
    assert "hold: steer" in (out / "report.md").read_text()


def test_bench_env_times_each_imperfections_preset():
    """``bench-env --imperfections ideal,paper``: the vector env is built with each preset in turn
    (the first also for the single env), on top of --robot."""
    import argparse

    from azimut_env.imperfections import with_imperfections
    from azimut_env.params import RobotParams
    from azimut_env.vector_env import AzimutVectorEnv
    from jobs.bench_env import _robot_kwargs, add_arguments, check_args

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    args = parser.parse_args(["--imperfections", "ideal,paper", "--reference", ""])
    assert args.imperfections == ["ideal", "paper"]
    check_args(args)
    assert _robot_kwargs(args) == {"imperfections": "ideal"}
    for name, expected in (("ideal", RobotParams()), ("paper", with_imperfections(RobotParams(), "paper"))):
        venv = AzimutVectorEnv(num_envs=1, **_robot_kwargs(args, name))
        assert venv.params == expected
        venv.close()
    swerve = argparse.Namespace(robot="swerve", robot_file=None, imperfections=None)
    assert _robot_kwargs(swerve) == {"robot": "swerve"}  # no preset given: the envs' rule
    assert _robot_kwargs(swerve, "paper") == {"robot": "swerve", "imperfections": "paper"}
