"""Convergence of the physics in the substep count (``azimut bench-env --convergence``): an
open-loop replay of smooth kinematic set-points at several substep counts, against a fine
reference (the measured figures are in the documentation, ``docs/results/bench-env.md``)."""

from __future__ import annotations

import numpy as np

from azimut_env.params import RobotParams
from azimut_env.physics.engine import AzimutPhysics
from azimut_env.physics.layout import RS_POSE, WS
from estimation import eta_from_twist, steering_from_lambda, wheel_speeds

__all__ = ["convergence_commands", "substep_convergence"]


def convergence_commands(seconds: float = 30.0, control_period: float = 0.02, seed: int = 0):
    """Open-loop set-points for :func:`substep_convergence`: a smooth random chassis twist (sums of
    sines, up to about 1 m/s and 1 rad/s, crossing rotations in place and direction reversals)
    mapped to kinematic steering angles and wheel speeds. Returns (β_cmd, φ̇_cmd), each (steps, n)."""
    geom = RobotParams().geometry
    rng = np.random.default_rng(seed)
    steps = int(round(seconds / control_period))
    t = np.arange(steps) * control_period
    freq = rng.uniform(0.05, 0.3, size=(3, 3))
    phase = rng.uniform(0.0, 2 * np.pi, size=(3, 3))
    amp = np.array([0.6, 0.4, 0.6])
    twist = np.stack([amp[j] * np.sum(np.sin(2 * np.pi * freq[j][:, None] * t + phase[j][:, None]), 0) / 2
                      for j in range(3)], 1)
    beta = np.zeros((steps, geom.n))
    phidot = np.zeros((steps, geom.n))
    for i in range(steps):
        lam, mu = eta_from_twist(twist[i])
        beta[i] = steering_from_lambda(lam, geom)
        phidot[i] = wheel_speeds(lam, mu, geom, beta=beta[i])
    return beta, phidot


def substep_convergence(substeps=(4, 6, 8, 12, 16, 24, 32, 48, 64, 128), reference: int = 256,
                        seconds: float = 30.0, seed: int = 0) -> list[dict[str, float]]:
    """Convergence of the physics in the substep count: the same open-loop set-points
    (:func:`convergence_commands`) replayed at each substep count and compared with ``reference``
    substeps. Returns one row per accepted count: the largest and final chassis position error
    [m], final heading error [rad], largest β error [rad], and the observed order against the
    previous row (log of the error ratio over log of the substep ratio, on the largest position
    error). Counts the stability check refuses are reported with ``refused`` set."""
    beta, phidot = convergence_commands(seconds, seed=seed)

    def replay(k: int):
        phys = AzimutPhysics(substeps=k)
        phys.reset_robot(0, (0.0, 0.0, 0.0), beta[0])
        poses = np.empty((len(beta), 3))
        betas = np.empty_like(beta)
        for i in range(len(beta)):
            phys.set_commands(beta[i][None], phidot[i][None])
            phys.step()
            poses[i] = phys.summary[0, RS_POSE]
            betas[i] = phys.wheel_summary[0, :, WS.BETA]
        return poses, betas

    ref_pose, ref_beta = replay(reference)
    rows: list[dict[str, float]] = []
    prev = None
    for k in substeps:
        try:
            pose, b = replay(int(k))
        except ValueError:
            rows.append({"substeps": float(k), "refused": 1.0})
            continue
        err = np.hypot(*(pose[:, :2] - ref_pose[:, :2]).T)
        row = {"substeps": float(k), "refused": 0.0, "max_position_error": float(err.max()),
               "final_position_error": float(err[-1]), "final_heading_error": float(abs(pose[-1, 2] - ref_pose[-1, 2])),
               "max_beta_error": float(np.max(np.abs(b - ref_beta))), "order": float("nan")}
        if prev is not None and row["max_position_error"] > 0:
            row["order"] = float(np.log(prev["max_position_error"] / row["max_position_error"])
                                 / np.log(k / prev["substeps"]))
        rows.append(row)
        prev = row
    return rows
