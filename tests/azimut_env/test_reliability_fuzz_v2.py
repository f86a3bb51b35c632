"""Property-based tests (hypothesis) of issue 20, one per class of the issue that the fuzz tests of
issue 10 (``test_reliability_fuzz.py``) did not reach: copies of the vector env at any time,
λ at any scale, obstacles of any shape. The numbers-at-entry class is fuzzed there (every config
dataclass field, found by walking the packages), as are the reset options at int64/float64 edges.

The default run keeps ``max_examples`` small; ``-m slow`` runs the same properties longer.
"""

from __future__ import annotations

import copy
import pickle

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from azimut_env.vector_env import AzimutVectorEnv


def _profiles(fn, default: int, slow: int, **given_kwargs):
    """The same property as a default test (``default`` examples) and a slow one."""
    quick = settings(max_examples=default, deadline=None, suppress_health_check=list(HealthCheck))(
        given(**given_kwargs)(fn))
    long = pytest.mark.slow(settings(max_examples=slow, deadline=None, suppress_health_check=list(HealthCheck))(
        given(**given_kwargs)(fn)))
    return quick, long


# ---------------------------------------------------------------------- lifecycle: copies at any time

OPS = st.lists(st.sampled_from(["step", "step", "step", "reset", "reset_some", "bad_step", "bad_reset", "copy"]),
               min_size=1, max_size=12)


def _apply(env, op, t):
    rng = np.random.default_rng(t)
    if op == "step":
        env.step(rng.uniform(-1, 1, (env.num_envs, 8)).astype(np.float32))
    elif op == "reset":
        env.reset(seed=t)
    elif op == "reset_some":
        env.reset(options={"reset_mask": np.arange(env.num_envs) == t % env.num_envs})
    elif op == "bad_step":
        try:
            env.step(np.full((env.num_envs, 8), np.inf, np.float32))
        except (ValueError, RuntimeError):
            pass
    elif op == "bad_reset":
        try:
            env.reset(options={"kick": {"step": 2**63}})
        except ValueError:
            pass


def _prop_vector_copy_any_time(ops, how):
    env = AzimutVectorEnv(num_envs=2, max_episode_steps=3)
    env.reset(seed=1)
    twin = None
    for t, op in enumerate(ops):
        if op == "copy":
            twin = pickle.loads(pickle.dumps(env)) if how == "pickle" else copy.deepcopy(env)
            continue
        try:
            _apply(env, op, t)
        except Exception as exc:  # noqa: BLE001 (an op refused in this state is applied to the twin too)
            if twin is not None:
                with pytest.raises(type(exc)):
                    _apply(twin, op, t)
            continue
        if twin is not None:
            _apply(twin, op, t)
            assert np.array_equal(twin.task.obs, env.task.obs) and np.array_equal(twin.task.reward, env.task.reward)
            assert np.array_equal(twin.physics.summary, env.physics.summary)


test_vector_copy_any_time, test_vector_copy_any_time_slow = _profiles(
    _prop_vector_copy_any_time, 15, 300, ops=OPS, how=st.sampled_from(["pickle", "deepcopy"]))


# ---------------------------------------------------------------------- λ at any scale


def _prop_lambda_any_scale(lam, k):
    from estimation import RobotGeometry
    from estimation.kinematics import steering_from_lambda

    lam = np.array(lam)
    if not np.any(lam):
        return
    scaled = np.ldexp(lam, k)
    if not np.array_equal(np.ldexp(scaled, -k), lam):  # the scaling itself rounded (subnormal): not exact
        return
    geom = RobotGeometry.azimut3()
    assert np.array_equal(steering_from_lambda(scaled, geom), steering_from_lambda(lam, geom))


test_lambda_any_scale, test_lambda_any_scale_slow = _profiles(
    _prop_lambda_any_scale, 200, 5000, lam=st.lists(st.floats(-1e3, 1e3), min_size=3, max_size=3),
    k=st.integers(-1070, 1010))


# ---------------------------------------------------------------------- obstacles of any shape


def _inside(poly: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Even-odd rule: which of ``pts`` (m, 2) are inside the closed polygon ``poly`` (k, 2)."""
    x, y = pts[:, 0:1], pts[:, 1:2]
    a, b = poly, np.roll(poly, -1, axis=0)
    crosses = (a[:, 1] > y) != (b[:, 1] > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        xs = a[:, 0] + (y - a[:, 1]) * (b[:, 0] - a[:, 0]) / (b[:, 1] - a[:, 1])
    return (np.sum(crosses & (x < xs), axis=1) % 2) == 1


def _prop_polygon_obstacles(radii, angles, jitter, winding):
    """A star-shaped polygon (simple by construction, concave for most radii): its convex parts
    are convex, cover it exactly (area, and every sampled point is in a part iff it is in the
    polygon, away from the boundary). Arbitrary vertex lists: refused with ValueError/TypeError, or
    decomposed likewise."""
    from azimut_env.physics.obstacles import Obstacle
    from azimut_env.physics.polygons import signed_area as _signed_area

    k = len(radii)
    theta = np.sort(np.array(angles[:k]) + np.arange(k)) * (2 * np.pi / k)
    poly = np.stack([np.array(radii) * np.cos(theta), np.array(radii) * np.sin(theta)], axis=1)[::winding]
    if jitter:
        poly = poly + np.array(jitter[:2]) * 3.0
    try:
        ob = Obstacle(vertices=[tuple(p) for p in poly])
    except (ValueError, TypeError):  # a sliver: zero area, or vertices too close to tell apart
        return
    parts = [np.array(p) for p in ob.parts]
    for part in parts:
        assert _signed_area(part) > 0  # counter-clockwise and convex
        d = np.roll(part, -1, axis=0) - part
        assert np.all(d[:, 0] * np.roll(d, -1, axis=0)[:, 1] - d[:, 1] * np.roll(d, -1, axis=0)[:, 0] > -1e-9)
    assert np.isclose(sum(_signed_area(p) for p in parts), abs(_signed_area(poly)), rtol=1e-9)
    pts = np.random.default_rng(k).uniform(poly.min(axis=0), poly.max(axis=0), (400, 2))
    in_poly = _inside(poly, pts)
    in_parts = np.any([_inside(p, pts) for p in parts], axis=0)
    a, ab = poly[None], (np.roll(poly, -1, axis=0) - poly)[None]  # edges a → a + ab
    t = np.clip(np.sum((pts[:, None] - a) * ab, axis=2) / np.sum(ab * ab, axis=2), 0.0, 1.0)
    edge = np.min(np.linalg.norm(pts[:, None] - (a + t[..., None] * ab), axis=2), axis=1)
    far = edge > 1e-6  # points on the boundary may go either way
    assert np.array_equal(in_poly[far], in_parts[far])


test_polygon_obstacles, test_polygon_obstacles_slow = _profiles(
    _prop_polygon_obstacles, 60, 2000, radii=st.lists(st.floats(0.05, 3.0), min_size=3, max_size=12),
    angles=st.lists(st.floats(0.0, 0.95), min_size=12, max_size=12),
    jitter=st.one_of(st.just([]), st.lists(st.floats(-1, 1), min_size=2, max_size=2)), winding=st.sampled_from([1, -1]))


def _prop_any_vertex_list(vertices):
    from azimut_env.physics.obstacles import Obstacle
    from azimut_env.physics.polygons import signed_area as _signed_area

    try:
        ob = Obstacle(vertices=vertices)
    except (ValueError, TypeError):
        return
    area = abs(_signed_area(np.array(ob.vertices)))
    assert np.isclose(sum(_signed_area(np.array(p)) for p in ob.parts), area, rtol=1e-9)


test_any_vertex_list, test_any_vertex_list_slow = _profiles(
    _prop_any_vertex_list, 100, 3000,
    vertices=st.lists(st.tuples(st.one_of(st.floats(-3, 3), st.integers(-3, 3)),
                                st.one_of(st.floats(-3, 3), st.integers(-3, 3))), min_size=0, max_size=9))


# ---------------------------------------------------------------------- numbers at other entry points

edge = st.one_of(
    st.sampled_from([10**400, -10**400, 2**63, True, np.True_, np.array(0.3), np.array(2), np.array(True), 1j,
                     "0.3", None, np.float32(0.3), np.int64(2), [0.3, 0.4]]),
    st.floats(allow_nan=True, allow_infinity=True), st.integers(-3, 3))


def _prop_track_kwargs(name, value):
    """Every keyword of ``Track.from_waypoints`` (read from its signature): refused with a clear
    error naming it, or a track of finite numbers."""
    import inspect

    from azimut_env.tracks import Track

    assert name in inspect.signature(Track.from_waypoints).parameters
    try:
        track = Track.from_waypoints([[0.0, 0.0], [2.0, 0.0], [2.0, 1.0]], **{name: value})
    except (ValueError, TypeError) as exc:
        assert name in str(exc) or "waypoints" in str(exc), (name, value, str(exc))
        return
    assert np.all(np.isfinite(track.xy)) and np.all(np.isfinite(track.speed)) and track.length > 0


def _track_kwargs():
    import inspect

    from azimut_env.tracks import Track

    return [p for p in inspect.signature(Track.from_waypoints).parameters if p != "waypoints"]


test_track_kwargs, test_track_kwargs_slow = _profiles(
    _prop_track_kwargs, 60, 2000, name=st.sampled_from(_track_kwargs()), value=edge)


def _prop_reward_weights(weights):
    from azimut_env.task.config import TaskConfig

    try:
        cfg = TaskConfig(reward_weights=weights)
    except (ValueError, TypeError) as exc:
        assert "reward_weights" in str(exc)
        return
    assert all(type(w) is float and np.isfinite(w) and w >= 0 for w in cfg.reward_weights.values())


def _reward_terms():
    from azimut_env.task.reward import reward_term_names

    return list(reward_term_names())


test_reward_weights, test_reward_weights_slow = _profiles(
    _prop_reward_weights, 60, 2000,
    weights=st.dictionaries(st.one_of(st.sampled_from(_reward_terms()), st.text(max_size=4)), edge, max_size=3))


# ---------------------------------------------------------------------- files the command line reads and writes

json_values = st.recursive(
    st.one_of(st.none(), st.booleans(), st.integers(-10, 10), st.floats(allow_nan=True), st.text(max_size=5)),
    lambda children: st.one_of(st.lists(children, max_size=4), st.dictionaries(st.text(max_size=8), children,
                                                                                   max_size=4)), max_leaves=12)


def _prop_record_files(tmp_path_factory, content, mutate):
    """Whatever a record file holds (any JSON, a valid record with one field replaced by any JSON,
    torn bytes, a directory), reading it back gives a valid record or None (recompute, listed as
    rejected), never an exception."""
    import json

    from jobs.campaign.store import TaskStore, record_problem
    from jobs.campaign.task import Task

    task = Task("jobs.eval.campaign:episode_task", {"controller": "icr", "track": "paper", "seed": 0},
                check="jobs.eval.campaign:check_episode_result")
    store = TaskStore(tmp_path_factory.mktemp("records"))
    path = store.path(task)
    from jobs.eval.report import SUMMARY_COLUMNS

    # every metric the report reads back (the schema check's own list), a number each
    metrics = {name: 0.5 for name, *_ in SUMMARY_COLUMNS if name != "completed"}
    metrics.update(completed=True, controller="icr", track="paper", seed=0)
    good = {"id": task.id, "fn": task.fn, "key": dict(task.key), "status": "ok", "attempts": 1,
            "result": {"metrics": metrics}}
    assert record_problem(good, task) is None
    if mutate in ("status", "attempts", "result", "key"):
        path.write_text(json.dumps({**good, mutate: content}, allow_nan=True))
    elif mutate in ("rms_lateral_m", "completed", "seed", "controller"):
        path.write_text(json.dumps({**good, "result": {"metrics": {**metrics, mutate: content}}}, allow_nan=True))
    elif mutate == "whole":
        path.write_text(json.dumps(content, allow_nan=True))
    elif mutate == "torn":
        path.write_text(json.dumps(good)[: len(json.dumps(content)) % 200])
    else:
        path.mkdir()
    got = store.load(task)
    if got is None:
        assert [p for p, _ in store.rejected] == [path]
    else:
        assert record_problem(got, task) is None and not store.rejected


def _record_test(max_examples):
    @settings(max_examples=max_examples, deadline=None, suppress_health_check=list(HealthCheck))
    @given(content=json_values, mutate=st.sampled_from(["status", "attempts", "result", "key", "rms_lateral_m",
                                                        "completed", "seed", "controller", "whole", "torn", "dir"]))
    def test(tmp_path_factory, content, mutate):
        _prop_record_files(tmp_path_factory, content, mutate)

    return test


test_record_files = _record_test(80)
test_record_files_slow = pytest.mark.slow(_record_test(2000))


def _prop_output_layout(tmp_path_factory, kinds, flags):
    """Any mix of files and folders where ``azimut eval`` writes (every path of its layout, made
    a file or a folder at random): the check refuses it (one line naming a path) or every path
    that exists is of the kind written there."""
    import argparse
    import os

    from jobs.args import check_output_layout
    from jobs.eval.outputs import output_layout

    args = argparse.Namespace(no_plots=not flags[0], video="gif" if flags[1] else None, kick_runs=flags[2],
                              controllers=["icr", "twist"], export="mcap" if flags[3] else None, tracks=["paper"])
    files, dirs = output_layout(args, [0])
    out = tmp_path_factory.mktemp("out")
    paths = sorted(set(files) | set(dirs))
    for rel, kind in zip(paths, kinds):
        p = out / rel
        if kind == "absent" or any(q.exists() and not q.is_dir() for q in p.parents if out in q.parents):
            continue
        p.parent.mkdir(parents=True, exist_ok=True)
        if kind == "file" and not p.exists():
            p.write_text("x")
        elif kind == "dir" and not p.exists():
            p.mkdir()
    try:
        check_output_layout(out, files, dirs)
    except ValueError as exc:
        assert len(str(exc).splitlines()) == 1 and str(out) in str(exc)
        return
    for rel in files:
        assert not os.path.isdir(out / rel)
    for rel in dirs:
        assert not (out / rel).exists() or (out / rel).is_dir()


def _layout_test(max_examples):
    @settings(max_examples=max_examples, deadline=None, suppress_health_check=list(HealthCheck))
    @given(kinds=st.lists(st.sampled_from(["absent", "absent", "file", "dir"]), min_size=20, max_size=20),
           flags=st.tuples(st.booleans(), st.booleans(), st.integers(0, 2), st.booleans()))
    def test(tmp_path_factory, kinds, flags):
        _prop_output_layout(tmp_path_factory, kinds, flags)

    return test


test_output_layout = _layout_test(60)
test_output_layout_slow = pytest.mark.slow(_layout_test(2000))


def _prop_strict_json(tmp_path_factory, value):
    """What the reports write (``jobs.records.write_json``: metrics.json, seeds.json) is strict JSON
    whatever it holds: NaN and ±inf as null, NumPy values as numbers (a strict parser refused bare
    NaN)."""
    import json

    from jobs.records import write_json

    def refuse(token):
        raise ValueError(f"not strict JSON: {token}")

    path = tmp_path_factory.mktemp("json") / "metrics.json"
    write_json(path, value)
    json.loads(path.read_text(), parse_constant=refuse)


def _strict_json_test(max_examples):
    leaves = st.one_of(st.none(), st.booleans(), st.integers(-10, 10), st.floats(allow_nan=True, allow_infinity=True),
                       st.text(max_size=4), st.sampled_from([np.float64("nan"), np.float32("inf"), np.int64(3),
                                                             np.array([1.0, np.nan]), np.bool_(True)]))
    values = st.recursive(leaves, lambda c: st.one_of(st.lists(c, max_size=4), st.dictionaries(st.text(max_size=4), c,
                                                                                                 max_size=4)),
                          max_leaves=12)

    @settings(max_examples=max_examples, deadline=None, suppress_health_check=list(HealthCheck))
    @given(value=values)
    def test(tmp_path_factory, value):
        _prop_strict_json(tmp_path_factory, value)

    return test


test_strict_json = _strict_json_test(80)
test_strict_json_slow = pytest.mark.slow(_strict_json_test(3000))
