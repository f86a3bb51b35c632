"""``azimut bench-env --action`` and ``--threads``: the vector env with a controller in the loop, and
how it scales with threads.

``--action`` (:func:`run_action_bench`): robot-steps/s behind each action space and where the time
of a step goes (targets, controller, env). ``--threads 1,2`` (:func:`print_thread_scaling`), in one run:

for each action space (raw set-points, or a controller in the loop: ``residual``, ``icr-rate``,
``twist``) and each N robots, the vector env is built at every thread count of ``--threads`` and
stepped with the same seeded uniform random actions (same-step autoresets on ``--track``; raw
set-points over a fifth of their range, as ``--num-envs`` draws them); robot-steps/s are timed
``--repeats`` times with the thread counts alternated (ascending, then descending, ...) and the
median is reported with its ratio to the first count. Every step's observations, rewards and ends
at every count are compared after the timed loops: they must be the same bits
(:mod:`estimation.threads`), and the table says so.
"""

from __future__ import annotations

import hashlib
import time
from statistics import median

import numpy as np

from jobs.bench_speed import load_average

__all__ = ["timed", "ACTION_BENCH", "bench_controller_action", "run_action_bench", "scaling_cell", "thread_scaling",
           "print_thread_scaling"]


def timed(acc: dict[str, float], fn, key: str):
    """``fn`` wrapped so that each call adds its wall time [s] to ``acc[key]`` (the stage splits)."""
    def wrapper(*args, **kwargs):
        t = time.perf_counter()
        out = fn(*args, **kwargs)
        acc[key] += time.perf_counter() - t
        return out
    return wrapper


#: ``--action`` names -> ``control.action_spaces.vector.VectorControllerAction`` kinds (None: raw set-points)
ACTION_BENCH = {"raw": None, "residual": "residual", "icr-rate": "icr_rate", "icr-target": "icr_target",
                "twist": "twist"}


def action_env(action: str, num_envs: int, track: str, env_kwargs: dict):
    """(the vector env, the env the benchmark steps): the same one for raw set-points, else the
    controller action space ``action`` on it (same-step autoresets)."""
    from gymnasium.vector import AutoresetMode

    from azimut_env.vector_env import AzimutVectorEnv

    venv = AzimutVectorEnv(num_envs=num_envs, track=track, autoreset_mode=AutoresetMode.SAME_STEP, **env_kwargs)
    kind = ACTION_BENCH[action]
    if kind is None:
        return venv, venv
    import control.action_spaces.vector as vw

    return venv, vw.VectorControllerAction(venv, action=kind)


def bench_controller_action(action: str, num_envs: int = 16, calls: int = 300, track: str = "random",
                            seed: int = 0, robot_kwargs: dict | None = None) -> dict[str, float]:
    """Robot-steps/s of the vector env behind a controller action space (uniform random actions,
    same-step autoresets), with the time per control step split into the policy-action ->
    controller-target stage (path followers, target shaping), the controller (the batched ICR
    controller, or the per-robot twist baselines), the vector env's step and the rest (wrapper
    glue)."""
    venv, wrapped = action_env(action, num_envs, track, robot_kwargs or {})
    kind = ACTION_BENCH[action]
    acc = {"targets": 0.0, "controller": 0.0, "env": 0.0}
    clock = time.perf_counter
    wrapped.reset(seed=seed)
    rng = np.random.default_rng(seed)
    actions = rng.uniform(-1, 1, size=(calls + 20,) + wrapped.action_space.shape).astype(np.float32)
    for k in range(20):  # warm-up (numba kernels load or compile)
        wrapped.step(actions[k])
    t0, c0 = clock(), time.process_time()
    for k in range(calls):
        wrapped.step(actions[20 + k])
    total, cpu = clock() - t0, time.process_time() - c0
    if kind is not None:  # a second, instrumented loop for the split (instance attributes shadow the methods)
        ctl = wrapped.controller  # the action space's ActionController
        inner = ctl.icr if ctl.icr is not None else ctl.swerve
        inner.step = timed(acc, inner.step, "controller")
        ctl._targets = timed(acc, ctl._targets, "targets")
        venv.step = timed(acc, venv.step, "env")
        try:
            t1 = clock()
            for k in range(calls):
                wrapped.step(actions[20 + k])
            inst = clock() - t1
        finally:
            for obj, name in ((inner, "step"), (ctl, "_targets"), (venv, "step")):
                del obj.__dict__[name]
    else:
        acc["env"], inst = total, total
    per = 1e6 / (calls * num_envs)
    return {"action": action, "num_envs": num_envs, "steps_per_s": calls * num_envs / total,
            "cpu_steps_per_s": calls * num_envs / cpu,
            "targets_us": acc["targets"] * per, "controller_us": acc["controller"] * per, "env_us": acc["env"] * per,
            "other_us": (inst - sum(acc.values())) * per, "instrumented_us": inst * per}


def run_action_bench(args, robot_kwargs: dict) -> int:
    """``--action``: robot-steps/s with a controller in the loop, and where the time goes."""
    track = args.track if args.track != "paper" else "random"
    print(f"AzimutVectorEnv behind controller action spaces: {args.action_envs} robots, track {track} (random: a "
          f"new track per episode), uniform random actions, same-step autoresets; us per robot-step "
          f"(instrumented loop) and robot-steps/s (uninstrumented loop). The machine may be shared: compare ratios "
          f"within one run.")
    print(f"load average {load_average()}")
    print(f"{'action':<12}{'steps/s':>9}{'x raw':>7}{'CPU st/s':>10}{'x raw':>7}{'targets':>9}{'ctl':>9}{'env':>9}"
          f"{'other':>9}{'total':>9}")
    raw = None
    for action in args.action:
        r = bench_controller_action(action, args.action_envs, max(20, args.steps // args.action_envs), track, args.seed,
                                    robot_kwargs)
        raw = r if action == "raw" else raw
        rel = [f"{r[k] / raw[k]:>7.2f}" if raw else f"{'-':>7}" for k in ("steps_per_s", "cpu_steps_per_s")]
        keys = ("targets_us", "controller_us", "env_us", "other_us", "instrumented_us")
        cells = "".join(f"{r[k]:>9.1f}" for k in keys)
        print(f"{action:<12}{r['steps_per_s']:>9.0f}{rel[0]}{r['cpu_steps_per_s']:>10.0f}{rel[1]}{cells}", flush=True)
    print(f"load average {load_average()}")
    print("(targets: the policy action -> ICR target stage, i.e. the residual's per-robot path followers or the "
          "target shaping; ctl: the batched ICR controller; env: AzimutVectorEnv.step; x raw: against the raw "
          "actions of the same run ('raw' first), in wall and in CPU time; goal 0.5x raw for residual, icr-rate and "
          "twist at 16 robots)")
    return 0


def scaling_cell(action: str, num_envs: int, threads: int, calls: int, track: str, seed: int,
                 robot_kwargs: dict | None = None) -> tuple[float, str]:
    """(robot-steps/s, digest of every step's observation, reward and ends) of ``calls`` steps of
    the vector env behind ``action`` at ``threads`` threads, after 20 untimed steps."""
    venv, env = action_env(action, num_envs, track, {**(robot_kwargs or {}), "num_threads": threads})
    try:
        env.reset(seed=seed)
        rng = np.random.default_rng(seed)
        # raw set-points as bench-env --num-envs draws them (a fifth of the range: the robots stay on
        # the track); a controller's actions over their whole range, as --action
        scale = 0.2 if env is venv else 1.0
        actions = (rng.uniform(-1, 1, size=(calls + 20,) + env.action_space.shape) * scale).astype(np.float32)
        for k in range(20):
            env.step(actions[k])
        clock = time.perf_counter
        kept = []  # every step's outputs, hashed after the timed loop
        t0 = clock()
        for k in range(calls):
            obs, rew, term, trunc, _ = env.step(actions[20 + k])
            kept.append((obs.copy(), rew.copy(), term.copy(), trunc.copy()))
        elapsed = clock() - t0
        digest = hashlib.sha256()
        for arrays in kept:
            for a in arrays:
                digest.update(a.tobytes())
    finally:
        venv.close()
    return calls * num_envs / elapsed, digest.hexdigest()[:16]


def thread_scaling(actions: list[str], num_envs: list[int], threads: list[int], robot_steps: int, repeats: int,
                   track: str, seed: int, robot_kwargs: dict | None = None, log=print) -> list[dict]:
    """One row per (action, N): the median robot-steps/s at each thread count, the ratio to the
    first, and whether every run gave the same bits. ``log``: each row as it is done."""
    rows = []
    for action in actions:
        for N in num_envs:
            calls = max(20, robot_steps // N)
            rates: dict[int, list[float]] = {t: [] for t in threads}
            digests = set()
            for rep in range(repeats):
                for t in (threads if rep % 2 == 0 else threads[::-1]):
                    rate, digest = scaling_cell(action, N, t, calls, track, seed, robot_kwargs)
                    rates[t].append(rate)
                    digests.add(digest)
            med = {t: median(v) for t, v in rates.items()}
            row = {"action": action, "num_envs": N, "calls": calls, "steps_per_s": med,
                   "ratio": {t: med[t] / med[threads[0]] for t in threads}, "same_bits": len(digests) == 1}
            rows.append(row)
            log(_row_line(row, threads))
    return rows


def _row_line(row: dict, threads: list[int]) -> str:
    cells = "".join(f"{row['steps_per_s'][t]:>12.0f}{row['ratio'][t]:>7.2f}x" for t in threads)
    return f"{row['action']:<10}{row['num_envs']:>6}{cells}   {'yes' if row['same_bits'] else 'NO'}"


def print_thread_scaling(args, robot_kwargs: dict) -> int:
    """The table of ``azimut bench-env --threads``; exit status 1 if a thread count changed a result."""
    actions = args.action or ["raw", "residual", "icr-rate", "twist"]
    num_envs = args.num_envs or [16, 256]
    track, threads = args.track, args.threads
    print(f"AzimutVectorEnv thread scaling: track {track}, same-step autoresets, seeded uniform random actions (raw: "
          f"a fifth of the set-point range, as --num-envs); ~{args.vector_steps} robot-steps per run, median of "
          f"{args.repeats} runs with the thread counts alternated; x: against {threads[0]} thread(s) in this run")
    print(f"load average {load_average()}")
    print(f"{'action':<10}{'N':>6}" + "".join(f"{f'{t} thr st/s':>12}{'x':>8}" for t in threads) + "   same bits")
    rows = thread_scaling(actions, num_envs, threads, args.vector_steps, args.repeats, track, args.seed,
                          robot_kwargs, log=lambda line: print(line, flush=True))
    print(f"load average {load_average()}")
    print("(same bits: every observation, reward and end of every run equal across the thread counts; goals: "
          "raw at 256 robots >= 1.7x with 2 threads, residual/icr-rate/twist >= 1.6x, 16 robots no slower)")
    return 0 if all(r["same_bits"] for r in rows) else 1
