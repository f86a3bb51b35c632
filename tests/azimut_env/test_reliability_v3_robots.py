"""Regression tests of issue 31 (reliability v3): robot files and command-line odds.

Each test failed before its fix: the chassis of a robot file whose modules lie far out (the
default 0.6 m plate: a wheel drove through an obstacle), files that passed the reader then
crashed ``azimut eval`` (centre of mass outside the support, ``alpha_deg`` in radians, lengths in
millimetres, masses in grams, an offset b the substep cannot take), ``bench-env --num-envs
10000000`` and ``--out`` at a dangling link (tracebacks), a kick of 1e200 (ZeroDivisionError in
the summary kernel), the silent first compile off a terminal, ``azimut --version`` and
``--action icr_rate``. A hypothesis property test covers the class of robot files: refused in one
line naming the file and a key, or simulated with finite results.
"""

from __future__ import annotations

import math
import os
import re

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from azimut_env.params import RobotParams
from estimation.robot_file import RobotFileError
from jobs.cli import main


def robot_text(modules, b=0.08, r=0.08, extra=""):
    """A schema-1 robot file: ``modules`` are dicts of a module table's keys."""
    rows = "".join("[[geometry.modules]]\n" + "".join(f"{k} = {v!r}\n" for k, v in m.items()) for m in modules)
    return f"schema = 1\n[geometry]\nb_m = {b!r}\nr_m = {r!r}\n{rows}{extra}"


def polar(alphas, l):
    return [{"alpha_deg": float(a), "l_m": float(l)} for a in alphas]


SQUARE = (45.0, 135.0, -135.0, -45.0)


def write(tmp_path, text, name="robot.toml"):
    p = tmp_path / name
    p.write_text(text)
    return str(p)


def cli(argv, capsys):
    try:
        code = main(argv)
    except SystemExit as exc:  # pragma: no cover - main returns its codes
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


# ---------------------------------------------------------------- 1. the chassis of a robot file


def test_chassis_is_derived_from_far_modules_and_holds_every_axis(tmp_path):
    p = RobotParams.from_file(write(tmp_path, robot_text(polar(SQUARE, 2.0))))
    reach = 2.0 * math.cos(math.pi / 4)
    assert p.chassis.length == pytest.approx(2 * (reach + 0.08))
    assert p.chassis.width == pytest.approx(2 * (reach + 0.08))
    # the plate's inertia follows its size (the default plate's was 1.62 kg·m²)
    assert p.chassis.inertia == pytest.approx(27.0 * 2 * p.chassis.length ** 2 / 12)
    for name in ("azimut3", "tri", "hex"):  # the presets keep the 0.6 m plate
        c = RobotParams.preset(name).chassis
        assert (c.length, c.width) == (0.6, 0.6)
    assert RobotParams.preset("swerve").chassis.length == 0.6985


def test_far_wheel_meets_the_obstacle(tmp_path):
    """An obstacle 1.45 m ahead, by the front wheels (axes at x = 1.41 m), is under the far
    robot's chassis (before: outside the 0.6 m plate, the robot started over it and drove
    through it)."""
    from azimut_env.env import AzimutEnv

    path = write(tmp_path, robot_text(polar(SQUARE, 2.0)))
    env = AzimutEnv(robot=path, imperfections="ideal")
    env.reset(seed=0)
    x, y, th = env.task.physics._state[0, :3]
    ahead = (float(x + 1.45 * math.cos(th)), float(y + 1.45 * math.sin(th)), 0.1)
    with pytest.raises(ValueError, match="overlap the robot's starting footprint"):
        env.reset(seed=0, options={"obstacles": [ahead]})


def test_given_chassis_too_small_for_the_modules_is_refused(tmp_path):
    path = write(tmp_path, robot_text(polar(SQUARE, 2.0), extra="[chassis]\nlength = 0.6\nwidth = 3.0\n"))
    with pytest.raises(RobotFileError, match=r"robot\.toml: \[chassis\]\.length = 0\.6: module \d's steering axis "
                                             r"at x = .* outside the chassis"):
        RobotParams.from_file(path)


# ---------------------------------------------------------------- 2. files that crashed azimut eval

BAD_FILES = {
    # centre of mass outside the support polygon (every module ahead of the origin)
    "com": (robot_text(polar((10, 60, -10, -60), 0.5)), r"\[geometry\.modules\]\[\d\].*centre of mass.*outside"),
    # alpha_deg in radians
    "radians": (robot_text(polar((0.785, 2.356, -2.356, -0.785), 0.3)),
                r"\[geometry\.modules\]\[\d\]\.alpha_deg = 2\.356: degrees expected .*radians\?\); 134\.989\?"),
    # tiny angles: modules nearly on top of each other
    "close": (robot_text(polar((0, 10, 180, 270), 0.3)), r"\[geometry\.modules\]\[1\]: .* closer than the wheel"),
    # lengths in millimetres
    "mm": (robot_text(polar(SQUARE, 300)), r"\[geometry\.modules\]\[0\]\.l_m = 300: .*metres expected "
                                           r"\(millimetres\?\); 0\.3\?"),
    "mm_xy": (robot_text([{"x_m": 300.0, "y_m": 300.0}, {"x_m": -300.0, "y_m": 300.0},
                          {"x_m": -300.0, "y_m": -300.0}]), r"\.x_m = 300: .*0\.3\?"),
    "mm_r": (robot_text(polar(SQUARE, 0.3), r=80.0), r"\[geometry\]\.r_m = 80: .*0\.08\?"),
    # masses in grams
    "grams": (robot_text(polar(SQUARE, 0.3), extra="[chassis]\nmass = 27000.0\n"),
              r"\[chassis\]\.mass = 27000: .*kilograms expected \(grams\?\); 27\?"),
    "grams_module": (robot_text(polar(SQUARE, 0.3), extra="[steering]\nmodule_mass = 2000.0\n"),
                     r"\[steering\]\.module_mass = 2000: .*2\?"),
}


@pytest.mark.parametrize("name", sorted(BAD_FILES))
def test_implausible_file_refused_at_read_time(tmp_path, name):
    text, pattern = BAD_FILES[name]
    path = write(tmp_path, text, f"{name}.toml")
    with pytest.raises(RobotFileError) as exc:
        RobotParams.from_file(path)
    msg = str(exc.value)
    assert msg.startswith(f"robot file {path}: ") and "\n" not in msg
    assert re.search(pattern, msg), msg


@pytest.mark.parametrize("name", ["com", "radians", "mm", "grams"])
def test_implausible_file_is_one_line_and_exit_2_in_eval(tmp_path, capsys, name):
    path = write(tmp_path, BAD_FILES[name][0], f"{name}.toml")
    code, _, err = cli(["eval", "--robot-file", path, "--tracks", "circle", "--controllers", "icr", "--max-time",
                        "3", "--no-plots", "--out", str(tmp_path / "out")], capsys)
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err and path in err, err


def test_offset_outside_the_stability_budget_names_the_keys(tmp_path, capsys):
    """b = 0.25 m on the default 0.02 kg·m² module: before, eval crashed with 'raise substeps',
    which no flag of it allows."""
    path = write(tmp_path, robot_text(polar(SQUARE, 0.3), b=0.25))
    RobotParams.from_file(path)  # a robot for Python (substeps= raises the count there)
    for command in ("eval", "train"):
        code, _, err = cli([command, "--robot-file", path, "--out", str(tmp_path / command)], capsys)
        assert code == 2 and err.count("\n") == 1, err
        assert path in err and "b_m = 0.25 m for [steering] module_inertia = 0.02" in err, err
    # bench-env has --substeps: its own check, with the count that passes
    code, _, err = cli(["bench-env", "--robot-file", path, "--steps", "10"], capsys)
    assert code == 2 and "--substeps 8" in err and "use at least" in err, err


# ---------------------------------------------------------------- 3. bench-env and dangling links


def test_bench_env_num_envs_bounded(capsys):
    code, _, err = cli(["bench-env", "--num-envs", "16,10000000"], capsys)
    assert code == 2 and err.count("\n") == 1 and "at most 100000" in err, err


@pytest.mark.parametrize("sub", ["", "/sub"])
def test_out_at_a_dangling_link_is_refused(tmp_path, capsys, sub):
    link = tmp_path / "gone"
    os.symlink(tmp_path / "nowhere" / "x", link)
    code, _, err = cli(["eval", "--out", f"{link}{sub}"], capsys)
    assert code == 2 and err.count("\n") == 1 and "symbolic link" in err, err
    from jobs.args import check_output_path

    with pytest.raises(ValueError, match="symbolic link"):
        check_output_path(link / "report.json")


# ---------------------------------------------------------------- 4. absurd kicks


def test_absurd_kick_refused_at_reset_and_safe_in_the_physics():
    from azimut_env.env import AzimutEnv
    from azimut_env.validation import ResetNeeded

    env = AzimutEnv(imperfections="ideal")
    with pytest.raises(ValueError, match=r"options\['kick'\]\['impulse'\]"):
        env.reset(seed=0, options={"kick": {"step": 0, "impulse": 1e200}})
    env.reset(seed=0, options={"kick": {"step": 0, "impulse": 1000.0}})  # the bound itself is taken
    env.reset(seed=0)
    env.task.physics.kick(0, [0, 1], 1e200)  # past the option's check: the kernel must not raise
    obs, _, terminated, _, info = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    assert terminated and info["error"] and np.all(np.isfinite(obs))
    with pytest.raises(ResetNeeded):
        env.step(np.zeros(env.action_space.shape, dtype=np.float32))


# ---------------------------------------------------------------- 5. the compile notice off a terminal


def test_compile_notice_speaks_only_while_numba_compiles(capsys):
    """Off a terminal too, once work starts, and only if numba compiled something in this process
    (a kernel loaded from the cache raises no compile event): a warm run and a refusal stay silent."""
    from types import SimpleNamespace

    from jobs import cli as cli_module

    timer = cli_module._compile_notice("eval", 60.0, SimpleNamespace(count=3))  # main's form: cancelled at the end
    assert timer is not None and timer.daemon
    timer.cancel()
    assert capsys.readouterr().err == ""
    cli_module._compile_notice("eval", 0.0, SimpleNamespace(count=0))  # warm: nothing compiled
    assert capsys.readouterr().err == ""
    cli_module._compile_notice("eval", 0.0, SimpleNamespace(count=2))
    err = capsys.readouterr().err
    assert err.startswith("azimut eval: compiling the numba kernels") and err.count("\n") == 1
    code, _, err = cli(["eval", "--seed", "-1"], capsys)  # a refusal stays one line, without the notice
    assert code == 2 and err.count("\n") == 1 and "compiling" not in err


def test_compile_notice_counts_real_compilations():
    """The counter sees numba compile a new kernel, and not a cached one loaded again."""
    import numba

    from jobs import cli as cli_module

    counter = cli_module._CompileCounter()
    try:
        @numba.njit
        def add_one(x):
            return x + 1

        add_one(1)
        assert counter.count >= 1
    finally:
        counter.close()


# ---------------------------------------------------------------- 6. --version, --action icr_rate


def test_version(capsys):
    from importlib import metadata

    code, out, err = cli(["--version"], capsys)
    assert code == 0 and out.strip() == f"azimut {metadata.version('azimut')}" and not err


def test_bench_env_action_takes_the_tables_spelling():
    import argparse

    from jobs import bench_env

    parser = argparse.ArgumentParser()
    bench_env.add_arguments(parser)
    assert parser.parse_args(["--action", "icr_rate,raw,icr_target"]).action == ["icr-rate", "raw", "icr-target"]


# ---------------------------------------------------------------- the class of robot files

_KEY = re.compile(r"^robot file \S+: (\[[a-z_.]+\](\[\d+\])?(\.[a-z_]+)?|[a-z_]+)")


@st.composite
def robot_files(draw):
    """Robot files: half of them a plausible robot (modules spread around the centre, SI units),
    half anything of the same shape (millimetres, radians, grams, points anywhere)."""
    n = draw(st.integers(3, 6))
    plausible = draw(st.booleans())
    unit = 1.0 if plausible else draw(st.sampled_from([1.0, 1000.0]))  # millimetres
    if plausible or draw(st.booleans()):
        radians = not plausible and draw(st.booleans())
        spread = 0.6 if plausible else 1.5  # of the spacing 360/n
        base = np.linspace(0, 360, n, endpoint=False) + draw(st.floats(-30, 30))
        jitter = [j * spread * 180.0 / n for j in draw(st.lists(st.floats(-1, 1), min_size=n, max_size=n))]
        alphas = [float(a + j) * (math.pi / 180 if radians else 1.0) for a, j in zip(base, jitter)]
        ls = draw(st.lists(st.floats(0.15, 2.0), min_size=n, max_size=n))
        if draw(st.booleans()):
            mods = [{"alpha_deg": round(a, 4), "l_m": round(l * unit, 4)} for a, l in zip(alphas, ls)]
        else:
            mods = [{"x_m": round(l * math.cos(math.radians(a)) * unit, 4),
                     "y_m": round(l * math.sin(math.radians(a)) * unit, 4)} for a, l in zip(alphas, ls)]
    else:
        pts = draw(st.lists(st.tuples(st.floats(-2.0, 2.0), st.floats(-2.0, 2.0)), min_size=n, max_size=n))
        mods = [{"x_m": round(x * unit, 4) + 0.01, "y_m": round(y * unit, 4)} for x, y in pts]
    b = round(draw(st.sampled_from([0.0, 0.04, 0.08] + [0.15, 0.25] * (not plausible))) * unit, 4)
    r = round(draw(st.sampled_from([0.03, 0.05, 0.08, 0.15])) * unit, 4)
    extra = ""
    if draw(st.booleans()):
        grams = 1.0 if plausible else draw(st.sampled_from([1.0, 1000.0]))
        extra += f"[chassis]\nmass = {draw(st.floats(10.0, 200.0)) * grams!r}\n"
        if draw(st.booleans()):
            extra += f"length = {draw(st.floats(0.2, 5.0))!r}\n"
    if draw(st.booleans()):
        extra += f"[steering]\nmodule_mass = {draw(st.floats(0.5, 10.0))!r}\n"
    return robot_text(mods, b=b, r=r, extra=extra)


@settings(max_examples=int(os.environ.get("AZIMUT_ROBOT_FUZZ", "100")), deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(text=robot_files())
def test_any_robot_file_is_refused_in_one_line_or_simulates_finitely(tmp_path_factory, text):
    """A robot file is refused (at read time, or by the command line's stability check) in one
    line naming the file and a key, or ``azimut eval``'s episode runs and its results are finite."""
    import argparse

    from control.rollout import run_episode
    from jobs.args import check_robot_stability

    path = write(tmp_path_factory.mktemp("fuzz"), text)
    try:
        RobotParams.from_file(path)
        check_robot_stability(argparse.Namespace(robot_file=path, robot=None, imperfections=None))
    except ValueError as exc:
        msg = str(exc).removeprefix("argument --robot-file: ")
        assert "\n" not in msg and msg.startswith(f"robot file {path}: "), msg
        assert _KEY.match(msg.replace(path, "F")) or "stability budget" in msg, msg
        return
    log = run_episode("icr", "circle", 0, max_time=3.0, env_kwargs={"robot": path, "imperfections": "ideal"})
    assert log.error in (None, "time limit", "off track", "stalled"), log.error
    for name in ("pose", "lateral", "slip_power", "nullspace_force", "antagonism", "beta_true", "mu_true"):
        assert np.all(np.isfinite(getattr(log, name))), name
