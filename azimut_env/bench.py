"""``azimut bench-env``: single-env throughput (steps/s) of Azimut-v0 with a time breakdown.

The breakdown times each stage of ``AzimutEnv.step`` in isolation on the live env state, repeated
many times (physics: the pymunk substeps and the compiled actuator/tire kernel; estimation: IT,
μ̂ and qua; observation: sensors, track query, observation vector, reward, info). The end-to-end
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
    """Measure steps/s and per-stage microseconds per step. Returns a dict of figures."""
    from .env import AzimutEnv, h_state_from_measurements
    from .sensors import measure_all

    env = AzimutEnv(track=track, substeps=substeps)
    env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    actions = rng.uniform(-1, 1, size=(steps, env.action_space.shape[0])).astype(np.float32) * 0.2
    # warm-up (numba kernels load from cache or compile)
    for i in range(50):
        env.step(actions[i])
    env.reset(seed=seed)
    done, resets, elapsed = 0, 0, 0.0
    chunk_rates = []
    chunk = max(1, steps // 5)
    while done < steps:
        t0 = time.perf_counter()
        n_chunk = 0
        for _ in range(chunk):
            _, _, term, trunc, _ = env.step(actions[done % steps])
            done += 1
            n_chunk += 1
            if term or trunc:
                break
        dt = time.perf_counter() - t0
        elapsed += dt
        chunk_rates.append(n_chunk / dt)
        if term or trunc:  # resets are not timed
            env.reset()
            resets += 1
    total = elapsed / done
    env.reset(seed=seed)
    for i in range(100):
        env.step(actions[i])
    reps = max(200, steps // 5)
    phys = env.physics
    geom = env.geometry
    q, w = env.measured_beta, env.measured_phidot
    t_phys = _time(phys.step, reps)
    t_est = _time(lambda: h_state_from_measurements(q, w, geom), reps)
    sens = env.params.sensors

    def observe():
        measure_all(phys.wheel_summary[0, :, 0], phys.motor_state[0, :, 0], phys.motor_state[0, :, 4],
                    phys.motor_state[0, :, 4], phys.motor_state[0, :, 3], env.control_period, sens, env.np_random)
        env._track_state(env.progress)
        env._get_obs()
        env._get_rew(0.01, 0.0, 0.0, actions[0], False)
        env._get_info({})

    t_obs = _time(observe, reps)
    return {
        "steps_per_s": 1.0 / total,
        "us_per_step": total * 1e6,
        "physics_us": t_phys * 1e6,
        "estimation_us": t_est * 1e6,
        "observation_us": t_obs * 1e6,
        "other_us": max(0.0, total - t_phys - t_est - t_obs) * 1e6,
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
    print(f"{'stage':<14}{'us/step':>10}{'share':>8}")
    for key, label in (("physics_us", "physics"), ("estimation_us", "estimation"), ("observation_us", "observation"),
                       ("other_us", "other")):
        print(f"{label:<14}{r[key]:>10.1f}{r[key] / per:>8.0%}")
    print(f"{'total':<14}{per:>10.1f}")
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
