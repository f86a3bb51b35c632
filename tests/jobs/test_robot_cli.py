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
    (["eval", "--robot", "swerve", "--kick-runs", "3", "--no-plots"], "default robot (azimut3, paper"),
    (["eval", "--imperfections", "ideal", "--kick-runs", "3", "--no-plots"], "default robot (azimut3, paper"),
    (["eval", "--imperfections", "real"], "imperfections must be one of 'paper', 'ideal', got 'real'"),
    (["eval", "--imperfections", "paper,ideal"], "imperfections must be one of"),
    (["train", "--imperfections", "real", "--out", "x"], "imperfections must be one of"),
    (["tune", "--imperfections", "Paper", "--out", "x"], "imperfections must be one of"),
    (["sim-paper", "--imperfections", "none"], "imperfections must be one of"),
    (["bench-env", "--imperfections", "ideal,real"], "unknown 'real'"),
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


def test_imperfections_flag_reaches_the_episodes_and_the_report(tmp_path):
    """``azimut eval --imperfections ideal``: in every task's key (so --resume does not reuse an
    episode of the paper robot), in the env of every episode, and named by metrics.json; without
    the flag the keys are those of before and the default robot is the paper one."""
    import argparse

    from jobs.eval.campaign import _episode_setup, episode_tasks
    from jobs.training.command import _robot_kwargs

    ideal = episode_tasks(["twist"], ["circle", "hold"], [0, 1], imperfections="ideal")
    plain = episode_tasks(["twist"], ["circle", "hold"], [0, 1])
    assert all(t.key["imperfections"] == "ideal" for t in ideal) and all("imperfections" not in t.key for t in plain)
    assert not {t.id for t in ideal} & {t.id for t in plain}
    assert _episode_setup("hold", 0, 1.0, 0.0, False, None, "tri", None, "paper")[1] == {"robot": "tri",
                                                                                         "imperfections": "paper"}
    assert _episode_setup("hold", 0, 1.0, 0.0, False, None, None, None)[1] is None
    out = tmp_path / "eval"
    assert main(["eval", "--imperfections", "ideal", "--tracks", "hold", "--controllers", "twist", "--max-time", "1",
                 "--no-plots", "--out", str(out)]) in (0, 1)
    m = json.loads((out / "metrics.json").read_text())
    assert m["campaign"]["imperfections"] == "ideal" and "(imperfections: ideal)" in (out / "report.md").read_text()
    ns = argparse.Namespace(robot="hex", robot_file=None, imperfections="paper")
    assert _robot_kwargs(ns) == {"robot": "hex", "imperfections": "paper"}  # azimut train's env kwargs


def test_sim_paper_robot_follows_the_file_and_the_flag(tmp_path):
    """sim-paper's robot: the file's preset, --imperfections on top (one definition of the flag)."""
    import argparse

    from azimut_env.imperfections import with_imperfections
    from azimut_env.params import RobotParams
    from azimut_env.robot_file import preset_source
    from jobs.sim_paper import _robot, add_arguments

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    path = tmp_path / "a3.toml"
    path.write_text(preset_source("azimut3"))
    paper = RobotParams.preset("azimut3")
    assert paper == with_imperfections(RobotParams(), "paper")
    for argv, expected in (([], paper), (["--robot", "azimut3"], paper), (["--robot-file", str(path)], paper),
                           (["--robot-file", str(path), "--imperfections", "ideal"], RobotParams()),
                           (["--robot", "swerve"], RobotParams.preset("swerve"))):
        assert _robot(parser.parse_args(argv)) == expected, argv


def test_eval_compares_the_icr_controller_with_both_twist_baselines_by_default():
    """The main job's report has the strongest twist baseline (the setpoint generator) beside the
    plain one; bench-campaign keeps the two-controller campaign its results page measured."""
    import argparse

    from jobs.bench_campaign import add_arguments as bench_arguments
    from jobs.eval.command import add_arguments

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    args = parser.parse_args([])
    assert list(args.controllers) == ["icr", "twist", "twist-setpoint"]
    assert args.tracks == ["paper", "circle", "figure8", "square", "crab", "random"]
    bench = argparse.ArgumentParser()
    bench_arguments(bench)
    assert bench.parse_args([]).controllers == ["icr", "twist"]
