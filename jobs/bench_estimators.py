"""``azimut bench-estimators``: the paper's §4.1 evaluation, reproduced and extended.

For each dataset (D1, D2, D3) and each method (NE, LS, NS, IT, IT+, ORACLE) it measures the
quality qua of eq. (28)–(29) (min and mean, %), the fraction of valid unit λ, and the cost per
point, batched ((N, n) in one call) and single-call (median), with ratios to NE measured in the
same run (the paper's Fig. 12 compares instruction counts; we compare wall-clock ratios).
A robustness sweep runs every practical method on random, singular, parallel and at-the-stops
inputs.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from dataclasses import asdict

import numpy as np

from estimation.datasets import dataset_d1, dataset_d2, dataset_d3, load_d2_recorded
from estimation.estimate import IT_BEST, estimate_icr, estimate_icr_it
from estimation.geometry import AZIMUT3_ASSUMPTIONS, RobotGeometry
from estimation.it import ITParams
from estimation.kinematics import steering_from_lambda
from estimation.quality import quality

__all__ = ["run_benchmark", "robustness_inputs", "order_stats", "FIG11_PAIRS", "add_arguments", "run"]

METHOD_ORDER = ("IT", "IT+", "NE", "LS", "NS", "ORACLE")
#: The paper's Table 1 (D3): (min %, mean %).
PAPER_TABLE1 = {"IT": (32.47, 67.18), "NE": (15.56, 49.94), "LS": (12.04, 47.24), "NS": (12.21, 48.02)}


#: The paper's Fig. 11 order on D2 (§4.1.1): IT gives "always the same or a better quality" than NS;
#: NS ahead of LS, which "performs well only when the propulsion axes are not closely parallel".
FIG11_PAIRS = (("IT", "NS"), ("NS", "LS"))
#: qua [points of 100] below which two estimates count as equal (rounding of the same optimum)
ORDER_TOL = 1e-9


def order_stats(qua_a: np.ndarray, qua_b: np.ndarray, margin: float = 0.1, tol: float = ORDER_TOL) -> dict:
    """How method a ranks against method b on the same points, from their qua (N,) [points of 100]:
    ``differ`` (points where |a − b| > ``tol``), ``a_at_least_b`` (share of those where a ≥ b),
    ``worst`` (min of a − b; negative where b was better), ``a_over_b_margin`` (share of all
    points where a > b + ``margin``: the paper's "visible" separation, 0.1 point by default)."""
    a = np.asarray(qua_a, dtype=np.float64)
    b = np.asarray(qua_b, dtype=np.float64)
    if a.shape != b.shape or a.ndim != 1 or a.size == 0:
        raise ValueError(f"qua_a and qua_b must be non-empty (N,) arrays of one shape, got {a.shape} and {b.shape}")
    diff = a - b
    differ = np.abs(diff) > tol
    return {"points": int(a.size), "differ": int(differ.sum()),
            "a_at_least_b": float(np.mean(diff[differ] > 0)) if differ.any() else 1.0,
            "worst": float(diff.min()), "a_over_b_margin": float(np.mean(diff > margin))}


def _quality_of(lam: np.ndarray, q: np.ndarray, geom: RobotGeometry) -> np.ndarray:
    """qua of the estimate; a wheel whose axis holds λ̂ may take any angle, so it takes q_k."""
    return quality(steering_from_lambda(lam, geom, singular_fill=q), q)


def _valid_unit(lam: np.ndarray) -> np.ndarray:
    return np.all(np.isfinite(lam), axis=-1) & (np.abs(np.linalg.norm(lam, axis=-1) - 1) < 1e-9)


def _time_batch(fns: dict, q: np.ndarray, rounds: int) -> dict[str, float]:
    """Best time per point [s] of each method over ``rounds`` rounds. Methods are interleaved
    within each round so that a change in machine load hits all of them alike, keeping the
    ratios between methods fair on a noisy machine."""
    best = {m: np.inf for m in fns}
    for r in range(rounds):
        for m, fn in fns.items():
            if m == "ORACLE" and r > 0:
                continue  # the yardstick is slow; one round is enough
            t0 = time.perf_counter()
            fn(q)
            best[m] = min(best[m], time.perf_counter() - t0)
    return {m: t / len(q) for m, t in best.items()}


def _time_single(fns: dict, q: np.ndarray, calls: int) -> dict[str, float]:
    """Median time [s] of one single-point call of each method, in interleaved blocks of 50 calls.
    ORACLE (slow, and its grid flushes the caches) is timed apart, on a few calls."""
    times = {m: [] for m in fns}
    fast = [m for m in fns if m != "ORACLE"]
    for start in range(0, calls, 50):
        for m in fast:
            fn = fns[m]
            for i in range(start, min(calls, start + 50)):
                x = q[i % len(q)]
                t0 = time.perf_counter()
                fn(x)
                times[m].append(time.perf_counter() - t0)
    if "ORACLE" in fns:
        for i in range(max(5, calls // 100)):
            t0 = time.perf_counter()
            fns["ORACLE"](q[i % len(q)])
            times["ORACLE"].append(time.perf_counter() - t0)
    return {m: float(np.median(v)) for m, v in times.items()}


def robustness_inputs(geom: RobotGeometry, n_random: int, seed: int = 7) -> dict[str, np.ndarray]:
    """Adversarial inputs: random angles (also far outside the range), exact singular inputs
    (the ICR on each steering axis, with the singular wheel at every angle), all-parallel
    axes, and every wheel at a stop."""
    rng = np.random.default_rng(seed)
    out = {}
    out["random"] = np.concatenate([
        rng.uniform(geom.steer_min, geom.steer_max, size=(n_random // 2, geom.n)),
        rng.uniform(-50.0, 50.0, size=(n_random - n_random // 2, geom.n)),
    ])
    sing = []
    for k in range(geom.n):
        beta = steering_from_lambda(geom.s_unit[k], geom)
        for free in np.linspace(geom.steer_min, geom.steer_max, 181):
            b = beta.copy()
            b[k] = free
            sing.append(b)
    out["singular"] = np.asarray(sing)
    gammas = np.linspace(-np.pi, np.pi, 721)
    out["parallel"] = geom.wrap_steering(gammas[:, None] - geom.alpha[None, :])
    corners = np.array(np.meshgrid(*[[geom.steer_max, geom.steer_min + 1e-15, 0.0]] * geom.n)).reshape(geom.n, -1).T
    out["stops"] = np.ascontiguousarray(corners)
    return out


def _method_row(m: str, fn, q: np.ndarray, geom: RobotGeometry, batched_s: float, single_s: float) -> dict:
    """One method's row on one dataset: quality (min, mean), valid unit λ̂, the times per point, and
    IT's iterations, starts and convergence; ``_qua`` holds the per-point quality."""
    lam = fn(q)
    qua = _quality_of(lam, q, geom) * 100
    row = {
        "qua_min": float(qua.min()), "qua_mean": float(qua.mean()),
        "valid_unit": float(_valid_unit(lam).mean()),
        "batched_us": 1e6 * batched_s, "single_us": 1e6 * single_s,
    }
    if m in ("IT", "IT+"):
        _, diag = estimate_icr_it(q, geom, ITParams() if m == "IT" else IT_BEST, diagnostics=True)
        row["iterations_mean"] = float(diag.iterations.mean())
        row["starts_mean"] = float(diag.starts_tried.mean())
        row["converged"] = float(diag.converged.mean())
    row["_qua"] = qua
    return row


def _dataset_result(q: np.ndarray, fns: dict, methods, geom: RobotGeometry, repeat: int, single_calls: int) -> dict:
    """Every method on one dataset: its row (:func:`_method_row`) with the ratios to NE and the gap
    to ORACLE, how often IT is at least as good, and the Fig. 11 order statistics."""
    batched = _time_batch(fns, q, repeat)
    single = _time_single(fns, q, single_calls)
    table = {m: _method_row(m, fns[m], q, geom, batched[m], single[m]) for m in methods}
    ne_b, ne_s = table["NE"]["batched_us"], table["NE"]["single_us"]
    for row in table.values():
        row["batched_vs_NE"] = row["batched_us"] / ne_b
        row["single_vs_NE"] = row["single_us"] / ne_s
        row["points_per_s"] = 1e6 / row["batched_us"]
        if "ORACLE" in table:
            row["gap_to_oracle_mean"] = table["ORACLE"]["qua_mean"] - row["qua_mean"]
    if "IT" in table and "IT+" in table:
        table["IT+"]["cost_vs_IT"] = table["IT+"]["batched_us"] / table["IT"]["batched_us"]
    # per-point dominance: is IT at least as good as each other method at every point?
    dom = {}
    for m in methods if "IT" in table else ():
        if m not in ("IT", "ORACLE"):
            dom[m] = float(np.mean(table["IT"]["_qua"] >= table[m]["_qua"] - 1e-9))
    order = {f"{a}>={b}": order_stats(table[a]["_qua"], table[b]["_qua"]) for a, b in FIG11_PAIRS
             if a in table and b in table}
    for row in table.values():
        row.pop("_qua")
    return {"n_points": len(q), "methods": table, "IT_at_least_as_good_fraction": dom, "fig11_order": order}


#: the methods that run over blocks of samples on several threads (estimation.estimate)
THREADED_METHODS = ("IT", "IT+", "ORACLE")


def thread_scaling(datasets: dict[str, np.ndarray], geom: RobotGeometry, methods, threads: list[int],
                   repeat: int) -> dict:
    """Per dataset and threaded method: points/s at each thread count (the best of ``repeat``
    rounds, the counts alternated within a round; ORACLE on its first 2,000 points), the ratio
    to the first count, and whether every count gave the same λ̂ bits."""
    out: dict = {}
    for name, q in datasets.items():
        for m in (m for m in THREADED_METHODS if m in methods):
            x = q[:2000] if m == "ORACLE" else q
            best = {t: np.inf for t in threads}
            lams = {}
            for t in threads:  # first calls: the parallel twins load (or compile) outside the timing
                estimate_icr(x[:200], geom, m, num_threads=t)
            for r in range(1 if m == "ORACLE" else repeat):
                for t in (threads if r % 2 == 0 else threads[::-1]):
                    t0 = time.perf_counter()
                    lams[t] = estimate_icr(x, geom, m, num_threads=t)
                    best[t] = min(best[t], time.perf_counter() - t0)
            rate = {t: len(x) / best[t] for t in threads}
            out[f"{name} {m}"] = {"points": len(x), "points_per_s": rate,
                                  "ratio": {t: rate[t] / rate[threads[0]] for t in threads},
                                  "same_bits": all(np.array_equal(lams[threads[0]], v) for v in lams.values())}
    return out


def _scaling_lines(res: dict) -> list[str]:
    scale = res.get("thread_scaling")
    if not scale:
        return []
    threads = res["threads"]
    lines = ["", f"## Thread scaling: points/s at {', '.join(map(str, threads))} threads (best of the rounds, "
             "counts alternated), × the first count", "",
             "| dataset, method | points | " + " | ".join(f"{t} thr points/s | ×" for t in threads) + " | same bits |",
             "|---|---:|" + "---:|---:|" * len(threads) + "---|"]
    for key, r in scale.items():
        cells = " | ".join(f"{r['points_per_s'][t]:,.0f} | {r['ratio'][t]:.2f}" for t in threads)
        lines.append(f"| {key} | {r['points']} | {cells} | {'yes' if r['same_bits'] else 'NO'} |")
    return lines


def run_benchmark(geom: RobotGeometry, n_points: int = 15000, n_random: int = 1_000_000, seed: int = 0,
                  single_calls: int = 2000, repeat: int = 7, d2_source: str = "auto",
                  methods: tuple[str, ...] = METHOD_ORDER, log=print, threads: list[int] | None = None) -> dict:
    """Run the whole evaluation and return a JSON-ready dict. ``threads``: the thread counts of
    the scaling section (the tables use the first; default: 1 only, no scaling section)."""
    threads = list(threads or [1])
    q1, _ = dataset_d1(geom, n_points, seed=seed + 1)
    q2, d2_src = dataset_d2(geom, source=d2_source, seed=seed + 2)
    q3 = dataset_d3(geom, n_points, seed=seed + 3)
    datasets = {"D1": q1, "D2": q2, "D3": q3}
    fns = {m: (lambda x, m=m: estimate_icr(x, geom, m, num_threads=threads[0])) for m in methods}

    # first call of each method: numba compilation, or loading it from the on-disk cache
    first_call = {}
    for m in methods:
        t0 = time.perf_counter()
        fns[m](q3[:2])
        first_call[m] = time.perf_counter() - t0

    results: dict = {
        "robot": {"n": geom.n, "alpha_deg": np.rad2deg(geom.alpha).tolist(), "l_m": geom.l.tolist(),
                  "b_m": geom.b.tolist(), "note": AZIMUT3_ASSUMPTIONS["note"]},
        "it_params": asdict(ITParams()), "it_plus_params": asdict(IT_BEST),
        "d2_source": d2_src, "machine": platform.processor() or platform.machine(),
        "python": sys.version.split()[0], "first_call_s": first_call, "datasets": {}, "threads": threads,
    }
    for name, q in datasets.items():
        log(f"[{name}] {len(q)} points ...")
        results["datasets"][name] = _dataset_result(q, fns, methods, geom, repeat, single_calls)

    log(f"[robustness] {n_random} random inputs plus singular, parallel and at-the-stops inputs ...")
    rob = {}
    inputs = robustness_inputs(geom, n_random)
    for m in methods:
        if m == "ORACLE":
            continue
        rob[m] = {k: float(_valid_unit(fns[m](v)).mean()) for k, v in inputs.items()}
    rob["n_inputs"] = {k: len(v) for k, v in inputs.items()}
    results["robustness_valid_unit"] = rob
    if len(threads) > 1:
        log(f"[threads] {', '.join(map(str, threads))} ...")
        results["thread_scaling"] = thread_scaling(datasets, geom, methods, threads, repeat)
    return results


def format_report(res: dict) -> str:
    lines = []
    lines.append(f"Robot: n = {res['robot']['n']}, α = {res['robot']['alpha_deg']} deg, l = {res['robot']['l_m'][0]} m "
                 f"(assumed: {res['robot']['note']})")
    lines.append(f"D2 source: {res['d2_source']}.  First call (numba compile or cache load), s: "
                 + ", ".join(f"{m} {t:.2f}" for m, t in res["first_call_s"].items()))
    for name, ds in res["datasets"].items():
        lines.append("")
        lines.append(f"## {name} ({ds['n_points']} points)")
        lines.append("")
        lines.append("| method | qua min % | qua mean % | gap to ORACLE | valid unit λ | batched µs/pt | points/s | "
                     "× NE | single µs | × NE |")
        lines.append("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
        for m, r in ds["methods"].items():
            gap = r.get("gap_to_oracle_mean", float("nan"))
            lines.append(f"| {m} | {r['qua_min']:.2f} | {r['qua_mean']:.2f} | {gap:.3f} | "
                         f"{100 * r['valid_unit']:.2f}% | "
                         f"{r['batched_us']:.2f} | {r['points_per_s']:,.0f} | {r['batched_vs_NE']:.1f} | "
                         f"{r['single_us']:.1f} | {r['single_vs_NE']:.2f} |")
        extra = []
        for m in ("IT", "IT+"):
            if m in ds["methods"]:
                r = ds["methods"][m]
                extra.append(f"{m}: {r['iterations_mean']:.1f} iterations, {r['starts_mean']:.2f} starts, "
                             f"{100 * r['converged']:.1f}% converged")
        if "IT+" in ds["methods"]:
            extra.append(f"IT+ cost / IT cost = {ds['methods']['IT+']['cost_vs_IT']:.2f}")
        if ds["IT_at_least_as_good_fraction"]:
            extra.append("IT ≥ other method at every point: " + ", ".join(
                f"{m} {100 * v:.2f}%" for m, v in ds["IT_at_least_as_good_fraction"].items()))
        for pair, o in ds.get("fig11_order", {}).items():
            a, b = pair.split(">=")
            extra.append(f"{a} ≥ {b} at {100 * o['a_at_least_b']:.2f}% of the {o['differ']} points where they differ "
                         f"(worst {a} − {b} = {o['worst']:+.4f} point); {a} > {b} + 0.1 point on "
                         f"{100 * o['a_over_b_margin']:.2f}% of all points")
        lines.append("")
        lines.extend(extra)
        if name == "D3":
            lines.append("Paper Table 1 (min/mean %): " + ", ".join(
                f"{m} {a:.2f}/{b:.2f}" for m, (a, b) in PAPER_TABLE1.items()))
            lines.append("Ours minus paper (mean): " + ", ".join(
                f"{m} {ds['methods'][m]['qua_mean'] - b:+.2f}" for m, (_, b) in PAPER_TABLE1.items()
                if m in ds["methods"]))
    lines.append("")
    lines.append("## Robustness: fraction of finite unit λ")
    rob = res["robustness_valid_unit"]
    cats = list(rob["n_inputs"])
    lines.append("")
    lines.append("| method | " + " | ".join(f"{c} ({rob['n_inputs'][c]:,})" for c in cats) + " |")
    lines.append("|---|" + "---:|" * len(cats))
    for m, r in rob.items():
        if m == "n_inputs":
            continue
        lines.append(f"| {m} | " + " | ".join(f"{100 * r[c]:.4f}%" for c in cats) + " |")
    lines.extend(_scaling_lines(res))
    return "\n".join(lines)


def _default_threads() -> list[int]:
    from estimation.threads import default_threads

    cores = default_threads()
    return [1, cores] if cores > 1 else [1]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from jobs.args import arg_choice_list, arg_int, arg_output_path, arg_threads_list

    parser.add_argument("--json", metavar="PATH", type=arg_output_path(), help="also write the results as JSON")
    parser.add_argument("--points", type=arg_int(10, 10_000_000), default=15000,
                        help="points in D1 and D3 (paper: 15000)")
    parser.add_argument("--random", type=arg_int(2, 100_000_000), default=1_000_000,
                        help="random inputs of the robustness sweep")
    parser.add_argument("--seed", type=arg_int(0, 2**32 - 1), default=0, help="dataset seed offset")
    parser.add_argument("--single-calls", type=arg_int(1, 10_000_000), default=2000,
                        help="single calls timed per method")
    parser.add_argument("--d2", choices=["auto", "recorded", "standin"], default="auto", help="D2 source")
    parser.add_argument("--methods", default=",".join(METHOD_ORDER), type=arg_choice_list(METHOD_ORDER),
                        help=f"comma-separated subset of {','.join(METHOD_ORDER)} (NE is required: the timing "
                             "ratios are against it)")
    parser.add_argument("--threads", type=arg_threads_list, default=None, metavar="N[,N...]",
                        help="thread counts: the tables at the first, a scaling section of IT, IT+ and ORACLE at all "
                             "(default: 1 and the cores this process may use)")


def check_args(args: argparse.Namespace) -> None:
    if "NE" not in args.methods:
        raise ValueError(f"argument --methods: must include NE (the timing ratios are against it), "
                         f"got {','.join(args.methods)}")
    if args.d2 == "recorded" and load_d2_recorded(RobotGeometry.azimut3()) is None:
        raise ValueError("argument --d2: no recorded D2 in this install (run azimut record-d2, or use auto/standin)")


def run(args: argparse.Namespace) -> int:
    methods = tuple(args.methods)
    geom = RobotGeometry.azimut3()
    res = run_benchmark(geom, n_points=args.points, n_random=args.random, seed=args.seed,
                        single_calls=args.single_calls, d2_source=args.d2, methods=methods,
                        log=lambda s: print(s, file=sys.stderr), threads=args.threads or _default_threads())
    print(format_report(res))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(res, fh, indent=2)
        print(f"\nwrote {args.json}")
    return 0
