"""``azimut bench-env --baseline DIR``: the user-facing jobs timed against another checkout, alternated.

The speed goals that matter to users are whole commands: ``azimut eval``'s default campaign and
``azimut train --action residual``. They can only be compared with an earlier version of the
code, so this runs the same command line with this checkout and with ``DIR`` (a checkout of an
earlier commit, e.g. ``git worktree add /tmp/base <commit>``), each in a fresh Python process
(``PYTHONPATH`` set to the checkout), alternating the two ``--repeats`` times, so that a shared
machine's drifting load falls on both. Per run it records the load average, the wall time and
the child's CPU time (user + system); per job it prints the ratios baseline / this checkout of
the medians. ``azimut eval``'s per-episode metrics must be identical between the two (a
changed figure is reported, not hidden); ``azimut train``'s env steps/s is the one it prints
("steps/s inside learn"). Each checkout compiles its numba kernels into its own cache on its
first run: a warm-up run of each is done first and not counted (``--cold`` times it instead).

:func:`reference_steps_per_s` times a Gymnasium env as the yardstick of ``azimut bench-env``'s
single env.
"""

from __future__ import annotations

import json
import math
import os
import re
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

__all__ = ["reference_steps_per_s", "load_average", "check_baseline", "time_command", "compare_eval_metrics",
           "run_baseline_bench"]

#: the jobs compared: name -> azimut arguments (OUT is replaced by a run folder)
JOBS = {
    "eval": ["eval", "--no-plots", "--out", "OUT"],
    "train": ["train", "--action", "residual", "--steps", "STEPS", "--eval-every", "0", "--checkpoint-every", "0",
              "--quiet", "--out", "OUT"],
}
_TIMING_KEYS = {"elapsed_s", "wall_s", "cpu_s", "time_s", "worker", "attempts"}


def check_baseline(path: str) -> Path:
    """The baseline checkout's folder, refused (``ValueError``, one line) if it holds no azimut."""
    root = Path(path).expanduser().resolve()
    if not (root / "jobs" / "cli.py").is_file():
        raise ValueError(f"argument --baseline: {path!r} is not a checkout of azimut (no jobs/cli.py there)")
    return root


def reference_steps_per_s(env_id: str = "Pendulum-v1", steps: int = 5000, seed: int = 0, with_cpu: bool = False):
    """Steps/s of a Gymnasium reference env measured in the same run (a yardstick for the
    machine's speed at that moment: compare ratios, not absolute figures, on a shared machine).
    ``with_cpu``: (wall steps/s, CPU-time steps/s)."""
    import gymnasium as gym

    env = gym.make(env_id).unwrapped
    env.reset(seed=seed)
    env.action_space.seed(seed)
    actions = [env.action_space.sample() for _ in range(steps)]
    t0, c0 = time.perf_counter(), time.process_time()
    for a in actions:
        _, _, term, trunc, _ = env.step(a)
        if term or trunc:
            env.reset()
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return (steps / wall, steps / cpu) if with_cpu else steps / wall


def load_average() -> str:
    """The 1, 5 and 15 min load averages, as printed."""
    try:
        return " ".join(f"{x:.1f}" for x in os.getloadavg())
    except OSError:
        return "n/a"


def time_command(root: Path, args: list[str]) -> dict:
    """Run ``python -m jobs.cli ARGS`` with ``root`` first on the path; its wall and CPU time [s],
    the load average before it, and its output."""
    env = dict(os.environ, PYTHONPATH=str(root))
    load = load_average()
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "jobs.cli", *args], cwd=root, env=env, capture_output=True,
                          text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if proc.returncode != 0:
        tail = (proc.stderr or proc.stdout).strip().splitlines()[-1:] or [""]
        raise RuntimeError(f"{' '.join(args[:1])} in {root} exited {proc.returncode}: {tail[0]}")
    return {"wall_s": wall, "cpu_s": cpu, "load": load, "stdout": proc.stdout}


def compare_eval_metrics(a: Path, b: Path) -> list[str]:
    """The per-episode metrics of two ``azimut eval`` folders that differ (timings aside)."""
    def rows(folder: Path) -> dict:
        data = json.loads((folder / "metrics.json").read_text())
        return {(r.get("controller"), r.get("track"), r.get("seed")): r for r in data["episodes"]}

    ra, rb = rows(a), rows(b)
    out = [f"episodes {sorted(set(ra) ^ set(rb))} in one run only"] if set(ra) != set(rb) else []
    for key in sorted(set(ra) & set(rb), key=str):
        for name in sorted(set(ra[key]) | set(rb[key])):
            if name in _TIMING_KEYS or name.endswith("elapsed_s"):
                continue
            va, vb = ra[key].get(name), rb[key].get(name)
            same = va == vb or (isinstance(va, float) and isinstance(vb, float) and math.isnan(va) and math.isnan(vb))
            if not same:
                out.append(f"{key} {name}: {va!r} vs {vb!r}")
    return out


def _median(xs: list[float]) -> float:
    s = sorted(xs)
    return s[len(s) // 2] if len(s) % 2 else 0.5 * (s[len(s) // 2 - 1] + s[len(s) // 2])


def _steps_per_s(stdout: str) -> float:
    m = re.search(r"\(([0-9.]+) steps/s inside learn\)", stdout)
    return float(m.group(1)) if m else float("nan")


def run_baseline_bench(baseline: Path, jobs: list[str], repeats: int = 2, train_steps: int = 32768,
                       cold: bool = False, stream=None) -> dict:
    """Time ``jobs`` (names of :data:`JOBS`) with the baseline and this checkout, alternated
    ``repeats`` times; print each run and the ratios. Returns the figures."""
    stream = stream if stream is not None else sys.stdout
    here = Path(__file__).resolve().parents[1]
    sides = {"baseline": baseline, "this": here}
    results: dict = {}
    with tempfile.TemporaryDirectory(prefix="azimut-bench-") as tmp:
        for job in jobs:
            print(f"{job}: azimut {' '.join(JOBS[job]).replace('STEPS', str(train_steps))} "
                  f"(baseline {baseline}, this {here})", file=stream, flush=True)
            runs: dict = {"baseline": [], "this": []}
            for k in range(0 if cold else -1, repeats):
                for side in (("baseline", "this") if k % 2 == 0 else ("this", "baseline")):
                    out = Path(tmp) / f"{job}-{side}-{k}"
                    args = [str(out) if a == "OUT" else str(train_steps) if a == "STEPS" else a for a in JOBS[job]]
                    r = time_command(sides[side], args)
                    r["out"] = out
                    r["steps_per_s"] = _steps_per_s(r["stdout"]) if job == "train" else float("nan")
                    label = "warm-up" if k < 0 else f"run {k + 1}"
                    extra = f", {r['steps_per_s']:.0f} env steps/s inside learn" if job == "train" else ""
                    print(f"  {label:<8} {side:<9} load {r['load']}: wall {r['wall_s']:7.1f} s, CPU "
                          f"{r['cpu_s']:7.1f} s{extra}", file=stream, flush=True)
                    if k >= 0:
                        runs[side].append(r)
            fig = {f"{side}_{what}": _median([r[what] for r in runs[side]]) for side in runs
                   for what in ("wall_s", "cpu_s", "steps_per_s")}
            line = (f"  {job}: this checkout {fig['baseline_wall_s'] / fig['this_wall_s']:.2f}x faster in wall time, "
                    f"{fig['baseline_cpu_s'] / fig['this_cpu_s']:.2f}x in CPU time (medians of {repeats})")
            if job == "train":
                line += f"; env steps/s {fig['this_steps_per_s'] / fig['baseline_steps_per_s']:.2f}x"
            print(line, file=stream, flush=True)
            if job == "eval":
                diff = compare_eval_metrics(runs["baseline"][0]["out"], runs["this"][0]["out"])
                fig["metric_differences"] = diff
                print("  eval metrics: " + ("identical in every episode" if not diff else
                                            f"{len(diff)} differ: " + "; ".join(diff[:5])), file=stream, flush=True)
            results[job] = fig
    return results
