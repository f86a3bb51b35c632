"""Estimate a whole log, chunk by chunk: every estimator's η̂ = (λ̂, μ̂) and qua per sample, the
dead-reckoned pose, and the comparison with a reference pose where the log has one.

Per sample, for each estimator m: ``estimate_eta(β, φ̇, geom, m)`` (λ̂, μ̂, qua of eq. (28)–(29)),
on the samples as the log gives them, so that a simulated episode's export reproduces the
simulator's own estimates bit for bit (each row of ``estimate_eta`` is independent of its batch).

Dead reckoning, as the simulator's ``pose_source="odometry"`` does it
(:mod:`azimut_env.task.localisation`): the odometry twist ``odometry_twist(λ̂, φ̇, β, β̇)`` with
β̇ the finite difference of consecutive good samples, and the exact SE(2) exponential over each
sample period (``integrate_pose``), composed in time order. It starts at the origin, or where a
reference pose exists, at the reference pose of the first sample it covers; the drift is then
the position error over the distance the reference travelled.

Moving apart from standing (:mod:`estimation.logs.motion`): per sample, the rigid-body
least-squares twist of the wheels (``twist_from_wheels_batch``, with the same β̇ as the dead
reckoning) and ``moving``, the fastest contact point of that fit at least ``moving_speed`` (default
:data:`~estimation.logs.motion.MOVING_SPEED`, 0.05 m/s). A gyro the reader gives
(:meth:`LogSource.yaw`) is interpolated at the samples (``yaw_at``).

Samples are skipped, and counted by reason, when the reader could not read them or a value is
NaN or infinite (:data:`~estimation.logs.source.BAD_REASONS`). Timestamps that are not strictly
increasing refuse the log (:class:`~estimation.logs.source.LogError`): the order of the samples,
and so every β̇ and every pose, would be a guess.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from estimation.estimate import METHODS, estimate_eta
from estimation.kinematics import integrate_pose, odometry_twist
from estimation.logs.motion import MOVING_SPEED, contact_speeds, interp_on, twist_from_wheels_batch
from estimation.logs.source import BAD_REASONS, GroundTruth, LogSource, YawTrack, mark_bad_values

__all__ = ["DEFAULT_METHODS", "LogEstimate", "estimate_log", "compose_increments", "compare_estimators",
           "odometry_drift"]

#: the estimators run by default: all but ORACLE (the exhaustive yardstick, about 100× slower)
DEFAULT_METHODS = ("IT", "IT+", "NE", "LS", "NS")


@dataclass
class LogEstimate:
    """The estimates of a log's good samples (K of them), in time order.

    Attributes:
        t_ns: (K,) timestamps [ns]; beta, phidot: (K, n) the samples (the paper's β [rad], φ̇ [rad/s]).
        methods: the estimators run; lam, mu, qua: per method, (K, 3) λ̂ (canonical sign), (K,) μ̂
            [m/s], (K,) qua. cost_s: per method, the seconds its ``estimate_eta`` calls took.
        odometry_method: the estimator whose λ̂ drives the dead reckoning; odom_twist: (K, 3)
            (ẋ, ẏ, θ̇) [m/s, m/s, rad/s]; pose: (K, 3) the dead-reckoned (x, y, θ).
        out_of_range: (K,) a steering angle outside the robot's range ]β_min, β_max] (limited
            steering, b_k ≠ 0: the estimators wrap it, β and β + π being the same axis).
        n_read: samples read, skipped ones included; skipped: reason -> count.
        truth: the reference pose, if any; truth_at: (K, 3) it interpolated at the samples (NaN
            outside its time span); aligned_at: the first sample it covers (where dead reckoning
            starts from it), or None.
        source: what the reader says it read (:meth:`LogSource.describe`).
        rigid_twist: (K, 3) the wheels' rigid-body least-squares twist (ẋ, ẏ, θ̇) (no ICR estimate:
            :func:`~estimation.logs.motion.twist_from_wheels_batch`); rigid_residual: (K,) its
            residual [m/s]; contact_speed: (K,) its fastest contact point's speed [m/s]; moving:
            (K,) ``contact_speed >= moving_speed`` [m/s].
        yaw: the gyro's heading, if the reader gives one; yaw_at: (K,) it interpolated at the
            samples [rad] (NaN outside its time span), None without a gyro.
    """

    t_ns: np.ndarray
    beta: np.ndarray
    phidot: np.ndarray
    methods: tuple[str, ...]
    lam: dict[str, np.ndarray]
    mu: dict[str, np.ndarray]
    qua: dict[str, np.ndarray]
    cost_s: dict[str, float]
    odometry_method: str
    odom_twist: np.ndarray
    pose: np.ndarray
    out_of_range: np.ndarray
    n_read: int
    skipped: dict[str, int]
    truth: GroundTruth | None = None
    truth_at: np.ndarray | None = None
    aligned_at: int | None = None
    source: dict = field(default_factory=dict)
    rigid_twist: np.ndarray | None = None
    rigid_residual: np.ndarray | None = None
    contact_speed: np.ndarray | None = None
    moving: np.ndarray | None = None
    moving_speed: float = MOVING_SPEED
    yaw: YawTrack | None = None
    yaw_at: np.ndarray | None = None

    @property
    def t_s(self) -> np.ndarray:
        """(K,) time since the first good sample [s]."""
        return (self.t_ns - self.t_ns[0]) * 1e-9 if self.t_ns.size else np.zeros(0)


@njit(cache=True)
def _compose_kernel(start, inc, out):
    x, y, th = start[0], start[1], start[2]
    for k in range(inc.shape[0]):
        c, s = math.cos(th), math.sin(th)
        x = x + (c * inc[k, 0] - s * inc[k, 1])
        y = y + (s * inc[k, 0] + c * inc[k, 1])
        th = th + inc[k, 2]
        out[k, 0], out[k, 1], out[k, 2] = x, y, th


def compose_increments(start: np.ndarray, inc: np.ndarray) -> np.ndarray:
    """Poses (K, 3) after each of the chassis-frame increments ``inc`` (K, 3) (dx, dy, dθ), applied
    in order from ``start`` (3,): (x, y)_k = (x, y)_{k−1} + R(θ_{k−1}) (dx, dy)_k, θ_k = θ_{k−1} + dθ_k
    (the composition of SE(2) motions; ``integrate_pose`` from the origin gives the increments).
    One pass in order, so that composing a path in pieces gives the same bits as in one go."""
    inc = np.ascontiguousarray(inc, dtype=np.float64)
    out = np.empty_like(inc)
    _compose_kernel(np.asarray(start, dtype=np.float64), inc, out)
    return out


class _Odometry:
    """Dead reckoning carried across chunks: the last good sample's β, time and pose."""

    def __init__(self, geom) -> None:
        self.geom = geom
        self.beta_prev: np.ndarray | None = None
        self.t_prev = 0
        self.pose = np.zeros(3)

    def advance(self, t_ns, beta, phidot, lam) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The odometry twists, the poses and the β̇ used, of the chunk's samples."""
        if t_ns.size == 0:
            return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, self.geom.n))
        first = self.beta_prev is None
        beta_prev = np.concatenate([beta[:1] if first else self.beta_prev[None], beta[:-1]])
        t_prev = np.concatenate([[t_ns[0] if first else self.t_prev], t_ns[:-1]])
        dt = (t_ns - t_prev) * 1e-9
        with np.errstate(invalid="ignore", divide="ignore"):
            beta_rate = np.where(dt[:, None] > 0, (beta - beta_prev) / np.where(dt > 0, dt, 1.0)[:, None], 0.0)
        twist = odometry_twist(lam, phidot, beta, beta_rate, self.geom)
        inc = integrate_pose(np.zeros_like(twist), twist, dt)
        poses = compose_increments(self.pose, inc)
        self.beta_prev, self.t_prev, self.pose = beta[-1].copy(), int(t_ns[-1]), poses[-1].copy()
        return twist, poses, beta_rate


def _check_time(t_ns: np.ndarray, last: int | None, offset: int, source: LogSource) -> None:
    """Strictly increasing timestamps, across chunks too; else a LogError naming the sample."""
    full = t_ns if last is None else np.concatenate([[last], t_ns])
    step = np.diff(full)
    if step.size and step.min() <= 0:
        j = int(np.flatnonzero(step <= 0)[0])
        k = offset + j + (0 if last is None else -1) + 1
        what = "duplicated" if step[j] == 0 else "not increasing"
        raise source.error(f"timestamps {what} at sample {k} (t = {full[j + 1]} ns after {full[j]} ns); "
                           "samples must be in strictly increasing time order")


def _check_estimate_args(methods, odometry_method, chunk_size, moving_speed) -> tuple[tuple, str]:
    """:func:`estimate_log`'s arguments checked (``ValueError``); returns the methods as a tuple and
    the odometry method (default: the first)."""
    methods = tuple(methods)
    if not methods or any(m not in METHODS for m in methods) or len(set(methods)) != len(methods):
        raise ValueError(f"methods must be distinct names among {METHODS}, got {methods}")
    odometry_method = methods[0] if odometry_method is None else odometry_method
    if odometry_method not in methods:
        raise ValueError(f"odometry_method {odometry_method!r} is not among the methods run {methods}")
    if isinstance(chunk_size, bool) or not isinstance(chunk_size, int) or chunk_size < 1:
        raise ValueError(f"chunk_size must be an integer >= 1, got {chunk_size!r}")
    if isinstance(moving_speed, bool) or not isinstance(moving_speed, (int, float)) or not moving_speed >= 0 \
            or not math.isfinite(moving_speed):
        raise ValueError(f"moving_speed must be a finite number >= 0 [m/s], got {moving_speed!r}")
    return methods, odometry_method


def _run_estimators(methods, beta, phidot, geom, mu_tol: float, est: dict, cost: dict) -> None:
    """Every method on one chunk's good samples: (λ̂, μ̂, quality) appended to ``est``, the time
    taken added to ``cost``."""
    for m in methods:
        t0 = time.perf_counter()
        lam, mu, _, qua = estimate_eta(beta, phidot, geom, m, mu_tol=mu_tol)
        cost[m] += time.perf_counter() - t0
        est[m]["lam"].append(lam)
        est[m]["mu"].append(mu)
        est[m]["qua"].append(qua)


def estimate_log(source: LogSource, methods=DEFAULT_METHODS, *, odometry_method: str | None = None,
                 chunk_size: int = 50_000, mu_tol: float = 1e-3, moving_speed: float = MOVING_SPEED,
                 progress: Callable[[int, int | None], None] | None = None) -> LogEstimate:
    """Read ``source`` chunk by chunk and estimate every good sample (see the module docstring).

    Args:
        methods: estimators among :data:`~estimation.estimate.METHODS`.
        odometry_method: the one whose λ̂ the dead reckoning uses (default: the first of ``methods``).
        chunk_size: samples per chunk (memory and progress granularity; results do not depend on it).
        mu_tol: ``estimate_eta``'s sign threshold [m/s] (the simulator's is 1e-3).
        moving_speed: [m/s] a sample moves when the fastest wheel contact point of the wheels'
            rigid fit moves at least this fast (see :mod:`estimation.logs.motion`).
        progress: called with (samples read, ``source.n_samples``) after each chunk.

    Raises :class:`LogError` for unsorted or duplicated timestamps, a log with no good sample, or
    an unusable reference pose; the reader's own ``LogError``s pass through.
    """
    methods, odometry_method = _check_estimate_args(methods, odometry_method, chunk_size, moving_speed)
    geom = source.geom
    parts: dict[str, list] = {k: [] for k in ("t", "beta", "phidot", "twist", "pose", "oor", "rigid", "resid",
                                              "speed")}
    est = {m: {"lam": [], "mu": [], "qua": []} for m in methods}
    cost = dict.fromkeys(methods, 0.0)
    skipped = dict.fromkeys(BAD_REASONS, 0)
    odo = _Odometry(geom)
    n_read, last, warm = 0, None, True
    limited = not getattr(geom, "unlimited_steering", False)
    for ch in source.chunks(chunk_size):
        _check_time(ch.t_ns, last, n_read, source)
        last = int(ch.t_ns[-1]) if ch.t_ns.size else last
        bad = mark_bad_values(ch.bad, ch.beta, ch.phidot)
        for code in np.unique(bad[bad != 0]):
            skipped[int(code)] += int(np.sum(bad == code))
        good = bad == 0
        n_read += ch.t_ns.size
        t, beta, phidot = ch.t_ns[good], ch.beta[good], ch.phidot[good]
        if warm and t.size:  # numba compiles (or loads its cache) on a first call: not the method's cost
            for m in methods:
                estimate_eta(beta[:1], phidot[:1], geom, m, mu_tol=mu_tol)
            warm = False
        _run_estimators(methods, beta, phidot, geom, mu_tol, est, cost)
        twist, poses, beta_rate = odo.advance(t, beta, phidot, est[odometry_method]["lam"][-1])
        rigid, resid = twist_from_wheels_batch(beta, beta_rate, phidot, geom)
        speed = contact_speeds(rigid, beta, geom).max(axis=1) if t.size else np.zeros(0)
        oor = ((beta > geom.steer_max) | (beta <= geom.steer_min)).any(axis=1) if limited else np.zeros(t.size, bool)
        for key, value in (("t", t), ("beta", beta), ("phidot", phidot), ("twist", twist), ("pose", poses),
                           ("oor", oor), ("rigid", rigid), ("resid", resid), ("speed", speed)):
            parts[key].append(value)
        if progress is not None:
            progress(n_read, source.n_samples)
    n = geom.n
    cat = {k: np.concatenate(v) if v else np.zeros((0,) + shape)
           for (k, v), shape in zip(parts.items(), [(), (n,), (n,), (3,), (3,), (), (3,), (), ()])}
    if cat["t"].size == 0:
        reasons = "; ".join(f"{c} x {BAD_REASONS[r]}" for r, c in skipped.items() if c)
        raise source.error(f"no good sample among the {n_read} read" + (f" ({reasons})" if reasons else ""))
    result = LogEstimate(
        t_ns=cat["t"].astype(np.int64), beta=cat["beta"], phidot=cat["phidot"], methods=methods,
        lam={m: np.concatenate(est[m]["lam"]) for m in methods}, mu={m: np.concatenate(est[m]["mu"]) for m in methods},
        qua={m: np.concatenate(est[m]["qua"]) for m in methods}, cost_s=cost, odometry_method=odometry_method,
        odom_twist=cat["twist"], pose=cat["pose"], out_of_range=cat["oor"].astype(bool), n_read=n_read,
        skipped={BAD_REASONS[r]: c for r, c in skipped.items() if c}, source=source.describe(),
        rigid_twist=cat["rigid"], rigid_residual=cat["resid"], contact_speed=cat["speed"],
        moving=cat["speed"] >= moving_speed, moving_speed=float(moving_speed))
    _attach_truth(result, source.ground_truth(), source)
    _attach_yaw(result, source.yaw(), source)
    return result


def _attach_yaw(result: LogEstimate, yaw: YawTrack | None, source: LogSource) -> None:
    """Check the gyro's heading and interpolate it at the samples."""
    if yaw is None:
        return
    t = np.asarray(yaw.t_ns, dtype=np.int64)
    y = np.asarray(yaw.yaw, dtype=np.float64)
    if t.ndim != 1 or y.shape != t.shape:
        raise source.error(f"the gyro's yaw ({yaw.source}) has {t.shape} timestamps and {y.shape} values")
    if not np.all(np.isfinite(y)):
        raise source.error(f"the gyro's yaw ({yaw.source}) holds NaN or infinite values")
    if t.size > 1 and np.diff(t).min() <= 0:
        j = int(np.flatnonzero(np.diff(t) <= 0)[0])
        raise source.error(f"the gyro's yaw ({yaw.source}) has timestamps not strictly increasing at its sample "
                           f"{j + 1}")
    result.yaw = YawTrack(t, y, yaw.source)
    result.yaw_at = interp_on(result.t_ns, t, y)


def _attach_truth(result: LogEstimate, truth: GroundTruth | None, source: LogSource) -> None:
    """Interpolate the reference pose at the samples and start the dead reckoning from it."""
    if truth is None or truth.t_ns.size == 0:
        return
    if not np.all(np.isfinite(truth.pose)):
        raise source.error(f"the reference pose ({truth.source}) holds NaN or infinite values")
    step = np.diff(truth.t_ns)
    if step.size and step.min() <= 0:
        j = int(np.flatnonzero(step <= 0)[0])
        raise source.error(f"the reference pose ({truth.source}) has timestamps not strictly increasing at its "
                           f"sample {j + 1}")
    t = result.t_ns
    inside = (t >= truth.t_ns[0]) & (t <= truth.t_ns[-1])
    at = np.full((t.size, 3), np.nan)
    if inside.any():
        tt = (truth.t_ns - truth.t_ns[0]).astype(np.float64)
        ts = (t[inside] - truth.t_ns[0]).astype(np.float64)
        at[inside, 0] = np.interp(ts, tt, truth.pose[:, 0])
        at[inside, 1] = np.interp(ts, tt, truth.pose[:, 1])
        at[inside, 2] = np.interp(ts, tt, np.unwrap(truth.pose[:, 2]))
        j = int(np.flatnonzero(inside)[0])
        result.pose = _realign(result.pose, j, at[j])
        result.aligned_at = j
    result.truth, result.truth_at = truth, at


def _realign(pose: np.ndarray, j: int, target: np.ndarray) -> np.ndarray:
    """The path ``pose`` moved rigidly so that its sample j lands on ``target`` (x, y, θ)."""
    dth = target[2] - pose[j, 2]
    c, s = math.cos(dth), math.sin(dth)
    dx, dy = pose[:, 0] - pose[j, 0], pose[:, 1] - pose[j, 1]
    return np.column_stack([target[0] + c * dx - s * dy, target[1] + s * dx + c * dy, pose[:, 2] + dth])


def odometry_drift(result: LogEstimate) -> dict | None:
    """Dead reckoning against the reference pose, from the sample where they were aligned to the
    last sample the reference covers: the distance the reference travelled [m], the final, RMS
    and max position error [m], the final heading error [rad], and the drift, final position
    error per metre travelled (NaN below 1 cm travelled). None without a reference."""
    if result.truth_at is None or result.aligned_at is None:
        return None
    covered = np.isfinite(result.truth_at[:, 0])
    idx = np.flatnonzero(covered)
    idx = idx[idx >= result.aligned_at]
    ref, odo = result.truth_at[idx], result.pose[idx]
    err = np.hypot(odo[:, 0] - ref[:, 0], odo[:, 1] - ref[:, 1])
    dist = float(np.sum(np.hypot(np.diff(ref[:, 0]), np.diff(ref[:, 1]))))
    dth = odo[-1, 2] - ref[-1, 2]
    return {
        "samples": int(idx.size),
        "duration_s": float((result.t_ns[idx[-1]] - result.t_ns[idx[0]]) * 1e-9),
        "distance_m": dist,
        "final_error_m": float(err[-1]),
        "rms_error_m": float(np.sqrt(np.mean(err**2))),
        "max_error_m": float(err.max()),
        "final_heading_error_rad": float(math.remainder(dth, 2 * math.pi)),
        "drift_per_m": float(err[-1] / dist) if dist >= 0.01 else float("nan"),
    }


def compare_estimators(result: LogEstimate) -> dict:
    """The estimators on this log as ``azimut bench-estimators`` compares them on D2: qua min and
    mean [%], the share of finite unit λ̂, the cost per sample [µs] and samples/s (the
    ``estimate_eta`` calls of :func:`estimate_log`: λ̂, μ̂ and qua), the share of samples where IT's
    qua is at least each other method's (within 1e-9), and the mean gap to ORACLE's qua where it ran."""
    k = result.t_ns.size
    table = {}
    for m in result.methods:
        qua = 100 * result.qua[m]
        lam = result.lam[m]
        unit = np.all(np.isfinite(lam), axis=1) & (np.abs(np.linalg.norm(lam, axis=1) - 1) < 1e-9)
        table[m] = {"qua_min": float(qua.min()), "qua_mean": float(qua.mean()), "valid_unit": float(unit.mean()),
                    "us_per_sample": 1e6 * result.cost_s[m] / k, "samples_per_s": k / max(result.cost_s[m], 1e-12)}
        if "ORACLE" in result.methods:
            table[m]["gap_to_oracle_mean"] = float(100 * (result.qua["ORACLE"].mean() - result.qua[m].mean()))
    dominance = {}
    if "IT" in result.methods:
        for m in result.methods:
            if m not in ("IT", "ORACLE"):
                dominance[m] = float(np.mean(result.qua["IT"] >= result.qua[m] - 1e-9))
    return {"samples": k, "methods": table, "IT_at_least_as_good_fraction": dominance}
