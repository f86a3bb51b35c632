"""The PNG plots of ``azimut eval``: each run's five plots (:func:`write_plots`), the
per-track overlays of the controllers (:func:`comparison_plots`) and, with ``--speed-scales``, the
per-track fronts (:func:`fronts_plot`). Needs matplotlib (the ``plot`` extra); imported only when
plots are written.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np

from control.episode import EpisodeLog
from control.icr.config import Mode
from jobs.eval.outputs import PLOT_ENDING

__all__ = ["write_plots", "comparison_plots", "fronts_plot"]


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, out: Path, name: str, files: list[str], dpi: int) -> None:
    """Save ``fig`` as ``out/name``, close it, and append ``name`` to ``files``."""
    files.append(name)
    fig.savefig(out / name, dpi=dpi, bbox_inches="tight")
    _pyplot().close(fig)


def _trajectory_axes(ax, track_xy: np.ndarray) -> None:
    """The dashed track on ``ax`` (x/y in metres, equal aspect)."""
    ax.plot(track_xy[:, 0], track_xy[:, 1], "k--", lw=1, label="track")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")


def _surface_samples(geom, n: int = 4000, seed: int = 0) -> np.ndarray:
    from estimation.kinematics import steering_from_lambda

    lam = np.random.default_rng(seed).normal(size=(n, 3))
    return steering_from_lambda(lam / np.linalg.norm(lam, axis=1, keepdims=True), geom)


def _shade_stops(ax, log: EpisodeLog) -> None:
    """Grey bands over the steps where the controller was not RUNNING (stopping, or turning wheels
    in place), labelled once."""
    if log.mode.size != log.t.size or not log.t.size:
        return
    stopped = np.asarray(log.mode) != int(Mode.RUNNING)
    edges = np.flatnonzero(np.diff(np.r_[False, stopped, False].astype(np.int8)))
    half = 0.5 * log.dt
    for j, (a, b) in enumerate(zip(edges[::2], edges[1::2])):
        ax.axvspan(log.t[a] - half, log.t[b - 1] + half, color="0.85", lw=0,
                   label="controller stopped or turning wheels in place" if j == 0 else "_nolegend_")


def _trajectory_plot(plt, log: EpisodeLog, what: str):
    """Plot 1: the trajectory over the track (Fig. 9), the stops that reconfigure marked."""
    fig, ax = plt.subplots(figsize=(6, 6))
    _trajectory_axes(ax, log.track.xy)
    if log.pose.size:
        ax.plot(log.pose[:, 0], log.pose[:, 1], "C0", lw=1.2, label=f"{log.controller}")
        ev = np.flatnonzero(np.diff(log.mode) != 0) + 1 if log.mode.size else []
        ev = [i for i in ev if log.mode[i] == int(Mode.RECONFIGURING)]
        if len(ev):
            ax.plot(log.pose[ev, 0], log.pose[ev, 1], "rx", label="stop + reconfigure")
    ax.legend(loc="best", fontsize=8)
    ax.set_title(f"trajectory: {what}")
    return fig


def _beta_pairs_plot(plt, log: EpisodeLog, what: str, geom):
    """Plot 2: pairwise β projections against the constraining surface S(λ) (Fig. 10)."""
    surf = _surface_samples(geom)
    pairs = [(i, j) for i in range(geom.n) for j in range(i + 1, geom.n)]
    fig, axes = plt.subplots(2, 3, figsize=(11, 7))
    for ax, (i, j) in zip(axes.ravel(), pairs):
        ax.plot(np.degrees(surf[:, i]), np.degrees(surf[:, j]), ".", color="0.75", ms=1,
                label="S(λ): the angles of a rigid motion (samples)")
        if log.beta_meas.size:
            ax.plot(np.degrees(log.beta_meas[:, i]), np.degrees(log.beta_meas[:, j]), ".", ms=1.5, color="C3",
                    label="measured β")
        ax.set_xlabel(f"β{i + 1} [deg]")
        ax.set_ylabel(f"β{j + 1} [deg]")
    axes[0, 0].legend(fontsize=7, markerscale=5)
    fig.suptitle(f"measured steering angles against the constraining surface S(λ): {what}")
    fig.tight_layout()
    return fig


def _qua_plot(plt, log: EpisodeLog, what: str):
    """Plot 3: qua over time (Fig. 11), the stops shaded."""
    fig, ax = plt.subplots(figsize=(8, 3))
    _shade_stops(ax, log)
    ax.plot(log.t, log.qua, lw=0.8, color="C0", label="qua (eq. 28–29): 1 = wheels agree on one ICR")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("qua")
    ax.set_ylim(min(0.0, float(np.min(log.qua)) if log.qua.size else 0.0), 1.02)
    ax.legend(fontsize=7, loc="lower left")
    ax.set_title(f"quality of the measured steering configuration: {what}")
    return fig


def _icr_sphere_plot(plt, log: EpisodeLog, what: str, geom):
    """Plot 4: the ICR's path on the sphere (canonical hemisphere w >= 0, orthographic from above)."""
    fig, ax = plt.subplots(figsize=(5, 5))
    th = np.linspace(0, 2 * np.pi, 200)
    ax.plot(np.cos(th), np.sin(th), "k", lw=0.8, label="w = 0: translation (ICR at infinity)")
    ax.plot([0.0], [0.0], "k+", ms=8, label="(0, 0, 1): rotation about the centre")
    ax.plot(*geom.s_unit[:, :2].T, "k^", label="steering axes ŝ_k")
    if log.lam_hat.size:
        lam = log.lam_hat * np.where(log.lam_hat[:, 2:3] < 0, -1.0, 1.0)
        points = ax.scatter(lam[:, 0], lam[:, 1], c=log.t, s=2, cmap="viridis", label="estimated ICR λ̂")
        fig.colorbar(points, ax=ax, shrink=0.8, label="t [s]")
    ax.set_aspect("equal")
    ax.set_xlabel("u (first component of λ̂)")
    ax.set_ylabel("v (second component of λ̂)")
    ax.legend(fontsize=6, loc="lower left")
    ax.set_title(f"estimated ICR λ̂ = (u, v, w), unit sphere seen from above (w ≥ 0):\n{what}", fontsize=9)
    return fig


def _commands_plot(plt, log: EpisodeLog, what: str, limits):
    """Plot 5: the wheel commands against their limits."""
    fig, axes = plt.subplots(3, 1, figsize=(9, 7), sharex=True)
    for ax, data, lim, name in ((axes[0], log.beta_rate, limits.steer_rate_max, "steering rate β̇_c [rad/s]"),
                                (axes[1], log.phidot_cmd, limits.wheel_speed_max, "wheel speed φ̇_c [rad/s]"),
                                (axes[2], log.phiddot, limits.wheel_accel_max, "wheel accel. φ̈_c [rad/s²]")):
        if data.size:
            for k in range(data.shape[1]):
                ax.plot(log.t, data[:, k], lw=0.6, color=f"C{k}", label=f"wheel {k + 1}")
        else:
            ax.text(0.5, 0.5, "not given by this controller", ha="center", va="center", transform=ax.transAxes)
        ax.axhline(lim, color="r", ls="--", lw=0.8, label="limit")
        ax.axhline(-lim, color="r", ls="--", lw=0.8)
        ax.set_ylim(-2 * lim, 2 * lim)
        ax.set_ylabel(name, fontsize=8)
    axes[0].legend(fontsize=7, loc="upper right", ncol=5)
    axes[-1].set_xlabel("t [s]")
    axes[0].set_title(f"wheel commands and their limits: {what}")
    return fig


def write_plots(log: EpisodeLog, out: Path, geom, limits) -> list[str]:
    """The five PNG plots of one run; returns their file names."""
    plt = _pyplot()
    stem = re.sub(r"[^A-Za-z0-9_.=+-]+", "_", f"{log.controller}_{log.track.name}")  # a file name
    what = f"{log.controller} on {log.track.name}"
    files: list[str] = []
    for plot, extra, key in ((_trajectory_plot, (), "trajectory"), (_beta_pairs_plot, (geom,), "beta_pairs"),
                             (_qua_plot, (), "qua"), (_icr_sphere_plot, (geom,), "icr_sphere"),
                             (_commands_plot, (limits,), "commands")):  # each saved (and closed) before the next
        fig = plot(plt, log, what, *extra)
        _save(fig, out, stem + PLOT_ENDING[key], files, 110)
    return files


def comparison_plots(track: str, traces: dict[str, Any], out: Path) -> list[str]:
    """Overlay the controllers on one track: trajectories; slip power, antagonism and null-space
    force over time. ``traces``: controller -> npz (t, pose, slip_power, antagonism,
    nullspace_force, track_xy; a trace without a series, from an older campaign, leaves it out).
    Returns the file names (relative to ``out``)."""
    plt = _pyplot()
    files: list[str] = []
    stem = re.sub(r"[^A-Za-z0-9_.=+-]+", "_", f"compare_{track}")  # a file name (a track may be a path)
    fig, ax = plt.subplots(figsize=(6.5, 6.5))
    _trajectory_axes(ax, next(iter(traces.values()))["track_xy"])
    for i, (controller, tr) in enumerate(traces.items()):
        if tr["pose"].size:
            ax.plot(tr["pose"][:, 0], tr["pose"][:, 1], color=f"C{i}", lw=1.2, label=controller)
    ax.legend(loc="best", fontsize=8)
    ax.set_title(f"trajectories on {track}")
    _save(fig, out, stem + PLOT_ENDING["trajectory"], files, 100)

    series = (("slip_power", "slip power Σ|F·v_slip| [W]"), ("antagonism", "antagonism [N]"),
              ("nullspace_force", "null-space force [N]"))
    fig, axes = plt.subplots(len(series), 1, figsize=(9, 7.5), sharex=True)
    for i, (controller, tr) in enumerate(traces.items()):
        for ax, (key, _) in zip(axes, series):
            if key in tr:
                ax.plot(tr["t"], tr[key], color=f"C{i}", lw=0.7, label=controller)
    for ax, (_, label) in zip(axes, series):
        ax.set_ylabel(label, fontsize=8)
    axes[-1].set_xlabel("t [s]")
    axes[0].legend(fontsize=8, loc="upper right")
    axes[0].set_title(f"slip, antagonism and null-space force over time on {track}")
    fig.tight_layout()
    _save(fig, out, stem + PLOT_ENDING["slip_force"], files, 100)
    return files


def fronts_plot(track: str, cells: list[dict], controllers: list[str], out: Path) -> list[str]:
    """The fronts of one track (``cells``: its summary cells, one per controller and speed scale):
    lap time against slip energy per metre (left) and against RMS lateral error (right), one line
    per controller through its speed scales (each point labelled ×scale; hollow where the
    controller did not finish every episode). Returns the file name, or nothing when no cell has a
    lap time."""
    from jobs.eval.verdict import finished_all, mean_of

    plt = _pyplot()
    panels = (("slip_energy_per_m", 1.0, "slip energy per metre [J/m]"), ("rms_lateral_m", 100.0, "RMS lateral [cm]"))
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5))
    drawn = False
    for i, controller in enumerate(controllers):
        mine = sorted((c for c in cells if c["controller"] == controller), key=lambda c: c["speed_scale"])
        for ax, (metric, factor, _) in zip(axes, panels):
            pts = [(mean_of(c, "completion_time_s"), factor * mean_of(c, metric), c) for c in mine
                   if mean_of(c, "completion_time_s") is not None and mean_of(c, metric) is not None]
            if not pts:
                continue
            drawn = True
            ax.plot([p[0] for p in pts], [p[1] for p in pts], "-", color=f"C{i}", lw=1.2, label=controller)
            for x, y, c in pts:
                full = finished_all(c)
                ax.plot([x], [y], "o", color=f"C{i}", mfc=f"C{i}" if full else "none", ms=6)
                ax.annotate(f"×{c['speed_scale']:g}", (x, y), textcoords="offset points", xytext=(4, 4), fontsize=7,
                            color=f"C{i}")
    if not drawn:
        _pyplot().close(fig)
        return []
    for ax, (_, _, label) in zip(axes, panels):
        ax.set_xlabel("lap time [s]")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8, loc="best")
    axes[0].set_title(f"fronts on {track}: lower left dominates", fontsize=9)
    axes[1].set_title("RMS lateral error (hollow: not every episode finished)", fontsize=9)
    fig.tight_layout()
    files: list[str] = []
    stem = re.sub(r"[^A-Za-z0-9_.=+-]+", "_", track)  # a file name (a track may be a path)
    _save(fig, out, stem + PLOT_ENDING["fronts"], files, 100)
    return files
