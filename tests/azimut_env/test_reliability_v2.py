"""Issue 20 (reliability v2), the envs: each example of the issue as a test. A refused ``reset``
option changes no state, in the single and the vector env; the vector env pickles and deep-copies
at any time and the copy goes on bit for bit."""

from __future__ import annotations

import copy
import pickle

import numpy as np
import pytest

from azimut_env.env import AzimutEnv
from azimut_env.tracks import Track
from azimut_env.vector_env import AzimutVectorEnv

ACTIONS = np.random.default_rng(4).uniform(-1, 1, (12, 8)).astype(np.float32)


def _single_steps(env, actions):
    return np.array([np.append(env.step(a)[0], env.task.reward[0]) for a in actions])


@pytest.mark.parametrize("step", [2**63, 2**64, 10**400])
def test_kick_step_beyond_int64_refused_before_the_reset_single_env(step):
    """``reset(options={"kick": {"step": 2**63}})`` raised OverflowError in the middle of the reset
    and left the env needing a reset."""
    env, ref = AzimutEnv(), AzimutEnv()
    env.reset(seed=5)
    ref.reset(seed=5)
    _single_steps(env, ACTIONS[:3])
    _single_steps(ref, ACTIONS[:3])
    with pytest.raises(ValueError, match=r"options\['kick'\]\['step'\] must be <= 9223372036854775807"):
        env.reset(options={"kick": {"step": step}})
    assert np.array_equal(_single_steps(env, ACTIONS[3:]), _single_steps(ref, ACTIONS[3:]))
    env.reset(options={"kick": {"step": 2**63 - 1}})  # the largest storable step is a valid (never reached) kick


@pytest.mark.parametrize("options", [{"kick": {"step": 2**63}},
                                     [{}, {}, {"kick": {"step": 2**63}}]])
def test_kick_step_beyond_int64_refused_before_any_sub_env_resets(options):
    """On the vector env sub-env 0 was already reset when the error came."""
    env, ref = AzimutVectorEnv(num_envs=3), AzimutVectorEnv(num_envs=3)
    acts = np.stack([ACTIONS] * 3, axis=1)
    env.reset(seed=2)
    ref.reset(seed=2)
    for a in acts[:3]:
        env.step(a)
        ref.step(a)
    with pytest.raises(ValueError, match="kick"):
        env.reset(options=options)
    for a in acts[3:]:
        got, want = env.step(a), ref.step(a)
        assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])


def _vector_steps(env, actions):
    out = []
    for a in actions:
        obs, r, term, trunc, _ = env.step(a)
        out.append(np.concatenate([obs.ravel(), r, term, trunc]))
    return np.array(out)


@pytest.mark.parametrize("how", ["pickle", "deepcopy"])
@pytest.mark.parametrize("when", ["built", "reset", "stepped", "autoreset", "refused_step"])
def test_vector_env_copies_at_any_time_go_on_bit_for_bit(how, when):
    """An ``AzimutVectorEnv`` could not be pickled or deep-copied after its first step (numba
    typed list)."""
    env = AzimutVectorEnv(num_envs=3, max_episode_steps=4)
    acts = np.stack([ACTIONS] * 3, axis=1)
    if when != "built":
        env.reset(seed=11)
    if when in ("stepped", "autoreset", "refused_step"):
        _vector_steps(env, acts[:4 if when == "autoreset" else 2])  # 4: every sub-env truncated, autoreset next
    if when == "refused_step":
        with pytest.raises(ValueError):
            env.step(np.full((3, 8), np.nan, np.float32))
    twin = pickle.loads(pickle.dumps(env)) if how == "pickle" else copy.deepcopy(env)
    if when == "built":
        env.reset(seed=11)
        twin.reset(seed=11)
    assert np.array_equal(_vector_steps(twin, acts[4:]), _vector_steps(env, acts[4:]))
    assert twin.np_random[0] is not env.np_random[0]  # its own generators, not shared with the original


# ---------------------------------------------------------------------- concave obstacles

#: a U-shaped obstacle open toward −x: a 2 m deep, 1 m wide notch from x = 1 to x = 3
U_NOTCH = [(1.0, -0.8), (3.3, -0.8), (3.3, 0.8), (1.0, 0.8), (1.0, 0.5), (3.0, 0.5), (3.0, -0.5), (1.0, -0.5)]


def _drive_forward(obstacles, steps=500):
    """The robot from the origin straight along +x at 0.4 m/s (wheels set for that translation)."""
    from azimut_env.physics.engine import AzimutPhysics
    from estimation.hrep import eta_from_twist
    from estimation.kinematics import steering_from_lambda, wheel_speed_coefficients

    phys = AzimutPhysics()
    g = phys.params.geometry
    lam, mu = eta_from_twist(np.array([0.4, 0.0, 0.0]))
    beta = steering_from_lambda(lam, g)
    phys.set_obstacles(obstacles)
    phys.reset_robot(0, (0.0, 0.0, 0.0), beta)
    phys.set_commands(beta[None], (mu * wheel_speed_coefficients(lam, g, beta) / g.r)[None])
    for _ in range(steps):
        phys.step()
    return phys.chassis_pose()[0]


@pytest.mark.parametrize("winding", [1, -1])
def test_robot_drives_into_a_concave_notch_as_far_as_the_geometry_allows(winding):
    """A concave polygon obstacle was replaced by its convex hull: the robot stopped at 0.70 m
    instead of driving 2 m into the U-shaped notch (its front stops at the notch's end, x = 3)."""
    x, y, theta = _drive_forward([U_NOTCH[::winding]])
    half_length = 0.3  # ChassisParams().length / 2
    assert 3.0 - half_length - 0.02 < x <= 3.0 - half_length + 1e-3, x
    assert abs(y) < 1e-3 and abs(theta) < 1e-3


def test_concave_obstacle_parts_cover_the_polygon_and_start_inside_the_notch():
    from azimut_env.physics.obstacles import Obstacle

    ob = Obstacle(vertices=U_NOTCH)
    assert len(ob.parts) >= 3 and ob.vertices == tuple(U_NOTCH)
    # a robot started inside the notch overlaps no obstacle (the hull covered the whole notch)
    track = Track.from_waypoints([[1.8, 0.0], [4.0, 0.0]], speed=0.3)
    env = AzimutEnv(track=track, obstacles=[U_NOTCH])
    env.reset(seed=0)
    assert env.physics.overlapping_obstacles(0) == []
    env.reset(seed=0, options={"obstacles": [U_NOTCH, (9.0, 9.0, 0.2)]})


@pytest.mark.parametrize("vertices, match", [
    ([(0, 0), (2, 2), (2, 0), (0, 2)], "intersect"),  # a bow tie
    ([(0, 0), (1, 0), (2, 0)], "zero area"),
    ([(0, 0), (1, 0), (1, 0), (0, 1)], "repeats a vertex|intersect"),
    ([(0, 0), (1e300, 0), (0, 1)], "within"),
    ([(0, 0), (10**400, 0), (0, 1)], "vertices"),
])
def test_polygons_that_are_not_simple_are_refused(vertices, match):
    from azimut_env.physics.obstacles import Obstacle

    with pytest.raises((ValueError, TypeError), match=match):
        Obstacle(vertices=vertices)
    env = AzimutEnv()
    env.reset(seed=1)
    with pytest.raises(ValueError, match="obstacles"):
        env.reset(options={"obstacles": [vertices]})


#: simple polygons on which pymunk's convex decomposition (Chipmunk, C) crashed the process
CRASHED_PYMUNK = [
    [(-0.28891080050347995, 3), (-1, 2.0), (-0.6702968446597817, 2.0), (-2, -2.861487582129209),
     (-1.2456805406537976, 3.0), (-1, 2.3925741437791155)],
    [(2.5272828658178117, -0.6577404539074374), (0, 1.0681781928406346), (1.540886530541604, 1e-10),
     (-5e-324, -0.29913870336074755), (-5e-324, 2.0), (3, 1.924981365932668)],
    [(0.0, -2.6903782705055166), (0.0, -3.0), (1e-300, 5e-324), (2, -3), (2.0309769145280994, 1.0756497583284554),
     (-1, 2), (-1, 1.4239151422302774), (-0.0, 2.2250738585072014e-308)],
]


def test_polygons_that_crashed_the_convex_decomposition_split_or_are_refused():
    """Each is split into convex counter-clockwise parts covering its area, or refused with a
    ValueError, in a child process (a regression would be a segmentation fault, not a failure)."""
    import json
    import subprocess
    import sys

    code = (
        "import json, sys, numpy as np\n"
        "from azimut_env.physics.polygons import convex_parts, signed_area\n"
        "for poly in json.loads(sys.argv[1]):\n"
        "    try:\n"
        "        parts = convex_parts(poly)\n"
        "    except ValueError as exc:\n"
        "        print('refused', exc); continue\n"
        "    area = abs(signed_area(np.array(poly, dtype=float)))\n"
        "    assert all(signed_area(np.array(p)) > 0 for p in parts)\n"
        "    assert abs(sum(signed_area(np.array(p)) for p in parts) - area) <= 1e-9 * area\n"
        "    print('split', len(parts))\n")
    out = subprocess.run([sys.executable, "-c", code, json.dumps(CRASHED_PYMUNK)], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert len(out.stdout.splitlines()) == len(CRASHED_PYMUNK)
    assert out.stdout.count("split") >= 1


@pytest.mark.parametrize("value, ok", [(8.98846567431158e307, False), (10.5, False), (-1.0, False), (-0.0, True),
                                       (10.0, True)])
def test_start_noise_is_refused_beyond_its_range_and_minus_zero_starts(value, ok):
    """The start noise drew from ±start_noise: 9e307 overflowed numpy's range (OverflowError at
    reset) and -0.0 was an empty range (ValueError at reset); both found by the fuzz tests."""
    if not ok:
        with pytest.raises(ValueError, match="start_noise"):
            AzimutEnv(start_noise=value)
        return
    env = AzimutEnv(start_noise=value)
    env.reset(seed=0)
    assert env.config.start_noise == abs(value)
