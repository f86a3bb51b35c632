"""A log calibrated: its samples read, the fit of :mod:`estimation.calibration` on the moving
ones, its uncertainty from the two halves of the log, and the figures before and after (IT's qua
while moving, each module's departure from the constraining surface)."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from estimation.calibration import apply_offsets, fit_calibration
from estimation.estimate import estimate_eta
from estimation.logs.calibrated import robot_record
from estimation.logs.motion import window_rate
from estimation.logs.source import BAD_REASONS, BAD_STALE, LogSource, mark_bad_values

__all__ = ["read_samples", "figures", "calibrate_source"]

#: at most this many moving samples enter the before/after figures (evenly spaced)
_FIGURE_SAMPLES = 50_000


def read_samples(source: LogSource, chunk: int = 50_000, progress: Callable | None = None):
    """Every good sample of ``source``: (t_ns (N,), beta (N, n), phidot (N, n), read, skipped by
    reason). ``source.error`` for timestamps that are not strictly increasing."""
    ts, bs, ps = [], [], []
    skipped = dict.fromkeys(BAD_REASONS, 0)
    read, last = 0, None
    for ch in source.chunks(chunk):
        full = ch.t_ns if last is None else np.concatenate([[last], ch.t_ns])
        if full.size > 1 and np.diff(full).min() <= 0:
            raise source.error("timestamps not strictly increasing; samples must be in time order")
        last = int(ch.t_ns[-1]) if ch.t_ns.size else last
        bad = mark_bad_values(ch.bad, ch.beta, ch.phidot)
        for code in np.unique(bad[bad != 0]):
            skipped[int(code)] += int(np.sum(bad == code))
        good = bad == 0
        ts.append(ch.t_ns[good])
        bs.append(ch.beta[good])
        ps.append(ch.phidot[good])
        read += ch.t_ns.size
        if progress is not None:
            progress(read, source.n_samples)
    n = source.geom.n
    t = np.concatenate(ts) if ts else np.zeros(0, np.int64)
    beta = np.concatenate(bs) if bs else np.zeros((0, n))
    phidot = np.concatenate(ps) if ps else np.zeros((0, n))
    return t.astype(np.int64), beta, phidot, read, {BAD_REASONS[r]: c for r, c in skipped.items() if c}


def figures(beta, phidot, geom, moving) -> dict:
    """IT's qua (mean, 5th percentile) and each module's departure from the constraining surface at
    IT's λ̂ [deg] (signed mean, mean |·|, 95th percentile |·|) over the moving samples."""
    idx = np.flatnonzero(moving)
    if idx.size > _FIGURE_SAMPLES:
        idx = idx[np.linspace(0, idx.size - 1, _FIGURE_SAMPLES).astype(np.int64)]
    q, p = beta[idx], phidot[idx]
    _, _, surface, qua = estimate_eta(q, p, geom, "IT")
    dep = np.degrees(geom.steering_difference(q, surface))
    return {"samples": int(idx.size), "qua_IT_mean": float(qua.mean()), "qua_IT_p5": float(np.percentile(qua, 5)),
            "departure_signed_mean_deg": dep.mean(0).tolist(), "departure_mean_abs_deg": np.abs(dep).mean(0).tolist(),
            "departure_p95_deg": np.percentile(np.abs(dep), 95, axis=0).tolist()}


def _wrap_deg(x):
    return (np.asarray(x) + 180.0) % 360.0 - 180.0


#: IT's mean qua while moving above which the logged angles already agree
_ANGLES_AGREE = 0.98
#: a fitted change larger than this [deg] is what only the wheel speeds can ask for when the angles agree
_BIG_CHANGE_DEG = 10.0
#: IT's mean qua while moving, after calibration, below which the wheels still disagree
_STILL_DISAGREE = 0.95


def _spread_deg(x) -> float:
    """The largest departure [deg] of the angles ``x`` from their circular mean."""
    return float(np.abs(_wrap_deg(np.degrees(x - math.atan2(np.mean(np.sin(x)), np.mean(np.cos(x)))))).max())


def _warnings(source, geom, offset, before, after, current, cur, beta, phidot, moving) -> list[str]:
    """What a team should check before pasting the offsets (one sentence each)."""
    out = []
    convention = source.describe().get("steer_convention")
    if convention in (None, "beta") and geom.n >= 3:
        # headings read as β: the offsets then come out as π/2 − α_k plus the true ones
        shifted = offset + geom.alpha - np.pi / 2
        if _spread_deg(offset) > 20.0 and _spread_deg(shifted) < 5.0:
            out.append("These offsets are nearly π/2 − α of each module: the log may hold module headings (WPILib's "
                       "convention) read as the paper's β; pass --steer-convention heading.")
    if after["qua_IT_mean"] < _STILL_DISAGREE:
        out.append(f"The wheels still disagree after calibration (IT's quality {100 * after['qua_IT_mean']:.1f}% while "
                   "moving): check the robot file (module positions, the robot given) before trusting these offsets.")
    if cur is not None:
        b_neg, p_neg = apply_offsets(beta, phidot, geom, -cur, np.ones(geom.n))
        neg = figures(b_neg, p_neg, geom, moving)["qua_IT_mean"]
        if neg > current["qua_IT_mean"] + 0.05:
            out.append(f"Your --current-offsets give {100 * current['qua_IT_mean']:.1f}% where their negatives give "
                       f"{100 * neg:.1f}%: they may be your code's offsets to subtract; pass their negatives.")
    return out


def _fit_source(source: LogSource, t, beta, phidot, read: int, skipped: dict, yaw, yaw_rate, moving_speed: float):
    """The calibration fit of the whole log; its ``ValueError`` names the log, the gyro and, where
    many samples were stale, that cause."""
    try:
        return fit_calibration(t, beta, phidot, source.geom, moving_speed=moving_speed, yaw_rate=yaw_rate)
    except ValueError as exc:
        stale = skipped.get(BAD_REASONS[BAD_STALE], 0)
        hint = (f" ({stale} of the {read} samples read were skipped as stale: a signal logged on change that "
                "stopped? --max-age)" if stale > 0.2 * max(read, 1) else "")
        gyro = f" (gyro: {yaw.source})" if yaw is not None and "gyro" in str(exc) else ""
        raise ValueError(f"{source.path}: {exc}{gyro}{hint}") from None


def _proposed_offsets(fit, cur, geom, yaw_rate):
    """The offsets to propose: the fit's, with the common part the log leaves free taken from the
    current offsets ``cur`` where given, wrapped to (-π, π]."""
    offset = fit.steer_offset.copy()
    if cur is not None:
        shift = math.atan2(np.mean(np.sin(cur - offset)), np.mean(np.cos(cur - offset)))
        if not fit.common_observable:  # the free common part: the code's current one
            offset = offset + shift
        elif np.all(geom.b == 0.0) and yaw_rate is None and abs(shift) > math.pi / 2:
            offset = offset + math.pi  # every coaxial module turned by 180° fits alike: the turn nearer the code's
    return np.mod(offset + np.pi, 2 * np.pi) - np.pi


def _halves_spread(fit, t, beta, phidot, geom, moving, yaw_rate, moving_speed: float):
    """Uncertainty: the fit on each half of the moving samples, from the whole log's result; returns
    the half-spreads of the relative offsets [deg] and of the wheel factors (None, None where a half
    cannot be fitted)."""
    halves = []
    idx = np.flatnonzero(moving)
    for part in (idx[: idx.size // 2], idx[idx.size // 2:]):
        mask = np.zeros(t.size, bool)
        lo, hi = part[0], part[-1] + 1
        mask[lo:hi] = True
        try:
            h, _ = fit_calibration(t[mask], beta[mask], phidot[mask], geom, moving_speed=moving_speed,
                                   yaw_rate=None if yaw_rate is None else yaw_rate[mask], start_offset=fit.steer_offset)
        except ValueError:
            halves = []
            break
        rel = h.steer_offset - fit.steer_offset  # relative offsets compared: a half may not fix the common part
        rel -= math.atan2(np.mean(np.sin(rel)), np.mean(np.cos(rel)))
        halves.append((rel, h.wheel_scale / np.exp(np.mean(np.log(h.wheel_scale))) if not fit.scale_absolute
                       else h.wheel_scale))
    spread_off = (np.abs(_wrap_deg(np.degrees(halves[0][0] - halves[1][0]))) / 2).tolist() if halves else None
    spread_scale = (np.abs(halves[0][1] - halves[1][1]) / 2).tolist() if halves else None
    return spread_off, spread_scale


def _refuse_big_change(source: LogSource, fit, offset, cur, base: dict, from_current: bool) -> None:
    """``ValueError`` where the angles already agree yet the fit would turn a module a lot: only
    the wheel speeds ask for it."""
    n = source.geom.n
    change = _wrap_deg(np.degrees(offset - (np.zeros(n) if cur is None else cur)))
    if not fit.common_observable:
        change = change - math.degrees(math.atan2(np.mean(np.sin(np.radians(change))),
                                                  np.mean(np.cos(np.radians(change)))))
    biggest = float(np.abs(_wrap_deg(change)).max())
    if base["qua_IT_mean"] >= _ANGLES_AGREE and biggest > _BIG_CHANGE_DEG:
        how = "with --current-offsets" if from_current else "as logged"
        raise ValueError(f"{source.path}: the steering angles already agree (IT's quality "
                         f"{100 * base['qua_IT_mean']:.1f}% while moving {how}), yet the "
                         f"fit would turn a module by {biggest:.0f}°: only the wheel speeds ask "
                         "for it (a drive motor inverted, a wheel speed of the wrong sign or scale?); check them, "
                         "calibrate refuses to propose these offsets")


def _module_entries(source: LogSource, fit, offset, cur, spread_off, spread_scale) -> list[dict]:
    """One entry per module of ``calibration.json``: offset, factor, their uncertainties, the change."""
    modules = []
    for k, name in enumerate(source.modules):
        entry = {"name": name, "steer_offset_deg": float(np.degrees(offset[k])),
                 "wheel_scale": float(fit.wheel_scale[k]),
                 "steer_offset_std_deg": float(np.degrees(fit.offset_std[k])),
                 "wheel_scale_std": float(fit.scale_std[k]),
                 "steer_offset_halves_spread_deg": None if spread_off is None else spread_off[k],
                 "wheel_scale_halves_spread": None if spread_scale is None else spread_scale[k]}
        if cur is not None:
            entry["change_from_current_deg"] = float(_wrap_deg(np.degrees(offset[k] - cur[k])))
        modules.append(entry)
    return modules


def calibrate_source(source: LogSource, *, moving_speed: float, current_offsets_deg=None, chunk: int = 50_000,
                     progress: Callable | None = None) -> dict:
    """Calibrate ``source`` (see the module docstring); the result is what ``calibration.json``
    holds. ``ValueError`` for a log with too few moving samples."""
    geom = source.geom
    n = geom.n
    t, beta, phidot, read, skipped = read_samples(source, chunk, progress)
    yaw = source.yaw()
    yaw_rate = window_rate(t, yaw.t_ns, yaw.yaw) if yaw is not None else None
    fit, moving = _fit_source(source, t, beta, phidot, read, skipped, yaw, yaw_rate, moving_speed)
    cur = None if current_offsets_deg is None else np.radians(np.asarray(current_offsets_deg, dtype=np.float64))
    offset = _proposed_offsets(fit, cur, geom, yaw_rate)
    spread_off, spread_scale = _halves_spread(fit, t, beta, phidot, geom, moving, yaw_rate, moving_speed)
    before = figures(beta, phidot, geom, moving)
    b_cal, p_cal = apply_offsets(beta, phidot, geom, offset, fit.wheel_scale)
    after = figures(b_cal, p_cal, geom, moving)
    current = None
    if cur is not None:
        b_cur, p_cur = apply_offsets(beta, phidot, geom, cur, np.ones(n))
        current = {**figures(b_cur, p_cur, geom, moving), "steer_offset_deg": np.degrees(cur).tolist()}
    _refuse_big_change(source, fit, offset, cur, before if current is None else current, current is not None)
    warnings = _warnings(source, geom, offset, before, after, current, cur, beta, phidot, moving)
    dur = (t[-1] - t[0]) * 1e-9 if t.size else 0.0
    return {
        "schema": 1, "robot": robot_record(geom, source.modules), "log": source.describe(),
        "modules": _module_entries(source, fit, offset, cur, spread_off, spread_scale),
        "common_offset_observable": fit.common_observable, "common_offset_std_deg": fit.common_std_deg,
        "weakest_combination_std_deg": fit.weakest_std_deg,
        "wheel_scale_absolute": fit.scale_absolute, "gyro": yaw.source if yaw is not None else None,
        "moving_speed_mps": moving_speed,
        "samples": {"read": read, "good": int(t.size), "skipped": skipped, "moving": int(moving.sum()),
                    "fitted": fit.samples, "duration_s": float(dur)},
        "fit": {"iterations": fit.iterations, "rms_residual_deg": math.degrees(fit.rms_rad)},
        "before": before, "current": current, "after": after, "notes": fit.notes, "warnings": warnings,
    }
