"""``azimut record-d2``: record dataset D2 from the simulated robot on the ``paper`` track.

The paper's D2 (§4) is the set of steering configurations measured while AZIMUT-3 drove a spiral,
a circle and a rounded square under ICR-based control. This command drives the simulated robot (the envs'
default: AZIMUT-3 with the ``"paper"`` imperfections, :mod:`azimut_env.imperfections`) on
the ``paper`` track with the ICR controller (:class:`~control.path_controllers.ICRPathController`,
its path follower not slowing down before the reference's stops; one episode of
:func:`control.rollout.run_episode`, ended at the end of the track, off the track or after
``max_time``) and keeps the measured
steering angles (wheel side of the compliant steering, with the env's sensor noise and encoder
quantisation) of every step where the controller is RUNNING and the robot moves (true speed above
``--min-speed``): the configurations of motion, off the constraining surface by the compliance
and the friction of the steering (``azimut sim-paper`` attributes the departure).
Exact duplicates (quantised encoders) are removed, and ``--points`` of them are kept, evenly
spaced in time.

File format (``estimation/data/d2.npz``, read by ``estimation.datasets.load_d2_recorded``):

* ``q``: (N, n) float64, measured steering angles [rad], in time order;
* ``alpha``, ``l``, ``b``, ``r``: the geometry it was recorded with;
* ``meta``: a JSON string (track, seed, speed scale, control period, imperfections preset, command
  line, counts).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from azimut_env.imperfections import DEFAULT_IMPERFECTIONS
from azimut_env.params import RobotParams
from control.icr.config import Mode
from control.path_controllers import ICRPathController
from control.rollout import run_episode
from jobs.args import arg_float, arg_int, arg_output_path

__all__ = ["record_d2", "add_arguments", "run", "DEFAULT_OUT"]

DEFAULT_OUT = Path(__file__).resolve().parent.parent / "estimation" / "data" / "d2.npz"


#: The paper's D2 holds 2450 configurations. The paper track at its nominal 1 m/s gives about 1570
#: unique ones at the 0.02 s control period, so D2 is recorded at half speed (0.5 m/s).
D2_SPEED_SCALE = 0.5


def record_d2(points: int = 2450, seed: int = 0, speed_scale: float = D2_SPEED_SCALE, min_speed: float = 0.05,
              max_time: float = 400.0, params: RobotParams | None = None,
              substeps: int | None = None) -> tuple[np.ndarray, dict]:
    """Drive ``paper`` under the ICR controller; return (q (N, n), metadata). See the module doc.
    ``params``: the robot (default: the envs' default, AZIMUT-3 with the ``"paper"``
    imperfections; ``azimut sim-paper --sweep ... --d2`` records one per swept value);
    ``substeps``: the physics' substeps (default: the env's)."""
    if points < 1:
        raise ValueError(f"points must be >= 1, got {points}")
    if not (math.isfinite(speed_scale) and speed_scale > 0):
        raise ValueError(f"speed_scale must be > 0, got {speed_scale}")
    env_kwargs = {k: v for k, v in (("params", params), ("substeps", substeps)) if v is not None} or None
    log = run_episode(ICRPathController(speed_scale, follower_stops=False, lookahead=None), "paper", seed=seed,
                      max_time=max_time, env_kwargs=env_kwargs)
    if log.error is not None and log.error != "off track":
        raise RuntimeError(f"simulation failed while recording D2: {log.error}")
    steps = int(log.qua.size)
    moving = (log.mode == int(Mode.RUNNING)) & (np.hypot(log.twist_true[:, 0], log.twist_true[:, 1]) > min_speed)
    kept = log.beta_meas[moving]
    q_all = np.asarray(kept)
    _, first = np.unique(q_all, axis=0, return_index=True)
    q_unique = q_all[np.sort(first)]
    if len(q_unique) > points:
        q = q_unique[np.linspace(0, len(q_unique) - 1, points).round().astype(int)]
    else:
        q = q_unique
    meta = dict(track="paper", seed=seed, speed_scale=speed_scale, min_speed=min_speed,
                control_period=log.dt, steps=steps, moving_steps=len(q_all),
                unique=len(q_unique), points=len(q), completed=bool(log.completed),
                controller="icr", imperfections=DEFAULT_IMPERFECTIONS if params is None else "given parameters",
                command="azimut record-d2 " + " ".join(sys.argv[2:]))
    return np.ascontiguousarray(q), meta


def save_d2(path: Path, q: np.ndarray, meta: dict, geom) -> None:
    """Write the D2 file (see the module docstring for the format)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, q=q, alpha=geom.alpha, l=geom.l, b=geom.b, r=geom.r, meta=json.dumps(meta))


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--points", type=arg_int(1, 10_000_000), default=2450,
                        help="configurations to keep (default 2450)")
    parser.add_argument("--seed", type=arg_int(0, 2**32 - 1), default=0, help="env seed (default 0)")
    parser.add_argument("--speed-scale", type=arg_float(0.0, 10.0, lo_open=True), default=D2_SPEED_SCALE,
                        help=f"multiply the paper track's speed (default {D2_SPEED_SCALE})")
    parser.add_argument("--out", default=str(DEFAULT_OUT), type=arg_output_path(),
                        help=f"output file (default {DEFAULT_OUT})")


def run(args: argparse.Namespace) -> int:
    try:
        q, meta = record_d2(points=args.points, seed=args.seed, speed_scale=args.speed_scale)
    except ValueError as exc:
        print(f"azimut record-d2: error: {exc}", file=sys.stderr)
        return 2
    geom = RobotParams().geometry
    save_d2(Path(args.out), q, meta, geom)
    print(f"D2: {len(q)} configurations ({meta['unique']} unique of {meta['moving_steps']} moving steps, "
          f"{meta['steps']} steps) written to {args.out}")
    return 0
