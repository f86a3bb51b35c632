"""``azimut bench-campaign``: the same ``azimut eval`` campaign run serially and on N workers in
one run, with the wall times, the speed-up and a check that every episode's metrics are
bit-identical.

Default: 2 controllers × 6 tracks × 4 seeds (48 full episodes, no plots), serial in this process
against ``--workers 2`` (local processes by default; ``--executors process,ray``
times both). The campaign runs in rounds of ``--seeds-per-round`` seeds (default 2), each run by
every executor in turn (alternating the order), so that the varying load of a shared machine
falls on all of them alike; a round holds several of the longest episodes (the ICR controller on
``paper``), so that it can be shared evenly by the workers. It also prints the ideal parallel
time computed from the serial task times. The serial runs follow one
short warm-up episode per controller, so they do not pay for loading the numba kernels; the
parallel runs include everything they cost (starting worker processes in every round, imports,
starting the Ray instance once). Besides the wall times it prints the CPU time the episodes got
(CPU time / wall time: the cores a run actually had).
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time

from azimut_env.tracks import TRACK_NAMES
from jobs.campaign.args import arg_seeds
from jobs.campaign.engine import EXECUTORS, resolve_executor, run_tasks
from jobs.eval.campaign import episode_task, episode_tasks
from jobs.eval.command import DEFAULT_TRACKS

__all__ = ["add_arguments", "check_args", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from jobs.args import arg_choice_list, arg_float, arg_int

    parser.add_argument("--controllers", type=arg_choice_list(("icr", "twist", "twist-setpoint", "feedforward")),
                        default=["icr", "twist"],  # its results page's campaign (not azimut eval's default)
                        help="comma-separated controllers (default: icr,twist)")
    parser.add_argument("--tracks", type=arg_choice_list(TRACK_NAMES), default=list(DEFAULT_TRACKS),
                        help="comma-separated tracks (default: all six)")
    parser.add_argument("--seeds", type=arg_seeds, default=[0, 1, 2, 3], help="seeds (default 0-3)")
    parser.add_argument("--workers", type=arg_int(2, 1024), default=2, help="parallel workers (default 2)")
    parser.add_argument("--executors", type=arg_choice_list([e for e in EXECUTORS if e != "serial"]),
                        default=["auto"],
                        help="parallel executors to time against serial, e.g. process,ray (default: auto)")
    parser.add_argument("--max-time", type=arg_float(0.0, 3600.0, lo_open=True), default=None, metavar="SECONDS",
                        help="cap each episode (default: full episodes)")
    parser.add_argument("--seeds-per-round", type=arg_int(0, 100_000), default=2, metavar="K",
                        help="rounds of K seeds, each run by every executor in turn, so that a shared machine's "
                             "load falls on all alike (default 2; 0: one round, the whole campaign)")


def check_args(args: argparse.Namespace) -> None:
    for ex in args.executors:
        resolve_executor(ex, args.workers, None)


def _spin(n: int) -> float:
    x = 0
    for i in range(n):
        x += i * i
    return float(x > 0)


def machine_headroom(workers: int, n: int = 5_000_000) -> float:
    """What the machine gives right now: the speed-up of ``workers`` processes each running a
    pure-Python loop over one process running one (no I/O, no memory traffic: the bound for any
    parallel run at this moment on a shared machine)."""
    import concurrent.futures as cf
    import multiprocessing

    with cf.ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn")) as ex:
        list(ex.map(_spin, [1000] * workers))  # workers started
        t0 = time.perf_counter()
        _spin(n)
        one = time.perf_counter() - t0
        t0 = time.perf_counter()
        list(ex.map(_spin, [n] * workers))
        many = time.perf_counter() - t0
    return workers * one / many


def _metrics(records) -> list[str]:
    return [json.dumps(r["result"]["metrics"], sort_keys=True) if r["status"] == "ok" else "failed" for r in records]


def _start_ray(workers: int, wall: dict) -> bool:
    """Ray started for the campaign (its start counted in Ray's wall time) unless it runs already;
    returns whether this call started it."""
    import logging

    import ray

    if ray.is_initialized():
        return False
    t0 = time.perf_counter()
    ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False, logging_level=logging.WARNING)
    wall["ray"] += time.perf_counter() - t0  # the instance's start is part of Ray's cost
    return True


def _run_rounds(rounds: list, names: list[str], workers: int, wall: dict, cpu: dict, load: dict,
                records: dict) -> None:
    """Each round run by every executor, the order alternating round by round; wall time, task CPU,
    load and records accumulated per executor."""
    with tempfile.TemporaryDirectory(prefix="azimut-bench-campaign-") as tmp:
        for k, chunk in enumerate(rounds):
            order = names if k % 2 == 0 else names[::-1]
            for name in order:
                t0 = time.perf_counter()
                recs = run_tasks(chunk, os.path.join(tmp, f"{name}-{k}"), executor=name,
                                 workers=1 if name == "serial" else workers)
                wall[name] += time.perf_counter() - t0
                cpu[name] += sum(r.get("cpu_s", 0.0) for r in recs)
                load[name].append(os.getloadavg()[0])
                records[name] += recs
            print(f"round {k + 1}/{len(rounds)}: " + ", ".join(f"{nm} {wall[nm]:.1f} s" for nm in names)
                  + " (cumulative)", flush=True)


def _ideal_wall(rounds: list, serial: list[dict], workers: int) -> float:
    """The best a parallel run could do, from the serial task times: per round, the longer of the
    longest task and the round's work shared by the workers."""
    ideal = 0.0
    for chunk in rounds:
        ids = {t.id for t in chunk}
        times = [r.get("elapsed_s", 0.0) for r in serial if r["id"] in ids]
        ideal += max(max(times), sum(times) / workers)
    return ideal


def _print_table(names: list[str], workers: int, n: int, wall: dict, cpu: dict, load: dict, records: dict,
                 ideal: float, headroom: list[float], failed: int) -> None:
    """The results: one row per executor (wall, speed-up, CPU, load, identical metrics), the ideal
    and the machine's headroom."""
    print()
    print(f"{'executor':<10} {'workers':>7} {'wall [s]':>9} {'episodes/s':>11} {'speed-up':>9} {'task CPU [s]':>13} "
          f"{'cores used':>11} {'load avg':>9}  identical metrics")
    for name in names:
        same = _metrics(records[name]) == _metrics(records["serial"])
        w = 1 if name == "serial" else workers
        print(f"{name:<10} {w:>7} {wall[name]:>9.1f} {n / wall[name]:>11.3f} {wall['serial'] / wall[name]:>8.2f}x "
              f"{cpu[name]:>13.1f} {cpu[name] / wall[name]:>11.2f} {sum(load[name]) / len(load[name]):>9.1f}  "
              f"{'yes' if same else 'NO'}")
    print(f"ideal on {workers} workers from the serial task times (longest task or work / workers, per round): "
          f"{ideal:.1f} s, {wall['serial'] / ideal:.2f}x; longest episode "
          f"{max(r.get('elapsed_s', 0) for r in records['serial']):.1f} s")
    print(f"machine headroom ({workers} pure-Python loops against 1, same moment): {headroom[0]:.2f}x before, "
          f"{headroom[1]:.2f}x after the campaign")
    print(f"(speed-up: serial wall time / wall time, same run; task CPU: the episodes' CPU time summed; cores used: "
          f"task CPU / wall, what the run got of the machine; load avg: 1-min load average after each round; "
          f"bar 1.7x for 2 workers on 2 cores; {failed} episodes failed)")


def run(args: argparse.Namespace) -> int:
    """The benchmark (module docstring): rounds of episodes by every executor, then the table."""
    tasks = episode_tasks(args.controllers, args.tracks, args.seeds, max_time=args.max_time)
    n = len(tasks)
    names = ["serial"] + [resolve_executor(ex, args.workers, None) for ex in args.executors]
    k = args.seeds_per_round or len(args.seeds)
    groups = [args.seeds[i:i + k] for i in range(0, len(args.seeds), k)]
    rounds = [[t for t in tasks if t.key["seed"] in group] for group in groups]
    print(f"campaign: {len(args.controllers)} controllers x {len(args.tracks)} tracks x {len(args.seeds)} seeds = "
          f"{n} episodes" + (f", at most {args.max_time} s each" if args.max_time else ", full length")
          + f"; {os.cpu_count()} CPUs; load average {os.getloadavg()[0]:.1f}", flush=True)
    print(f"{len(rounds)} round(s) of {len(rounds[0])} episodes, each run by " + ", then ".join(names)
          + " (alternating the order), so that the load of a shared machine falls on all alike", flush=True)
    headroom = [machine_headroom(args.workers)]
    print(f"machine headroom now: {args.workers} processes of a pure-Python loop run {headroom[0]:.2f}x faster than 1",
          flush=True)
    for controller in args.controllers:  # warm-up: numba kernels loaded before the serial clock starts
        episode_task(controller, "circle", 0, max_time=0.2)
    wall = dict.fromkeys(names, 0.0)
    cpu = dict.fromkeys(names, 0.0)
    load: dict[str, list[float]] = {k: [] for k in names}
    records: dict[str, list] = {k: [] for k in names}
    ray_started = _start_ray(args.workers, wall) if "ray" in names else False
    try:
        _run_rounds(rounds, names, args.workers, wall, cpu, load, records)
    finally:
        if ray_started:
            import ray

            ray.shutdown()
    headroom.append(machine_headroom(args.workers))
    ideal = _ideal_wall(rounds, records["serial"], args.workers)
    key = {t.id: i for i, t in enumerate(tasks)}
    for name in names:
        records[name].sort(key=lambda r: key[r["id"]])
    failed = sum(r["status"] != "ok" for r in records["serial"])
    _print_table(names, args.workers, n, wall, cpu, load, records, ideal, headroom, failed)
    ok = all(_metrics(records[nm]) == _metrics(records["serial"]) for nm in names)
    return 0 if ok and failed == 0 else 1
