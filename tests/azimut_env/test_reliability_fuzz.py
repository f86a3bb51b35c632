"""Property-based tests (hypothesis) of issue 10: arbitrary options, keyword arguments and command
lines thrown at every entry point. Each call must either succeed or raise a clear error
(``ValueError``, ``TypeError``, ``ResetNeeded``; the CLI: exit status 2 and one line on stderr),
never another exception type; and after a refusal, the next good call must behave exactly as if
the bad one had never happened (the trajectories are compared bit for bit with an env that never
saw it).

The default run keeps ``max_examples`` small (a few tens of seconds in all); ``-m slow`` runs the
same properties with many more examples. ``TRIED`` counts the inputs per entry point; run with
``-s`` to see the counts printed at the end.
"""

from __future__ import annotations

import collections
import importlib
import inspect
import math
import os
import shlex

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from azimut_env.env import AzimutEnv
from azimut_env.tracks import TRACK_NAMES, Track
from azimut_env.validation import ResetNeeded
from azimut_env.vector_env import AzimutVectorEnv
from estimation import METHODS, RobotGeometry, estimate_eta, estimate_icr, quality
from jobs.cli import _available, main

CLEAR = (ValueError, TypeError, ResetNeeded)
TRIED: collections.Counter = collections.Counter()
GEOM = RobotGeometry.azimut3()
SMALL_TRACK = Track.from_waypoints([[0.0, 0.0], [2.0, 0.0], [2.0, 1.0]], speed=0.4, name="paper")
START = SMALL_TRACK.sample(0.0)  # an obstacle here makes a reset fail late (after validation)


def _profiles(fn, default: int, slow: int, **given_kwargs):
    """The same property as a default test (``default`` examples) and a slow one."""
    quick = settings(max_examples=default, deadline=None, derandomize=False,
                     suppress_health_check=list(HealthCheck))(given(**given_kwargs)(fn))
    long = pytest.mark.slow(settings(max_examples=slow, deadline=None,
                                     suppress_health_check=list(HealthCheck))(given(**given_kwargs)(fn)))
    return quick, long


# ---------------------------------------------------------------------- value strategies

junk = st.one_of(
    st.none(), st.booleans(), st.integers(-10**9, 10**9), st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=6), st.complex_numbers(max_magnitude=10), st.lists(st.integers(-10, 10), max_size=5),
    st.lists(st.floats(allow_nan=True), max_size=4), st.dictionaries(st.text(max_size=4), st.integers(), max_size=2),
    st.builds(object), st.just(np.array([1.0, 2.0])), st.just(np.float32(0.5)), st.just(np.int64(2)),
)
#: numbers at the edges of what the task's arrays hold (int64 steps, float64 values)
edge_numbers = st.one_of(st.sampled_from([2**63 - 1, 2**63, -2**63 - 1, 2**64, 10**400, -10**400, 1e308, -1e308,
                                          np.uint64(2**64 - 1), np.array(3), np.array(0.5), np.True_]),
                         st.integers())
plausible_kick = st.fixed_dictionaries({}, optional={
    "step": st.one_of(st.integers(-3, 30), edge_numbers, junk),
    "wheels": st.one_of(st.lists(st.integers(-2, 6), max_size=5), junk),
    "impulse": st.one_of(st.floats(-2, 2), edge_numbers, junk), "extra": junk})
plausible_obstacles = st.one_of(
    st.lists(st.tuples(st.floats(-5, 5), st.floats(-5, 5), st.floats(-0.5, 1.0)), max_size=3),
    st.just([(float(START[0]), float(START[1]), 0.3)]),  # over the start pose: a reset that fails late
    st.just([[(0.0, 0.0), (1.0, 0.0)]]), junk)
option_values = {
    "track": st.one_of(st.sampled_from(TRACK_NAMES + ("nope", "")), st.just(SMALL_TRACK), junk),
    "kick": st.one_of(plausible_kick, junk),
    "start_progress": st.one_of(st.floats(-5, 50), edge_numbers, junk),
    "obstacles": plausible_obstacles,
}
reset_options = st.one_of(
    st.none(), junk,
    st.fixed_dictionaries({}, optional={**option_values, "bogus": junk}),
    st.fixed_dictionaries({"obstacles": st.just([(float(START[0]), float(START[1]), 0.3)])},  # valid, fails late
                          optional={"start_progress": st.floats(0, 0.02), "kick": st.just({"wheels": [1]})}),
)
seeds = st.one_of(st.none(), st.integers(-5, 2**33), junk)


def _actions(n: int, steps: int) -> np.ndarray:
    return np.random.default_rng(1).uniform(-1, 1, (steps, 2 * n)).astype(np.float32)


def _step_all(env, actions):
    out = []
    for a in actions:
        obs, r, term, trunc, _ = env.step(a)
        out.append(np.append(obs, [r, term, trunc]))
    return np.array(out)


# ---------------------------------------------------------------------- single env: reset, step, kick


def _prop_single_env_refusal_changes_nothing(seed0, call, seed, options, action, wheels, impulse):
    TRIED["env." + call] += 1
    env, ref = AzimutEnv(track=SMALL_TRACK), AzimutEnv(track=SMALL_TRACK)
    acts = _actions(env.n, 6)
    env.reset(seed=seed0)
    ref.reset(seed=seed0)
    _step_all(env, acts[:2])
    _step_all(ref, acts[:2])
    try:
        if call == "reset":
            env.reset(seed=seed, options=options)
        elif call == "step":
            env.step(action)
        else:
            env.kick(wheels, impulse)
    except CLEAR:
        TRIED["env.refused"] += 1
    else:
        return  # accepted: nothing to compare with
    try:
        got = _step_all(env, acts[2:])
    except ResetNeeded:
        assert call == "reset"  # only a reset that failed late (an obstacle over the start) leaves this
        TRIED["env.failed_reset"] += 1
    else:
        assert np.array_equal(got, _step_all(ref, acts[2:]))
    env.reset(options={"track": SMALL_TRACK})
    ref.reset(options={"track": SMALL_TRACK})  # unseeded: the generator was not consumed by the refusal
    assert np.array_equal(_step_all(env, acts), _step_all(ref, acts))


test_single_env_refusal_changes_nothing, test_single_env_refusal_changes_nothing_slow = _profiles(
    _prop_single_env_refusal_changes_nothing, 40, 1500,
    seed0=st.integers(0, 1000), call=st.sampled_from(["reset", "reset", "step", "kick"]), seed=seeds,
    options=reset_options, action=st.one_of(junk, st.lists(st.floats(allow_nan=True), min_size=8, max_size=8)),
    wheels=st.one_of(st.lists(st.integers(-2, 6), max_size=5), junk), impulse=st.one_of(st.floats(-1, 1), junk))


# ---------------------------------------------------------------------- constructor keyword arguments

KWARGS = [p for p in inspect.signature(AzimutEnv.__init__).parameters if p not in ("self", "render_mode")]


def _prop_constructor_kwargs(name, value):
    TRIED["env.__init__"] += 1
    try:
        env = AzimutEnv(**{name: value})
    except CLEAR:
        TRIED["env.__init__.refused"] += 1
        return
    # accepted: the env must work (a bounded amount of work: skip absurd but legal step costs)
    cfg = env.config
    if cfg.substeps * cfg.solver_iterations > 2000:
        return
    env.reset(seed=0)
    obs, r, *_ = env.step(np.zeros(2 * env.n, np.float32))
    assert np.all(np.isfinite(obs)) and math.isfinite(r)


test_constructor_kwargs, test_constructor_kwargs_slow = _profiles(
    _prop_constructor_kwargs, 60, 2000, name=st.sampled_from(KWARGS),
    value=st.one_of(junk, st.floats(-1e3, 1e3), st.integers(-5, 50), st.sampled_from(TRACK_NAMES)))


# ---------------------------------------------------------------------- vector env


def _prop_vector_reset_refusal(seed, options, mask):
    TRIED["vector.reset"] += 1
    N = 3
    env, ref = AzimutVectorEnv(num_envs=N, track=SMALL_TRACK), AzimutVectorEnv(num_envs=N, track=SMALL_TRACK)
    acts = np.stack([_actions(env.n, 4)] * N, axis=1)
    env.reset(seed=7)
    ref.reset(seed=7)
    if mask is not None and isinstance(options, dict):
        options = {**options, "reset_mask": mask}
    try:
        env.reset(seed=seed, options=options)
    except CLEAR:
        TRIED["vector.refused"] += 1
    else:
        return
    # every option is checked before any sub-env moves (no option of the vector env fails late: its
    # obstacles are the constructor's), so no sub-env was reset and the episode goes on as before
    got = [env.step(a)[0] for a in acts]
    assert np.array_equal(np.array(got), np.array([ref.step(a)[0] for a in acts]))


per_sub_env = st.lists(st.one_of(st.none(), st.fixed_dictionaries({}, optional=option_values), junk),
                       min_size=0, max_size=4)
test_vector_reset_refusal, test_vector_reset_refusal_slow = _profiles(
    _prop_vector_reset_refusal, 30, 800, seed=st.one_of(seeds, st.lists(seeds, max_size=4)),
    options=st.one_of(reset_options, per_sub_env),
    mask=st.one_of(st.none(), junk, st.lists(st.booleans(), min_size=3, max_size=3).map(np.array)))


VECTOR_KWARGS = ["num_envs", "max_episode_steps", "autoreset_mode", "render_index", "track", "obstacles",
                 "substeps", "control_period", "lookahead_count", "sensors", "params"]


def _prop_vector_constructor_and_step(name, value, action):
    TRIED["vector.__init__"] += 1
    kwargs = {"num_envs": 2, "track": SMALL_TRACK}
    kwargs[name] = value
    try:
        env = AzimutVectorEnv(**kwargs)
    except CLEAR:
        TRIED["vector.__init__.refused"] += 1
        return
    if env.num_envs > 64 or env.config.substeps * env.config.solver_iterations > 2000:
        return
    env.reset(seed=3)
    ref = AzimutVectorEnv(**kwargs)
    ref.reset(seed=3)
    TRIED["vector.step"] += 1
    try:
        env.step(action)
    except CLEAR:
        TRIED["vector.step.refused"] += 1
    else:
        return
    good = np.zeros((env.num_envs, 2 * env.n), np.float32)
    a, b = env.step(good), ref.step(good)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])


test_vector_constructor_and_step, test_vector_constructor_and_step_slow = _profiles(
    _prop_vector_constructor_and_step, 30, 800, name=st.sampled_from(VECTOR_KWARGS),
    value=st.one_of(junk, st.integers(-3, 70), st.sampled_from(["next_step", "same_step", "disabled", "human"])),
    action=st.one_of(junk, st.lists(st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=8,
                                             max_size=8), min_size=1, max_size=3).map(np.array)))


def _prop_wrappers(kind, kwargs, action):
    from control.action_spaces.single import ICRTargetAction, TwistAction

    TRIED["wrapper"] += 1
    cls = ICRTargetAction if kind == "icr" else TwistAction
    try:
        env = cls(AzimutEnv(track=SMALL_TRACK), **kwargs)
        ref = cls(AzimutEnv(track=SMALL_TRACK), **kwargs)
    except CLEAR:
        TRIED["wrapper.refused"] += 1
        return
    env.reset(seed=2)
    ref.reset(seed=2)
    try:
        env.step(action)
    except CLEAR:
        TRIED["wrapper.refused"] += 1
    else:
        return
    good = np.zeros(env.action_space.shape, np.float32)
    good[-1] = 0.3
    assert np.array_equal(env.step(good)[0], ref.step(good)[0])


wrapper_kwargs = st.fixed_dictionaries({}, optional={
    "mu_max": st.one_of(st.floats(0.01, 3), junk), "min_norm": st.one_of(st.floats(0, 1), junk),
    "shape_targets": st.one_of(st.booleans(), junk), "target_rate": st.one_of(st.floats(0.1, 10), junk)})
test_wrappers, test_wrappers_slow = _profiles(
    _prop_wrappers, 20, 500, kind=st.sampled_from(["icr", "twist"]),
    kwargs=wrapper_kwargs.map(lambda d: d), action=st.one_of(junk, st.lists(st.floats(allow_nan=True), min_size=3,
                                                                              max_size=4).map(np.array)))


# ---------------------------------------------------------------------- parameter dataclasses


def _config_classes():
    """Every config dataclass of the libraries (frozen, every init field with a default), found by
    walking the packages: a new class or field is fuzzed without editing this file."""
    import dataclasses
    import pkgutil

    import azimut_env
    import control
    import estimation

    classes = []
    for pkg in (estimation, azimut_env, control):
        for info in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + "."):
            module = importlib.import_module(info.name)
            for obj in vars(module).values():
                if inspect.isclass(obj) and dataclasses.is_dataclass(obj) and obj.__module__ == module.__name__ \
                        and obj.__dataclass_params__.frozen \
                        and all(f.default is not dataclasses.MISSING or f.default_factory is not dataclasses.MISSING
                                for f in dataclasses.fields(obj) if f.init):
                    classes.append(obj)
    return [(c, f.name, str(f.type)) for c in classes for f in dataclasses.fields(c) if f.init]


CONFIG_FIELDS = _config_classes()
#: what a field of each annotation must hold once accepted (the canonical Python type, never a
#: bool for a number, a NumPy scalar or a 0-d array)
STORED = {"float": (float,), "int": (int,), "bool": (bool,), "str": (str,)}
numbers_at_entry = st.one_of(
    st.just(10**400), st.just(-10**400), st.just(2**63), st.just(True), st.just(np.True_), st.just(np.False_),
    st.sampled_from([np.array(0.3), np.array(2), np.array(True), np.array(1 + 1j), np.array("1"), np.array([0.5])]),
    st.sampled_from([np.float32(0.5), np.float16(2), np.int8(3), np.uint64(2**63), np.complex128(1),
                     np.longdouble(0.25), "0.5", b"1", 1j]),
    st.floats(allow_nan=True, allow_infinity=True), st.integers(-5, 5))


def _prop_config_fields(cls_field, value):
    cls, name, annotation = cls_field
    TRIED["config"] += 1
    try:
        obj = cls(**{name: value})
    except (ValueError, TypeError) as exc:
        TRIED["config.refused"] += 1
        if annotation in STORED or annotation.endswith("| None"):  # a plain field's error names it
            assert name in str(exc), (cls.__name__, name, value, str(exc))
        return
    got = getattr(obj, name)
    if isinstance(value, float) and not math.isfinite(value):  # NaN or inf kept: a defect unless inf means "none"
        assert isinstance(got, float) and math.isinf(got) and math.isinf(value), (cls.__name__, name, value)
    kinds = [k.strip() for k in annotation.split("|")]
    if got is None and "None" in kinds:
        return
    want = [STORED[k] for k in kinds if k in STORED]
    if want:  # stored as the canonical type of its annotation, exactly (no subclass: bool is an int)
        assert any(type(got) in w for w in want), (cls.__name__, name, value, type(got))


test_config_fields, test_config_fields_slow = _profiles(
    _prop_config_fields, 200, 5000, cls_field=st.sampled_from(CONFIG_FIELDS),
    value=st.one_of(junk, numbers_at_entry, st.floats(-1e3, 1e3), st.integers(-5, 5), st.just(float("nan"))))


# ---------------------------------------------------------------------- estimators

arrays = st.one_of(
    st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=0, max_size=9).map(np.array),
    st.lists(st.lists(st.floats(-20, 20), min_size=4, max_size=4), min_size=1, max_size=5).map(np.array),
    st.lists(st.complex_numbers(max_magnitude=3), min_size=4, max_size=4).map(np.array),
    st.lists(st.integers(-3, 3), min_size=4, max_size=4).map(np.array),
    st.lists(st.text(max_size=2), min_size=4, max_size=4).map(np.array), junk)


def _prop_estimators(q, phidot, method, mu_tol):
    TRIED["estimation"] += 1
    try:
        lam = estimate_icr(q, GEOM, method)
    except (ValueError, TypeError):
        TRIED["estimation.refused"] += 1
    else:
        assert np.all(np.isfinite(lam)) and np.allclose(np.linalg.norm(lam, axis=-1), 1.0)
    try:
        lam, mu, beta, qua = estimate_eta(q, phidot, GEOM, method, mu_tol=mu_tol)
    except (ValueError, TypeError):
        TRIED["estimation.refused"] += 1
    else:
        assert np.all(np.isfinite(mu)) and np.all((qua >= 0) & (qua <= 1))
    try:
        v = quality(q, phidot)
    except (ValueError, TypeError):
        TRIED["estimation.refused"] += 1
    else:
        assert np.all((v >= 0) & (v <= 1))


test_estimators, test_estimators_slow = _profiles(
    _prop_estimators, 150, 5000, q=arrays, phidot=arrays,
    method=st.one_of(st.sampled_from([m for m in METHODS if m != "ORACLE"]), junk),
    mu_tol=st.one_of(st.floats(0, 1), junk))


# ---------------------------------------------------------------------- the command line

def _flags() -> dict[str, list[str]]:
    """Every subcommand's option strings, read from its own parser (new subcommands and flags are
    fuzzed without editing this file)."""
    from jobs.cli import CommandParser

    out = {}
    for name, (module_name, _) in _available().items():
        parser = CommandParser(prog=f"azimut {name}")
        importlib.import_module(module_name).add_arguments(parser)
        out[name] = sorted(o for act in parser._actions for o in act.option_strings if o.startswith("--")
                           and o != "--help")
    return out


FLAGS = _flags()
cli_values = st.one_of(
    st.integers(-5, 10**7).map(str), st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.sampled_from(["icr", "twist", "icr,twist", "paper", "circle,nope", "NE", "NE,LS", "IT,NE", "auto", "recorded",
                     "", "1,16", "0", "-1", "x", "Pendulum-v1", "Nope-v0", "{tmp}/out", "{file}", "{file}/x",
                     "/proc/x", "{tmp}", "{tmp}/missing/x.json"]),
    st.text(max_size=8))


def _prop_cli(command, flags, tmp_path_factory, capsys_holder):
    tmp = tmp_path_factory.mktemp("cli")
    cwd = tmp / "cwd"  # relative output paths land here, not in the checkout
    cwd.mkdir()
    existing = tmp / "existing.txt"
    existing.write_text("x")
    TRIED["cli"] += 1
    argv = [command] + [a.replace("{tmp}", str(tmp)).replace("{file}", str(existing))
                        for pair in flags for a in pair if a is not None]
    module = importlib.import_module(_available()[command][0]) if command in _available() else None
    if module is None:
        return
    ran = []
    real_run = module.run
    module.run = lambda args: ran.append(args) or 0  # the work itself is not fuzzed, only its entry
    before = os.getcwd()
    os.chdir(cwd)
    try:
        code = main(argv)
    except SystemExit as exc:  # main returns codes; a SystemExit escaping it is a defect too
        raise AssertionError(f"SystemExit({exc.code}) escaped main for {shlex.join(argv)}") from None
    finally:
        module.run = real_run
        os.chdir(before)
    err = capsys_holder.readouterr().err
    assert code in (0, 2), (argv, code)
    if code == 2:
        TRIED["cli.refused"] += 1
        assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, (argv, err)
        assert not ran
    else:
        assert ran or "--help" in argv
    assert existing.read_text() == "x"  # nothing written before the work
    assert not any(cwd.iterdir()), (argv, sorted(p.name for p in cwd.iterdir()))  # checks create nothing


def _cli_test(max_examples):
    cmd_flags = st.sampled_from(sorted(FLAGS)).flatmap(
        lambda c: st.tuples(st.just(c), st.lists(st.tuples(st.sampled_from(FLAGS[c] + ["--bogus"]),
                                                           st.one_of(st.none(), cli_values)), max_size=4)))

    @settings(max_examples=max_examples, deadline=None, suppress_health_check=list(HealthCheck))
    @given(cf=cmd_flags)
    def test(cf, tmp_path_factory, capsys):
        _prop_cli(cf[0], cf[1], tmp_path_factory, capsys)

    return test


test_cli_arguments = _cli_test(150)
test_cli_arguments_slow = pytest.mark.slow(_cli_test(4000))


@pytest.fixture(scope="module", autouse=True)
def _print_counts():
    """After the module: print how many inputs each entry point got (``pytest -s`` shows it)."""
    yield
    if TRIED:
        print("\nfuzz inputs tried:", dict(sorted(TRIED.items())))
