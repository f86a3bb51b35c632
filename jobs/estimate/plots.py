"""The PNG plots of ``azimut estimate`` (matplotlib, the ``plot`` extra; imported only to write them):
the measured steering configurations against the constraining surface (the paper's Fig. 10), qua
over time per estimator (Fig. 11), the dead-reckoned path against the reference pose, and the
motion plot (IT's qua and each module's steering departure over time with the moving samples
shaded, and the wheels' turn rate against the gyro's).

Long logs are thinned for drawing only: at most :data:`MAX_POINTS` evenly spaced samples in the
steering plot, and qua drawn as the mean and the minimum of :data:`QUA_BINS` equal time bins (the
minimum keeps every dip visible)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from estimation.datasets import dataset_d1
from estimation.logs import LogEstimate

__all__ = ["write_plots", "MAX_POINTS", "QUA_BINS"]

#: most samples drawn in the steering-space plot
MAX_POINTS = 20_000
#: time bins of the qua plot when a log has more samples
QUA_BINS = 2_000


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, out: Path, name: str, files: list[str]) -> None:
    plt = _pyplot()
    fig.savefig(out / name, dpi=110, bbox_inches="tight")
    plt.close(fig)
    files.append(name)


def _binned(t: np.ndarray, y: np.ndarray, bins: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(bin centre time, mean, min) of ``y`` over ``bins`` groups of consecutive samples."""
    edges = np.linspace(0, t.size, bins + 1).astype(int)
    edges = np.unique(edges)
    starts = edges[:-1]
    counts = np.diff(edges)
    mean = np.add.reduceat(y, starts) / counts
    low = np.minimum.reduceat(y, starts)
    centre = np.add.reduceat(t, starts) / counts
    return centre, mean, low


def steer_space(result: LogEstimate, geom, modules, out: Path, files: list[str]) -> None:
    plt = _pyplot()
    surf, _ = dataset_d1(geom, 4000, seed=0)  # S(λ) for λ uniform on the sphere: the constraining surface
    pairs = [(i, j) for i in range(geom.n) for j in range(i + 1, geom.n)]
    cols = min(3, len(pairs))
    rows = -(-len(pairs) // cols)
    step = max(1, result.t_ns.size // MAX_POINTS)
    beta = geom.wrap_steering(result.beta[::step])
    fig, axes = plt.subplots(rows, cols, figsize=(3.7 * cols, 3.4 * rows), squeeze=False)
    for ax, (i, j) in zip(axes.ravel(), pairs):
        ax.plot(np.degrees(surf[:, i]), np.degrees(surf[:, j]), ".", color="0.75", ms=1, label="surface S(λ)")
        ax.plot(np.degrees(beta[:, i]), np.degrees(beta[:, j]), ".", color="C3", ms=1.5, label="measured β")
        ax.set_xlabel(f"β {modules[i]} [deg]")
        ax.set_ylabel(f"β {modules[j]} [deg]")
    for ax in axes.ravel()[len(pairs):]:
        ax.set_visible(False)
    axes[0, 0].legend(fontsize=7, markerscale=5)
    thin = f" (every {step}th sample)" if step > 1 else ""
    fig.suptitle(f"measured steering vs the constraining surface{thin}")
    fig.tight_layout()
    _save(fig, out, "steer_space.png", files)


def qua_time(result: LogEstimate, out: Path, files: list[str]) -> None:
    plt = _pyplot()
    t = result.t_s
    m = len(result.methods)
    fig, axes = plt.subplots(m, 1, figsize=(9, 1.6 + 1.4 * m), sharex=True, squeeze=False)
    binned = t.size > QUA_BINS
    for ax, method in zip(axes[:, 0], result.methods):
        qua = result.qua[method]
        if binned:
            tc, mean, low = _binned(t, qua, QUA_BINS)
            ax.fill_between(tc, low, mean, color="C0", alpha=0.3, lw=0, label="bin min")
            ax.plot(tc, mean, lw=0.7, color="C0", label="bin mean")
        else:
            ax.plot(t, qua, lw=0.7, color="C0")
        ax.set_ylabel(f"qua {method}")
        ax.set_ylim(min(0.0, float(qua.min())), 1.02)
    if binned:
        axes[0, 0].legend(fontsize=7, loc="lower left")
    axes[-1, 0].set_xlabel("t [s]")
    how = f" (mean and min of {QUA_BINS} time bins)" if binned else ""
    axes[0, 0].set_title(f"quality of the measured steering configuration per estimator{how}")
    _save(fig, out, "qua_time.png", files)


def odometry(result: LogEstimate, out: Path, files: list[str]) -> None:
    plt = _pyplot()
    has_truth = result.truth_at is not None and result.aligned_at is not None
    fig, axes = plt.subplots(1, 2 if has_truth else 1, figsize=(12 if has_truth else 6, 5.5), squeeze=False)
    ax = axes[0, 0]
    if has_truth:
        ax.plot(result.truth_at[:, 0], result.truth_at[:, 1], "k--", lw=1, label=f"reference ({result.truth.source})")
    ax.plot(result.pose[:, 0], result.pose[:, 1], "C0", lw=1, label=f"dead reckoning ({result.odometry_method})")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend(fontsize=8, loc="best")
    ax.set_title("path")
    if has_truth:
        ok = np.flatnonzero(np.isfinite(result.truth_at[:, 0]))
        ok = ok[ok >= result.aligned_at]
        ref, odo = result.truth_at[ok], result.pose[ok]
        dist = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(ref[:, 0]), np.diff(ref[:, 1])))])
        err = np.hypot(odo[:, 0] - ref[:, 0], odo[:, 1] - ref[:, 1])
        ax2 = axes[0, 1]
        ax2.plot(dist, err, "C3", lw=1)
        ax2.set_xlabel("distance travelled by the reference [m]")
        ax2.set_ylabel("position error [m]")
        ax2.set_title("dead-reckoning drift")
    fig.tight_layout()
    _save(fig, out, "odometry.png", files)


def motion(result: LogEstimate, modules, diag: dict, out: Path, files: list[str]) -> None:
    plt = _pyplot()
    rates = diag.get("rates")
    rows = 3 if rates is not None else 2
    fig, axes = plt.subplots(rows, 1, figsize=(10, 2.2 + 2.0 * rows), sharex=True, squeeze=False)
    axes = axes[:, 0]
    step = max(1, result.t_ns.size // MAX_POINTS)
    t = result.t_s[::step]
    moving = result.moving[::step]
    method = diag["departure"]["method"]
    for ax in axes:
        ax.fill_between(t, 0, 1, where=moving, transform=ax.get_xaxis_transform(), color="C2", alpha=0.12, lw=0,
                        label="moving")
    axes[0].plot(t, result.qua[method][::step], lw=0.7, color="C0", label=f"qua {method}")
    axes[0].set_ylabel(f"qua {method}")
    axes[0].set_ylim(min(0.0, float(result.qua[method].min())), 1.02)
    axes[0].legend(fontsize=7, loc="lower left")
    dep = diag["departure_samples_deg"][::step]
    for k, name in enumerate(modules):
        axes[1].plot(t, dep[:, k], lw=0.7, label=name)
    lim = np.nanpercentile(np.abs(diag["departure_samples_deg"][result.moving]), 99.5) if result.moving.any() else 5
    axes[1].set_ylim(-max(1.0, 1.5 * lim), max(1.0, 1.5 * lim))
    axes[1].set_ylabel("steering departure [deg]")
    axes[1].legend(fontsize=7, loc="lower left", ncol=min(6, len(modules)))
    if rates is not None:
        axes[2].plot(t, rates["gyro"][::step], lw=0.9, color="k", label=f"gyro ({result.yaw.source})")
        axes[2].plot(t, rates["odometry"][::step], lw=0.7, color="C0",
                     label=f"dead reckoning ({result.odometry_method})")
        axes[2].plot(t, rates["rigid"][::step], lw=0.7, color="C1", ls="--", label="rigid fit")
        axes[2].set_ylabel("turn rate [rad/s]")
        axes[2].legend(fontsize=7, loc="lower left")
    axes[-1].set_xlabel("t [s]")
    thin = f" (every {step}th sample)" if step > 1 else ""
    axes[0].set_title(f"moving (shaded) and standing{thin}")
    _save(fig, out, "motion.png", files)


def write_plots(result: LogEstimate, geom, modules, out: Path, diag: dict | None = None) -> list[str]:
    """Write the plots to ``out`` (the motion plot with the log's
    :func:`~estimation.logs.diagnosis.diagnose` ``diag``); returns their file names."""
    files: list[str] = []
    steer_space(result, geom, modules, out, files)
    qua_time(result, out, files)
    odometry(result, out, files)
    if diag is not None:
        motion(result, modules, diag, out, files)
    return files
