"""The evaluation datasets of §4.1: D1, D2 and D3. All seeded.

* D1: λ uniform on the sphere, q = S(λ): every point defines its ICR exactly (accuracy).
* D2: steering configurations met on a real trajectory (reliability, efficiency). The paper's is
  AZIMUT-3's recorded run of Fig. 9–10 (2450 points): a spiral, a circle, then a square with
  rounded corners. If ``estimation/data/d2.npz`` exists (recorded from the simulated robot by
  ``azimut record-d2``), it is used; otherwise :func:`d2_standin` synthesises a stand-in.
* D3: q uniform in ]−π/2, π/2]^n (robustness): wheels knocked anywhere.
"""

from __future__ import annotations

from importlib import resources

import numpy as np

from estimation.geometry import RobotGeometry
from estimation.hrep import eta_from_twist, normalize
from estimation.kinematics import steering_from_lambda

__all__ = ["dataset_d1", "dataset_d2", "dataset_d3", "d2_standin", "D2_FILE", "load_d2_recorded"]

#: Recorded D2 shipped with the package (written by ``azimut record-d2``).
D2_FILE = "data/d2.npz"


def dataset_d1(geom: RobotGeometry, n_points: int = 15000, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """D1: ``(q, λ)`` with λ uniform on the unit sphere (canonical w ≥ 0 not enforced) and
    q = S(λ) on the constraining surface. Shapes (N, n) and (N, 3)."""
    rng = np.random.default_rng(seed)
    lam = normalize(rng.normal(size=(n_points, 3)))
    return steering_from_lambda(lam, geom), lam


def dataset_d3(geom: RobotGeometry, n_points: int = 15000, seed: int = 3) -> np.ndarray:
    """D3: q uniform in the steering range ]β_min, β_max]^n, shape (N, n)."""
    rng = np.random.default_rng(seed)
    u = rng.uniform(0.0, 1.0, size=(n_points, geom.n))
    return geom.steer_max - u * np.pi  # ]β_min, β_max]: u ∈ [0, 1) maps onto it


def _paper_path_twists(dt: float, speed: float) -> np.ndarray:
    """Chassis twists (ẋ, ẏ, θ̇) along the paper's Fig. 9 path, car-like (heading along the path,
    so the ICR lies on the lateral axis), with a slowly varying crab angle on the spiral."""
    twists = []
    # spiral: curvature radius growing from 0.6 m to 2.0 m over two turns, crab angle drifting
    t_sp = np.arange(0.0, 2 * 2 * np.pi * 1.3 / speed, dt)
    radius = np.linspace(0.6, 2.0, t_sp.size)
    crab = 0.35 * np.sin(2 * np.pi * t_sp / t_sp[-1])
    for R, c in zip(radius, crab):
        twists.append((speed * np.cos(c), speed * np.sin(c), speed / R))
    # circle: constant ICR, radius 1.0 m, one turn
    for _ in np.arange(0.0, 2 * np.pi * 1.0 / speed, dt):
        twists.append((speed, 0.0, speed / 1.0))
    # square with rounded corners: 2 m straights (parallel axes), 0.4 m radius quarter turns
    for _ in range(4):
        for _ in np.arange(0.0, 2.0 / speed, dt):
            twists.append((speed, 0.0, 0.0))
        for _ in np.arange(0.0, 0.5 * np.pi * 0.4 / speed, dt):
            twists.append((speed, 0.0, speed / 0.4))
    return np.asarray(twists)


def d2_standin(geom: RobotGeometry, n_points: int = 2450, seed: int = 2, dt: float = 0.01,
               speed: float = 0.5, steer_tau: float = 0.12, deflection_deg: float = 4.0,
               noise_deg: float = 1.0, quantum_deg: float = 0.05) -> np.ndarray:
    """Synthetic stand-in for the paper's D2: the Fig. 9 path with compliant deviations.

    The commanded steering β_c = F(λ(t)) goes through a first-order lag of time constant
    ``steer_tau`` [s] (the compliant, rate-limited steering), a per-wheel deflection proportional
    to the contact point's lateral acceleration (up to about ``deflection_deg``), an AR(1) noise of
    ``noise_deg`` and quantisation to ``quantum_deg``. Duplicates are removed, then ``n_points``
    points are taken evenly along the run. Returns (n_points, n) [rad] in the steering range.
    """
    rng = np.random.default_rng(seed)
    twists = _paper_path_twists(dt, speed)
    lam, mu = eta_from_twist(twists)
    beta_cmd = steering_from_lambda(lam, geom)
    # first-order lag of the steering, on the unwrapped command (wheels do not jump by π)
    unwrapped = np.unwrap(beta_cmd, period=np.pi, axis=0)
    beta = np.empty_like(unwrapped)
    beta[0] = unwrapped[0]
    a = dt / (steer_tau + dt)
    for i in range(1, len(unwrapped)):
        beta[i] = beta[i - 1] + a * (unwrapped[i] - beta[i - 1])
    # lateral deflection from the contact points' accelerations in the chassis frame
    vel = np.stack([twists[:, 0:1] - twists[:, 2:3] * geom.axis_xy[None, :, 1],
                    twists[:, 1:2] + twists[:, 2:3] * geom.axis_xy[None, :, 0]], axis=-1)  # (T, n, 2)
    acc = np.gradient(vel, dt, axis=0) + twists[:, 2, None, None] * np.stack([-vel[..., 1], vel[..., 0]], axis=-1)
    gamma = geom.alpha + beta
    lateral = acc[..., 0] * np.cos(gamma) + acc[..., 1] * np.sin(gamma)
    scale = np.deg2rad(deflection_deg) / max(np.percentile(np.abs(lateral), 99), 1e-9)
    beta = beta + np.clip(scale * lateral, -np.deg2rad(2 * deflection_deg), np.deg2rad(2 * deflection_deg))
    noise = np.zeros_like(beta)
    sigma = np.deg2rad(noise_deg)
    for i in range(1, len(beta)):
        noise[i] = 0.9 * noise[i - 1] + np.sqrt(1 - 0.81) * sigma * rng.normal(size=geom.n)
    beta = beta + noise
    q = np.deg2rad(quantum_deg) * np.round(beta / np.deg2rad(quantum_deg))
    q = geom.wrap_steering(q)
    _, first = np.unique(q, axis=0, return_index=True)
    q = q[np.sort(first)]
    idx = np.linspace(0, len(q) - 1, n_points).round().astype(int)
    return np.ascontiguousarray(q[idx])


def load_d2_recorded(geom: RobotGeometry) -> np.ndarray | None:
    """D2 recorded from the simulated robot, if shipped and recorded for this geometry."""
    try:
        ref = resources.files("estimation").joinpath(D2_FILE)
        if not ref.is_file():
            return None
        with ref.open("rb") as fh, np.load(fh) as data:
            q = np.asarray(data["q"], dtype=np.float64)
            if "alpha" in data and not (data["alpha"].shape == geom.alpha.shape
                                        and np.allclose(data["alpha"], geom.alpha)
                                        and np.allclose(data["l"], geom.l)):
                return None
    except (FileNotFoundError, OSError, KeyError):
        return None
    if q.ndim != 2 or q.shape[1] != geom.n:
        return None
    return np.ascontiguousarray(q)


def dataset_d2(geom: RobotGeometry, source: str = "auto", seed: int = 2) -> tuple[np.ndarray, str]:
    """D2: ``(q, source)`` where source is "recorded" (from the simulator) or "standin".

    ``source`` may force "recorded" (ValueError if absent) or "standin"."""
    if source not in ("auto", "recorded", "standin"):
        raise ValueError(f"source must be 'auto', 'recorded' or 'standin', got {source!r}")
    if source in ("auto", "recorded"):
        q = load_d2_recorded(geom)
        if q is not None:
            return q, "recorded"
        if source == "recorded":
            raise ValueError(f"no recorded D2 for this geometry in estimation/{D2_FILE}; run `azimut record-d2`")
    return d2_standin(geom, seed=seed), "standin"
