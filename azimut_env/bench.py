"""``azimut bench-env``: single-env throughput (steps/s) of Azimut-v0 with a time breakdown.

The breakdown times each stage of ``AzimutEnv.step`` inside the end-to-end loop (physics: the
pymunk substeps and the compiled actuator/tire kernel; estimation: IT, μ̂ and qua; observation:
sensors, track query, observation vector, reward, info). The end-to-end
figure is the plain ``env.step`` loop with small uniformly random actions (resets excluded), also
given for the fastest of five chunks since the machine may be shared; "other" is what the
end-to-end time has beyond the stages (action checks, Python glue, cache effects).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

__all__ = ["bench_env", "add_arguments", "run"]


def _time(fn, repeat: int) -> float:
    t0 = time.perf_counter()
    for _ in range(repeat):
        fn()
    return (time.perf_counter() - t0) / repeat


def bench_env(steps: int = 5000, track: str = "paper", seed: int = 0, substeps: int = 8) -> dict[str, float]:
    """Measure steps/s and per-stage microseconds per step. Returns a dict of figures.

    The stages are timed inside the end-to-end loop itself (thin timing wrappers on the env's
    stage methods), so the breakdown adds up to the measured total on a shared machine too."""
    from . import env as env_module
    from .env import AzimutEnv

    env = AzimutEnv(track=track, substeps=substeps)
    env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    actions = rng.uniform(-1, 1, size=(steps, env.action_space.shape[0])).astype(np.float32) * 0.2
    # warm-up (numba kernels load from cache or compile)
    for i in range(50):
        env.step(actions[i])
    acc = {"physics": 0.0, "estimation": 0.0, "sensors": 0.0, "track": 0.0, "observation": 0.0}
    clock = time.perf_counter

    def timed(fn, key):
        def wrapper(*args, **kwargs):
            t = clock()
            out = fn(*args, **kwargs)
            acc[key] += clock() - t
            return out
        return wrapper

    h_state = env_module.h_state_from_measurements
    env.physics.step = timed(env.physics.step, "physics")
    env._measure = timed(env._measure, "sensors")  # includes estimation, subtracted below
    env._track_state = timed(env._track_state, "track")
    env._get_obs = timed(env._get_obs, "observation")
    env._get_rew = timed(env._get_rew, "observation")
    env._get_info = timed(env._get_info, "observation")
    env_module.h_state_from_measurements = timed(h_state, "estimation")
    try:
        env.reset(seed=seed)
        for key in acc:
            acc[key] = 0.0
        done, resets, elapsed = 0, 0, 0.0
        chunk_rates = []
        chunk = max(1, steps // 5)
        while done < steps:
            t0 = clock()
            n_chunk = 0
            for _ in range(chunk):
                _, _, term, trunc, _ = env.step(actions[done % steps])
                done += 1
                n_chunk += 1
                if term or trunc:
                    break
            dt = clock() - t0
            elapsed += dt
            chunk_rates.append(n_chunk / dt)
            if term or trunc:  # resets are not timed, in the total or in the stages
                saved = dict(acc)
                env.reset()
                acc.update(saved)
                resets += 1
    finally:
        env_module.h_state_from_measurements = h_state
    total = elapsed / done
    per = {key: value / done for key, value in acc.items()}
    per["sensors"] = max(0.0, per["sensors"] - per["estimation"])
    staged = sum(per.values())
    return {
        "steps_per_s": 1.0 / total,
        "us_per_step": total * 1e6,
        "physics_us": per["physics"] * 1e6,
        "estimation_us": per["estimation"] * 1e6,
        "observation_us": (per["sensors"] + per["track"] + per["observation"]) * 1e6,
        "sensors_us": per["sensors"] * 1e6,
        "track_us": per["track"] * 1e6,
        "obs_reward_info_us": per["observation"] * 1e6,
        "other_us": max(0.0, total - staged) * 1e6,
        "substeps": float(substeps),
        "steps": float(done),
        "resets": float(resets),
        "best_chunk_steps_per_s": max(chunk_rates),
    }


def reference_steps_per_s(env_id: str = "Pendulum-v1", steps: int = 5000, seed: int = 0) -> float:
    """Steps/s of a Gymnasium reference env measured in the same run (a yardstick for the
    machine's speed at that moment: compare ratios, not absolute figures, on a shared machine)."""
    import gymnasium as gym

    env = gym.make(env_id).unwrapped
    env.reset(seed=seed)
    env.action_space.seed(seed)
    actions = [env.action_space.sample() for _ in range(steps)]
    t0 = time.perf_counter()
    for a in actions:
        _, _, term, trunc, _ = env.step(a)
        if term or trunc:
            env.reset()
    return steps / (time.perf_counter() - t0)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--steps", type=int, default=5000, help="env steps in the end-to-end loop")
    parser.add_argument("--track", default="paper")
    parser.add_argument("--substeps", type=int, default=8, help="physics substeps per control step")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--reference", default="Pendulum-v1",
                        help="a Gymnasium env timed in the same run as a yardstick ('' to skip)")


def run(args: argparse.Namespace) -> int:
    r = bench_env(args.steps, args.track, args.seed, args.substeps)
    per = r["us_per_step"]
    print(f"Azimut-v0 single env, track {args.track}, {int(r['substeps'])} substeps, {int(r['steps'])} steps")
    print(f"{'stage':<16}{'us/step':>10}{'share':>8}")
    for key, label in (("physics_us", "physics"), ("estimation_us", "estimation"), ("observation_us", "observation"),
                       ("sensors_us", "  sensors"), ("track_us", "  track"), ("obs_reward_info_us", "  obs+rew+info"),
                       ("other_us", "other")):
        print(f"{label:<16}{r[key]:>10.1f}{r[key] / per:>8.0%}")
    print(f"{'total':<16}{per:>10.1f}")
    print(f"steps/s: {r['steps_per_s']:.0f} overall, {r['best_chunk_steps_per_s']:.0f} in the best chunk "
          f"({int(r['resets'])} resets, not timed)  (bar 1500, goal 5000)")
    if args.reference:
        ref = reference_steps_per_s(args.reference)
        print(f"reference {args.reference}: {ref:.0f} steps/s in the same run (Azimut-v0 at "
              f"{r['steps_per_s'] / ref:.2f}x of it)")
    return 0


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_arguments(p)
    raise SystemExit(run(p.parse_args()))
