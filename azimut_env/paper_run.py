"""The paper's phenomenon, measured: drive a track with a kinematic feed-forward and record how far
the *measured* steering configuration leaves the constraining surface (qua, eq. 28–29).

The feed-forward turns the track's reference twist (plus a proportional correction of the pose
error, so that the robot stays on the track) into wheel set-points through ``estimation``'s
kinematics: λ, μ from the twist, β = F(λ) (eq. 16–17) and φ̇ from eq. (r φ̇ = μ c − b β̇). It
knows nothing of the compliance: whatever the measured β do is the robot's doing.

Run ``python -m azimut_env.paper_run`` (or ``azimut sim-paper``) to print the numbers and write
a plot like the paper's Fig. 10–11.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass

import numpy as np

from estimation import eta_from_twist, steering_from_lambda, wheel_speeds

__all__ = ["FeedForwardController", "PaperRun", "run_feedforward", "add_arguments", "run"]


@dataclass
class FeedForwardController:
    """Kinematic feed-forward with proportional pose correction.

    Attributes:
        k_pos: position gain [1/s]; k_head: heading gain [1/s]; speed_scale: multiplies the
        track's speed profile.
    """

    k_pos: float = 1.5
    k_head: float = 1.5
    speed_scale: float = 1.0

    def __post_init__(self) -> None:
        self._beta_prev = None

    def reset(self) -> None:
        self._beta_prev = None

    def __call__(self, env) -> np.ndarray:
        """The normalised action for the env's current state (uses the true pose for the frame)."""
        track, geom = env.track, env.geometry
        x, y, th = env.true_pose
        s = env.progress
        ref = track.sample(s)
        tw = track.reference_twist(s) * self.speed_scale
        vx = tw[0] + self.k_pos * (ref[0] - x)
        vy = tw[1] + self.k_pos * (ref[1] - y)
        w = tw[2] - self.k_head * math.remainder(th - ref[2], 2 * math.pi)
        c, sn = math.cos(th), math.sin(th)
        body = np.array([c * vx + sn * vy, -sn * vx + c * vy, w])
        dt = env.control_period
        if np.linalg.norm(body) < 1e-6:
            beta = env.measured_beta if self._beta_prev is None else self._beta_prev
            phidot = np.zeros(geom.n)
        else:
            lam, mu = eta_from_twist(body)
            beta = steering_from_lambda(lam, geom)
            rate = None if self._beta_prev is None else (beta - self._beta_prev) / dt
            if rate is not None:
                rate = np.where(np.abs(rate) > 5.0, 0.0, rate)  # a wheel flipping at its stop
            phidot = wheel_speeds(lam, mu, geom, beta_rate=rate, beta=beta)
        self._beta_prev = np.asarray(beta, dtype=float)
        return env.action_from_setpoints(beta, phidot)


@dataclass
class PaperRun:
    """Time series of one run (per control step)."""

    t: np.ndarray
    qua: np.ndarray
    qua_true: np.ndarray
    speed: np.ndarray
    lateral_error: np.ndarray
    slip_power: np.ndarray
    internal_force: np.ndarray
    beta_meas: np.ndarray
    beta_est: np.ndarray
    progress: np.ndarray
    finished: bool
    error: str | None

    def summary(self, min_speed: float = 0.05) -> dict[str, float]:
        """qua statistics over the steps where the robot moves (speed > ``min_speed`` m/s)."""
        moving = self.speed > min_speed
        q = self.qua[moving] if moving.any() else self.qua
        qt = self.qua_true[moving] if moving.any() else self.qua_true
        return {
            "steps": int(self.t.size),
            "moving_steps": int(moving.sum()),
            "qua_mean": float(q.mean()),
            "qua_min": float(q.min()),
            "qua_p05": float(np.percentile(q, 5)),
            "qua_true_mean": float(qt.mean()),
            "qua_true_min": float(qt.min()),
            "lateral_rms": float(np.sqrt(np.mean(self.lateral_error**2))),
            "slip_power_mean": float(self.slip_power.mean()),
            "internal_force_mean": float(self.internal_force.mean()),
            "finished": bool(self.finished),
        }


def run_feedforward(track: str = "paper", seed: int = 0, max_steps: int = 6000, sensors=None,
                    controller: FeedForwardController | None = None, **env_kwargs) -> PaperRun:
    """Drive ``track`` with the feed-forward until it finishes, leaves the track or ``max_steps``.

    qua is computed from the measured β (what the robot's sensors see; noise included) and
    ``qua_true`` from the true β, each against S(λ̂) of its own IT estimate."""
    from estimation import estimate_icr, quality

    from .env import AzimutEnv

    env = AzimutEnv(track=track, sensors=sensors, **env_kwargs)
    ctrl = controller if controller is not None else FeedForwardController()
    ctrl.reset()
    env.reset(seed=seed)
    rec: dict[str, list] = {k: [] for k in ("qua", "qua_true", "speed", "lat", "slip", "internal", "bm", "be", "s")}
    finished, error = False, None
    geom = env.geometry
    for _ in range(max_steps):
        action = ctrl(env)
        _, _, term, _, info = env.step(action)
        if "error" in info:
            error = info["error"]
            break
        bt = geom.wrap_steering(info["beta_true"])
        lam_t = estimate_icr(bt, geom)
        qt = float(quality(steering_from_lambda(lam_t, geom, singular_fill=bt), bt))
        rec["qua"].append(info["qua"])
        rec["qua_true"].append(qt)
        rec["speed"].append(float(np.hypot(*info["twist"][:2])))
        rec["lat"].append(info["lateral_error"])
        rec["slip"].append(info["slip_power"])
        rec["internal"].append(info["internal_force"])
        rec["bm"].append(env.measured_beta)
        rec["be"].append(info["beta_est"])
        rec["s"].append(info["progress"])
        if term:
            finished = bool(info.get("finished"))
            break
    n = len(rec["qua"])
    return PaperRun(t=np.arange(1, n + 1) * env.control_period, qua=np.array(rec["qua"]),
                    qua_true=np.array(rec["qua_true"]), speed=np.array(rec["speed"]),
                    lateral_error=np.array(rec["lat"]), slip_power=np.array(rec["slip"]),
                    internal_force=np.array(rec["internal"]), beta_meas=np.array(rec["bm"]).reshape(n, -1),
                    beta_est=np.array(rec["be"]).reshape(n, -1), progress=np.array(rec["s"]), finished=finished,
                    error=error)


def plot_run(result: PaperRun, path: str) -> None:
    """qua over time and the measured vs estimated steering angles (like the paper's Fig. 10–11)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 1, figsize=(10, 8), sharex=True)
    axes[0].plot(result.t, result.qua, lw=0.8, label="qua (measured β)")
    axes[0].plot(result.t, result.qua_true, lw=0.8, alpha=0.7, label="qua (true β)")
    axes[0].set_ylabel("qua")
    axes[0].set_ylim(0, 1.02)
    axes[0].legend(loc="lower left")
    for k in range(result.beta_meas.shape[1]):
        line, = axes[1].plot(result.t, np.rad2deg(result.beta_meas[:, k]), lw=0.8, label=f"β{k + 1} measured")
        axes[1].plot(result.t, np.rad2deg(result.beta_est[:, k]), lw=0.8, ls="--", color=line.get_color())
    axes[1].set_ylabel("β [deg] (dashed: S(λ̂))")
    axes[1].legend(loc="upper right", fontsize=7, ncol=4)
    axes[2].plot(result.t, result.internal_force, lw=0.8, label="internal force [N]")
    axes[2].plot(result.t, result.slip_power, lw=0.8, label="slip power [W]")
    axes[2].set_xlabel("t [s]")
    axes[2].legend(loc="upper right")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--track", default="paper", help="built-in track name (default paper)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--max-steps", type=int, default=6000)
    parser.add_argument("--ideal-sensors", action="store_true", help="no sensor noise or quantisation")
    parser.add_argument("--plot", default=None, help="write a PNG plot here (needs matplotlib)")


def run(args: argparse.Namespace) -> int:
    res = run_feedforward(args.track, seed=args.seed, max_steps=args.max_steps,
                          sensors="ideal" if args.ideal_sensors else None)
    summ = res.summary()
    print(f"track {args.track}, seed {args.seed}: {summ['steps']} steps ({summ['moving_steps']} moving), "
          f"finished={summ['finished']}, error={res.error}")
    for key in ("qua_mean", "qua_min", "qua_p05", "qua_true_mean", "qua_true_min", "lateral_rms",
                "slip_power_mean", "internal_force_mean"):
        print(f"  {key:20s} {summ[key]:.4f}")
    if args.plot:
        plot_run(res, args.plot)
        print(f"plot written to {args.plot}")
    return 0 if res.error is None else 1


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_arguments(p)
    raise SystemExit(run(p.parse_args()))
