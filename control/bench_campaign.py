"""``azimut bench-campaign``: the same ``azimut eval`` campaign run serially and on N workers in
one run, with the wall times, the speed-up and a check that every episode's metrics are
bit-identical.

Default: 2 controllers × 6 tracks × 4 seeds (48 full episodes, no plots), serial in this process
against ``--workers 2`` (Ray when installed, else local processes). The serial run goes first,
after one short warm-up episode per controller so that it does not pay for loading the numba
kernels; the parallel runs include everything they cost (starting workers, imports, Ray).
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time

from azimut_env.tracks import TRACK_NAMES

from .campaign import EXECUTORS, arg_seeds, resolve_executor, run_tasks
from .evaluate import CONTROLLERS, DEFAULT_TRACKS
from .eval_campaign import episode_task, episode_tasks

__all__ = ["add_arguments", "check_args", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from azimut_env.validation import arg_choice_list, arg_float, arg_int

    parser.add_argument("--controllers", type=arg_choice_list(CONTROLLERS), default=list(CONTROLLERS),
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


def check_args(args: argparse.Namespace) -> None:
    for ex in args.executors:
        resolve_executor(ex, args.workers, None)


def _metrics(records) -> list[str]:
    return [json.dumps(r["result"]["metrics"], sort_keys=True) if r["status"] == "ok" else "failed" for r in records]


def run(args: argparse.Namespace) -> int:
    tasks = episode_tasks(args.controllers, args.tracks, args.seeds, max_time=args.max_time)
    n = len(tasks)
    print(f"campaign: {len(args.controllers)} controllers x {len(args.tracks)} tracks x {len(args.seeds)} seeds = "
          f"{n} episodes" + (f", at most {args.max_time} s each" if args.max_time else ", full length")
          + f"; {os.cpu_count()} CPUs", flush=True)
    for controller in args.controllers:  # warm-up: numba kernels loaded before the serial clock starts
        episode_task(controller, "circle", 0, max_time=0.2)
    results = []
    with tempfile.TemporaryDirectory(prefix="azimut-bench-campaign-") as tmp:
        t0 = time.perf_counter()
        serial = run_tasks(tasks, os.path.join(tmp, "serial"), executor="serial")
        t_serial = time.perf_counter() - t0
        busy = sum(r.get("elapsed_s", 0.0) for r in serial)
        results.append(("serial", 1, t_serial, busy, True))
        print(f"serial: {t_serial:.1f} s", flush=True)
        for ex in args.executors:
            name = resolve_executor(ex, args.workers, None)
            t0 = time.perf_counter()
            par = run_tasks(tasks, os.path.join(tmp, name), executor=name, workers=args.workers)
            t_par = time.perf_counter() - t0
            same = _metrics(par) == _metrics(serial)
            results.append((name, args.workers, t_par, sum(r.get("elapsed_s", 0.0) for r in par), same))
            print(f"{name} x{args.workers}: {t_par:.1f} s", flush=True)
    failed = sum(r["status"] != "ok" for r in serial)
    print()
    print(f"{'executor':<10} {'workers':>7} {'wall [s]':>9} {'episodes/s':>11} {'speed-up':>9} "
          f"{'task time [s]':>14}  identical metrics")
    for name, w, wall, busy, same in results:
        print(f"{name:<10} {w:>7} {wall:>9.1f} {n / wall:>11.3f} {t_serial / wall:>8.2f}x {busy:>14.1f}  "
              f"{'yes' if same else 'NO'}")
    print(f"(speed-up: serial wall time / wall time, same run; task time: the episodes' own run times summed, "
          f"which grows when workers share cores; bar 1.7x for 2 workers on 2 cores; {failed} episodes failed)")
    return 0 if all(r[4] for r in results) and failed == 0 else 1
