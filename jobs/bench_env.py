"""``azimut bench-env``: simulator throughput (env steps/s), single env and vector env, with time splits.

* The single env (``AzimutEnv``, one robot per Space and per Python call) is timed in a plain
  ``env.step`` loop with small uniformly random actions (resets excluded), split inside the same
  loop (thin timing wrappers) into the physics, what follows it (the noise draw and the one
  compiled call of :mod:`azimut_env.task.pipeline`), the info dict and the rest.
* ``--num-envs 1,16,64,256`` also times ``AzimutVectorEnv`` at each N, in the same run: an
  uninstrumented loop of ``vec.step`` gives the steps/s (robot-steps per second: N per call) and
  the ratio against the single env; a second, instrumented loop splits the time per robot-step
  into actions, read of the pymunk bodies, force model (the compiled substep kernel: actuators,
  spring, tires, module and chassis integration), write back to pymunk, ``space.step`` (only
  with obstacles), the summary, sensors (noise draws and encoder models), estimation (the
  batched IT), track queries, reward + observation, and the rest (Python glue, info arrays). The
  physics stages come from ``AzimutPhysics.step``'s own timing hook (``stage_times``), so the
  split times the code that runs. Memory: resident-set growth of a 512-robot vector env per
  robot, measured in a fresh process.

Compare ratios measured within one run: the machine may be shared.
"""

from __future__ import annotations

import argparse
import gc
import time

import numpy as np

from azimut_env.tracks import TRACK_NAMES
from jobs.args import add_robot_arguments, arg_choice_list, arg_int, arg_name_list, arg_threads_list, robot_label
from jobs.bench_speed import JOBS, check_baseline, load_average, reference_steps_per_s, run_baseline_bench
from jobs.bench_threads import ACTION_BENCH, timed

__all__ = ["bench_env", "bench_vector_env", "memory_per_robot", "reference_steps_per_s",
           "add_arguments", "run"]

#: stages of the vector env's split, in print order
VECTOR_STAGES = ("actions", "read", "force", "write", "space_step", "summary", "sensors", "estimation", "track",
                 "reward_obs", "other")


def _rss_mb() -> float:
    """Resident set size of this process [MB] (Linux /proc; NaN elsewhere)."""
    try:
        with open("/proc/self/statm") as f:
            pages = int(f.read().split()[1])
        import os

        return pages * os.sysconf("SC_PAGE_SIZE") / 1e6
    except (OSError, ValueError, AttributeError):
        return float("nan")


def bench_env(steps: int = 5000, track: str = "paper", seed: int = 0, substeps: int = 8,
              robot_kwargs: dict | None = None) -> dict[str, float]:
    """Single env: steps/s and per-stage microseconds per step. Returns a dict of figures.

    The stages are timed inside the end-to-end loop itself (thin timing wrappers on the task's
    stage methods), so the breakdown adds up to the measured total on a shared machine too."""
    from azimut_env.env import AzimutEnv

    env = AzimutEnv(track=track, substeps=substeps, **(robot_kwargs or {}))
    env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    actions = rng.uniform(-1, 1, size=(steps, env.action_space.shape[0])).astype(np.float32) * 0.2
    for i in range(50):  # warm-up (numba kernels load from cache or compile)
        env.step(actions[i])
    acc = {"physics": 0.0, "observe": 0.0, "info": 0.0}
    clock = time.perf_counter

    task = env.task
    task.physics.step = timed(acc, task.physics.step, "physics")
    task.observe = timed(acc, task.observe, "observe")  # the noise draw and the one compiled call
    import azimut_env.env as env_module  # the info dict, built per step by the env (azimut_env.task.info)

    robot_info = env_module.robot_info
    env_module.robot_info = timed(acc, robot_info, "info")
    env.reset(seed=seed)
    for key in acc:
        acc[key] = 0.0
    done, resets, elapsed, cpu = 0, 0, 0.0, 0.0
    chunk_rates = []
    chunk = max(1, steps // 5)
    while done < steps:
        t0, c0 = clock(), time.process_time()
        n_chunk = 0
        term = trunc = False
        for _ in range(chunk):
            _, _, term, trunc, _ = env.step(actions[done % steps])
            done += 1
            n_chunk += 1
            if term or trunc:
                break
        dt = clock() - t0
        cpu += time.process_time() - c0
        elapsed += dt
        chunk_rates.append(n_chunk / dt)
        if term or trunc:  # resets are not timed, in the total or in the stages
            saved = dict(acc)
            env.reset()
            acc.update(saved)
            resets += 1
    env_module.robot_info = robot_info
    total = elapsed / done
    per = {key: value / done for key, value in acc.items()}
    return {
        "steps_per_s": 1.0 / total,
        "cpu_steps_per_s": done / cpu,
        "us_per_step": total * 1e6,
        "physics_us": per["physics"] * 1e6,
        "observe_us": per["observe"] * 1e6,
        "info_us": per["info"] * 1e6,
        "other_us": max(0.0, total - sum(per.values())) * 1e6,
        "substeps": float(substeps),
        "steps": float(done),
        "resets": float(resets),
        "best_chunk_steps_per_s": max(chunk_rates),
    }


def bench_vector_env(num_envs: int, robot_steps: int = 20000, track: str = "paper", seed: int = 0,
                     substeps: int = 8, split: bool = True, solver_iterations: int = 20,
                     max_episode_steps: int | None = 6000, robot_kwargs: dict | None = None) -> dict[str, float]:
    """``AzimutVectorEnv`` with N = ``num_envs``: robot-steps/s over about ``robot_steps`` robot-steps
    (uninstrumented; in wall and in CPU time), the per-robot-step time split (a second, instrumented
    loop) and the memory per robot. ``max_episode_steps`` short enough puts autoresets (timed) in
    the loop. Returns a dict of figures (times in µs per robot-step)."""
    from azimut_env.vector_env import AzimutVectorEnv

    gc.collect()
    rss0 = _rss_mb()
    venv = AzimutVectorEnv(num_envs=num_envs, track=track, substeps=substeps, solver_iterations=solver_iterations,
                           max_episode_steps=max_episode_steps, **(robot_kwargs or {}))
    venv.reset(seed=seed)
    N = num_envs
    rng = np.random.default_rng(seed)
    actions = (rng.uniform(-1, 1, size=(64, N, 2 * venv.n)) * 0.2).astype(np.float32)
    for i in range(10):  # warm-up
        venv.step(actions[i % 64])
    calls = max(20, int(robot_steps // N))
    clock = time.perf_counter
    chunk = max(1, calls // 5)
    rates = []
    t_total = 0.0
    done = 0
    cpu0 = time.process_time()
    while done < calls:
        t0 = clock()
        m = min(chunk, calls - done)
        for j in range(m):
            venv.step(actions[(done + j) % 64])
        dt = clock() - t0
        t_total += dt
        rates.append(m * N / dt)
        done += m
    cpu = time.process_time() - cpu0
    rss1 = _rss_mb()
    out: dict[str, float] = {
        "num_envs": float(N),
        "steps_per_s": calls * N / t_total,
        "cpu_steps_per_s": calls * N / cpu,
        "best_chunk_steps_per_s": max(rates),
        "us_per_robot_step": t_total / (calls * N) * 1e6,
        "rss_growth_mb_per_robot": (rss1 - rss0) / N,
        "calls": float(calls),
    }
    if split:
        out.update(_vector_split(venv, actions, calls))
    venv.close()
    return out


def _vector_split(venv, actions: np.ndarray, calls: int) -> dict[str, float]:
    """The instrumented loop: stage times per robot-step [µs] (keys ``<stage>_us``), with the
    stages after the physics run one by one (``Pipeline.run_timed``: the uninstrumented loop
    runs them as one compiled call)."""
    acc = {k: 0.0 for k in VECTOR_STAGES}
    clock = time.perf_counter
    task, phys = venv.task, venv.physics
    step, reset = task.pipelines()
    task.apply_actions = timed(acc, task.apply_actions, "actions")
    phys.stage_times = acc  # the physics stages from AzimutPhysics.step's own timing hook
    task.sensors.draw_noise = timed(acc, task.sensors.draw_noise, "sensors")
    column = lambda stage: {"sensors": "sensors", "icr_estimate": "estimation", "track_state": "track",  # noqa: E731
                            "localisation": "track"}.get(stage.__module__.rsplit(".", 1)[-1], "reward_obs")
    task.pipelines = lambda: (lambda rows, action: step.runtimed(rows, action, acc, column), reset)
    N = venv.num_envs
    try:
        t0 = clock()
        for i in range(calls):
            venv.step(actions[i % 64])
        total = clock() - t0
    finally:
        for name in ("apply_actions", "pipelines"):
            task.__dict__.pop(name, None)
        phys.stage_times = None
        task.sensors.__dict__.pop("draw_noise", None)
    acc["other"] = max(0.0, total - sum(v for k, v in acc.items() if k != "other"))
    scale = 1e6 / (calls * N)
    out = {f"{k}_us": v * scale for k, v in acc.items()}
    out["instrumented_us_per_robot_step"] = total * scale
    return out


def memory_per_robot(num_envs: int = 512, track: str = "paper", substeps: int = 8) -> float:
    """MB per robot of the vector env: the resident-set growth from building and running a
    ``num_envs``-robot vector env after a 16-robot one (imports, compiled kernels and one-time
    allocations paid), divided by ``num_envs``, in a fresh Python process."""
    import subprocess
    import sys

    code = (
        "import gc, numpy as np\n"
        "from jobs.bench_env import _rss_mb\n"
        "from azimut_env.vector_env import AzimutVectorEnv\n"
        "def run(n):\n"
        f"    v = AzimutVectorEnv(num_envs=n, track={track!r}, substeps={int(substeps)})\n"
        "    v.reset(seed=0)\n"
        "    for _ in range(5): v.step(np.zeros((n, 8), dtype=np.float32))\n"
        "    return v\n"
        "keep = run(16); gc.collect(); r0 = _rss_mb()\n"
        f"big = run({int(num_envs)}); gc.collect(); print((_rss_mb() - r0) / {int(num_envs)})\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return float(out.stdout.strip().splitlines()[-1])



#: ``--num-envs`` bound: ~10 kB per robot (RSS growth at 4096 robots), 1 GB; 10**7 was a MemoryError
MAX_NUM_ENVS = 100_000


def _int_list(text: str) -> list[int]:
    try:
        values = [int(x) for x in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a comma-separated list of integers, got {text!r}") from None
    if not values or any(v < 1 for v in values):
        raise argparse.ArgumentTypeError(f"expected positive integers, got {text!r}")
    if max(values) > MAX_NUM_ENVS:
        raise argparse.ArgumentTypeError(f"{max(values)} robots: at most {MAX_NUM_ENVS} (about 10 kB and a pymunk "
                                         f"body per robot: {max(values) * 1e-5:.3g} GB for {max(values)})")
    return values


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--action", default=None, metavar="NAME[,NAME...]",
                        type=arg_name_list(tuple(ACTION_BENCH)),
                        help="only time the vector env behind these action spaces (raw, residual, icr-rate, "
                             "icr-target, twist; icr_rate, icr_target as the tables print them) with a controller "
                             "in the loop, at --action-envs robots")
    parser.add_argument("--action-envs", type=arg_int(1, 4096), default=16,
                        help="robots for --action (default 16)")
    parser.add_argument("--steps", type=arg_int(1, 100_000_000), default=5000,
                        help="single-env steps in the end-to-end loop")
    add_robot_arguments(parser, imperfections=True, several=True)  # several: the vector env timed with each
    parser.add_argument("--track", default="paper", choices=TRACK_NAMES,
                        help=f"built-in track among {', '.join(TRACK_NAMES)}")
    parser.add_argument("--substeps", type=arg_int(1, 10_000), default=8, help="physics substeps per control step")
    parser.add_argument("--seed", type=arg_int(0, 2**32 - 1), default=0)
    parser.add_argument("--num-envs", type=_int_list, default=None, metavar="N[,N...]",
                        help="also time the vector env at these N (e.g. 1,16,64,256)")
    parser.add_argument("--vector-steps", type=arg_int(1, 100_000_000), default=20000,
                        help="robot-steps per N in the vector env's timed loop (at least 20 calls)")
    parser.add_argument("--episode-steps", type=arg_int(1, 100_000_000), default=6000,
                        help="vector env time limit; short values put (timed) autoresets in the loop")
    parser.add_argument("--solver-iterations", type=arg_int(1, 10_000), default=20,
                        help="pymunk solver iterations per substep in the vector env (default 20, as the envs)")
    parser.add_argument("--reference", default="Pendulum-v1",
                        help="a Gymnasium env timed in the same run as a yardstick ('' to skip)")
    parser.add_argument("--baseline", default=None, metavar="DIR",
                        help="instead, time azimut eval's default campaign and azimut train --action residual with "
                             "this checkout and with DIR (a checkout of an earlier commit), alternated")
    parser.add_argument("--jobs", default=list(JOBS), type=arg_choice_list(tuple(JOBS)),
                        help="with --baseline: the jobs to time (default eval,train)")
    parser.add_argument("--repeats", type=arg_int(1, 100), default=2,
                        help="with --baseline: runs per side; with --threads: alternated runs per count (default 2)")
    parser.add_argument("--threads", type=arg_threads_list, default=None, metavar="N[,N...]",
                        help="instead, the vector env's scaling with threads (e.g. 1,2) at --num-envs robots (default "
                             "16,256) for each --action (default raw,residual,icr-rate,twist), alternated runs, and "
                             "whether every count gives the same bits (jobs/bench_threads.py)")
    parser.add_argument("--train-steps", type=arg_int(4096, 100_000_000), default=32768,
                        help="with --baseline: azimut train's --steps (default 32768)")
    parser.add_argument("--cold", action="store_true",
                        help="with --baseline: no warm-up run (the first run compiles the numba kernels)")
    parser.add_argument("--convergence", action="store_true",
                        help="instead of timing, measure the physics' convergence in the substep count (30 s open-loop "
                             "replay, 4..128 substeps against 256)")


def check_args(args: argparse.Namespace) -> None:
    """The reference env must exist and the substeps be inside the physics' stability budget
    before minutes of timing are spent (``--convergence`` sweeps its own substep counts)."""
    if args.baseline:
        check_baseline(args.baseline)
    if not args.convergence:
        from azimut_env.physics.stability import check_substeps
        from azimut_env.task.config import robot_of

        for kw in (_robot_kwargs(args, name) for name in args.imperfections or [None]):
            check_substeps(args.substeps, robot_of(kw))
    if args.reference:
        import gymnasium as gym

        if args.reference not in gym.registry:
            raise ValueError(f"argument --reference: unknown Gymnasium env {args.reference!r} ('' to skip)")


def _robot_kwargs(args: argparse.Namespace, imperfections: str | None = None) -> dict:
    """The env keyword arguments of ``--robot``/``--robot-file`` and ``imperfections`` (default: the
    first of ``--imperfections``; none given: the envs' rule)."""
    from jobs.args import robot_env_kwargs

    imperfections = imperfections or (getattr(args, "imperfections", None) or [None])[0]
    return robot_env_kwargs(getattr(args, "robot", None), getattr(args, "robot_file", None), imperfections)


def run(args: argparse.Namespace) -> int:
    if args.baseline:
        run_baseline_bench(check_baseline(args.baseline), args.jobs, args.repeats, args.train_steps, args.cold)
        return 0
    if args.threads:
        from jobs.bench_threads import print_thread_scaling

        return print_thread_scaling(args, _robot_kwargs(args))
    if args.action:
        from jobs.bench_threads import run_action_bench

        return run_action_bench(args, _robot_kwargs(args))
    if args.convergence:
        return _print_convergence()
    r = _print_single(args)
    if args.num_envs:
        _print_vector(args, r["steps_per_s"])
    return _print_reference(args.reference, r) if args.reference else 0


def _print_convergence() -> int:
    print("substep convergence: 30 s open-loop replay of smooth kinematic set-points, against 256 substeps")
    print(f"{'substeps':>9}{'max pos mm':>12}{'final mm':>10}{'heading deg':>12}{'beta deg':>10}{'order':>7}")
    from azimut_env.physics.convergence import substep_convergence

    for row in substep_convergence():
        if row["refused"]:
            print(f"{int(row['substeps']):>9}  refused by the stability check")
            continue
        print(f"{int(row['substeps']):>9}{row['max_position_error'] * 1e3:>12.3f}"
              f"{row['final_position_error'] * 1e3:>10.3f}{np.degrees(row['final_heading_error']):>12.4f}"
              f"{np.degrees(row['max_beta_error']):>10.4f}{row['order']:>7.2f}")
    return 0


def _print_single(args: argparse.Namespace) -> dict[str, float]:
    r = bench_env(args.steps, args.track, args.seed, args.substeps, _robot_kwargs(args))
    per = r["us_per_step"]
    print(f"Azimut-v2 single env, robot {robot_label(args)}, track {args.track}, {int(r['substeps'])} substeps, "
          f"{int(r['steps'])} steps")
    print(f"{'stage':<16}{'us/step':>10}{'share':>8}")
    for key, label in (("physics_us", "physics"), ("observe_us", "after physics"), ("info_us", "info dict"),
                       ("other_us", "other")):
        print(f"{label:<16}{r[key]:>10.1f}{r[key] / per:>8.0%}")
    print("(after physics: the sensor noise draw and the one compiled call for sensors, estimation, track, "
          "termination, reward and observation; other: step()'s checks, the actions, the blow-up check)")
    print(f"{'total':<16}{per:>10.1f}")
    best, resets = r["best_chunk_steps_per_s"], int(r["resets"])
    print(f"steps/s: {r['steps_per_s']:.0f} overall ({r['cpu_steps_per_s']:.0f} in CPU time), {best:.0f} in the best "
          f"chunk ({resets} resets, not timed)  (bar 1500, goal 5000)")
    return r


def _print_vector(args: argparse.Namespace, single: float) -> None:
    print(f"\nAzimutVectorEnv (N robots in one Space), track {args.track}, {args.substeps} substeps, "
          f"{args.solver_iterations} solver iterations, IT estimation included; ~{args.vector_steps} robot-steps "
          f"per N, episodes of at most {args.episode_steps} steps (autoresets timed)")
    presets = args.imperfections or [None]
    print(f"{'N':>5}{'steps/s':>10}{'best':>9}{'ratio':>7}{'us/step':>9}" + "  imperfections" * bool(presets[0]))
    rows = []
    for N in args.num_envs:
        for name in presets:
            v = bench_vector_env(N, args.vector_steps, args.track, args.seed, args.substeps,
                                 solver_iterations=args.solver_iterations, max_episode_steps=args.episode_steps,
                                 robot_kwargs=_robot_kwargs(args, name))
            rows.append(v)
            first = rows[len(rows) - 1 - presets.index(name)]  # this N's row of the first preset
            tail = (f"  {name} ({v['steps_per_s'] / first['steps_per_s']:.2f}x {presets[0]}, "
                    f"{v['cpu_steps_per_s'] / first['cpu_steps_per_s']:.2f}x in CPU time)") if name else ""
            print(f"{N:>5}{v['steps_per_s']:>10.0f}{v['best_chunk_steps_per_s']:>9.0f}"
                  f"{v['steps_per_s'] / single:>6.1f}x{v['us_per_robot_step']:>9.1f}{tail}", flush=True)
    print("(steps/s: robot-steps per second ('best': the best fifth of the loop); ratio: against the single "
          "env above, same run; bar 40000, goal 80000 at N = 64)")
    mb = memory_per_robot(512, args.track, args.substeps)
    print(f"memory: {mb:.3f} MB per robot (resident-set growth of a 512-robot vector env of the default robot, "
          "fresh process)\n")
    print("time split, us per robot-step (instrumented loop; 'read', 'force', 'write', 'space.step' are per control "
          "step, all substeps; without obstacles pymunk is read and written once per step and not stepped; the "
          "stages after the physics one by one here, not as the one compiled call of the loop above)")
    labels = dict(space_step="space.step", reward_obs="rew+obs", summary="summary")
    print(f"{'N':>5}" + "".join(f"{labels.get(k, k):>11}" for k in VECTOR_STAGES) + f"{'total':>9}")
    for v in rows:
        cells = "".join(f"{v[k + '_us']:>11.2f}" for k in VECTOR_STAGES)
        print(f"{int(v['num_envs']):>5}{cells}{v['instrumented_us_per_robot_step']:>9.1f}")


def _print_reference(name: str, r: dict[str, float]) -> int:
    import gymnasium as gym
    try:
        ref, ref_cpu = reference_steps_per_s(name, with_cpu=True)
    except gym.error.DependencyNotInstalled as exc:
        print(f"reference {name}: not timed, a dependency is missing ({str(exc).splitlines()[0]}); "
              "LunarLanderContinuous-v3 needs box2d: pip install 'gymnasium[box2d]'")
        return 0
    print(f"reference {name}: {ref:.0f} steps/s in the same run ({ref_cpu:.0f} in CPU time); the single env at "
          f"{r['steps_per_s'] / ref:.2f}x of it ({r['cpu_steps_per_s'] / ref_cpu:.2f}x in CPU time; goal 0.75x "
          f"LunarLanderContinuous-v3); load average {load_average()}")
    return 0

