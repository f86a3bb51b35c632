"""The energy check of the blow-up detector: energy the robot gains that its motors did not put in.

Over a step the robot's mechanical energy E (:func:`energy_kernel`, the compiled twin of
:func:`~azimut_env.physics.modules.mechanical_energy`: kinetic energy of chassis, modules and
wheels, elastic energy of the steering springs and the tires' contact patches) changes by the
work W of the motors (``ACC.WORK``: the steering motors' τ_s Δθ_m through the series springs, the
drives' τ_m φ̇ dt) minus what the dampers, the tires, the bearings, the rolling resistance, the
steering friction and the inelastic stops dissipate. The unexplained gain G = ΔE − W is then at
most the integrator's error: ≤ 0 on most steps, and positive on a few (a torque clipped at a
motor's limit makes the spring term of E an overestimate for a step; a kick is an outside input,
counted before the step). An explicit integrator pushed past its stability bound (a substep too
long for a stiffness, a module inertia too small for its spring: :mod:`azimut_env.physics.stability`)
instead gains energy step after step while the state stays within every other blow-up limit.

The check: over the last ``BlowUpLimits.energy_window`` steps (default 25, 0.5 s at the default
control period), G > 0 on at least 80% of them and ΣG > max(``energy_gain`` (default 0.25 J),
1% of E) gives :attr:`~azimut_env.physics.blowup.BlowUp.ENERGY`. On the presets under bang-bang
steering, kicks and random commands, no 25-step window has more than 12% positive steps; a module
inertia at 3% of its value (spring ω·dt 0.79, bound 0.5) has 100% and is flagged within 25 steps
(``tests/azimut_env/test_energy_check.py``). An instability that draws its energy through a motor's
own work (an explicit damper past its bound, fed by the position loop) is not seen by this check.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from azimut_env.physics.blowup import BlowUp, BlowUpLimits
from azimut_env.physics.layout import ACC, BODY, CS, JS, MS, RS, WP
from azimut_env.physics.tire import TS
from estimation.threads import BlockKernel

__all__ = ["EnergyCheck", "energy_kernel", "energy_gain_kernel", "POSITIVE_SHARE", "RELATIVE_GAIN"]

#: the share of a window's steps with a positive unexplained gain that the check requires
POSITIVE_SHARE = 0.8
#: the window's total gain must also exceed this share of the energy [-]
RELATIVE_GAIN = 0.01


@njit(cache=True)
def energy_kernel(state, body, js, ms, ts, wp, axis_xy, transfer, com_h, accel, out, lo, hi):
    """out (N,): the mechanical energy [J] of the robots ``lo`` to ``hi - 1``, as
    :func:`~azimut_env.physics.modules.mechanical_energy` computes it (loads with the transfer of
    ``accel`` (N, 2) when ``com_h`` > 0; a block of :class:`estimation.threads.BlockKernel`)."""
    for i in range(lo, hi):
        m = body[i, BODY.MASS]
        vx, vy, w, th = state[i, CS.VX], state[i, CS.VY], state[i, CS.W], state[i, CS.TH]
        c, s = math.cos(th), math.sin(th)
        e = 0.5 * m * (vx * vx + vy * vy) + 0.5 * body[i, BODY.MOMENT] * w * w
        for k in range(js.shape[1]):
            om = js[i, k, JS.OMEGA]
            e += 0.5 * wp[i, k, WP.I_MOD] * om * om
            mc = wp[i, k, WP.M_MOD] * wp[i, k, WP.COM]
            if mc != 0.0:  # the coupling of a module's centre of mass off its axis
                gam = th + wp[i, k, WP.ALPHA] + js[i, k, JS.BETA]
                cg, sg = math.cos(gam), math.sin(gam)
                ax = c * axis_xy[k, 0] - s * axis_xy[k, 1]
                ay = s * axis_xy[k, 0] + c * axis_xy[k, 1]
                e += mc * om * (-sg * vx + cg * vy + (ax * cg + ay * sg) * w)
            spin = ms[i, k, MS.PHIDOT]
            e += 0.5 * wp[i, k, WP.I_W] * spin * spin
            twist = ms[i, k, MS.THETA] - js[i, k, JS.BETA]
            e += 0.5 * wp[i, k, WP.K_S] * twist * twist
            load = wp[i, k, WP.LOAD]
            if com_h > 0.0:
                load = max(load - com_h * m * (transfer[k, 0] * accel[i, 0] + transfer[k, 1] * accel[i, 1]), 0.0)
            k_x = wp[i, k, WP.C_KAPPA] * load / wp[i, k, WP.SIGMA_LONG]
            k_y = wp[i, k, WP.C_ALPHA] * load / wp[i, k, WP.SIGMA_LAT]
            k_t = 0.5 * k_y * wp[i, k, WP.HALF_LEN] ** 2
            e += 0.5 * (k_x * ts[i, k, TS.U_LONG] ** 2 + k_y * ts[i, k, TS.U_LAT] ** 2 + k_t * ts[i, k, TS.TWIST] ** 2)
        out[i] = e


@njit(cache=True)
def energy_gain_kernel(e_before, e_after, acc, hist, filled, pos, gain_abs, summary, code):
    """Record each robot's unexplained gain G = e_after − e_before − Σ_k ACC.WORK in its ring
    ``hist`` (N, window) (``filled``, ``pos``: (N,) int counts and next slots) and, where the
    window is full and the robot has no blow-up code yet, set ``summary[i, RS.CODE] = code`` when
    G > 0 on at least :data:`POSITIVE_SHARE` of the window and ΣG > max(gain_abs, 1% of e_after)."""
    window = hist.shape[1]
    for i in range(e_before.shape[0]):
        work = 0.0
        for k in range(acc.shape[1]):
            work += acc[i, k, ACC.WORK]
        hist[i, pos[i]] = e_after[i] - e_before[i] - work
        pos[i] = (pos[i] + 1) % window
        if filled[i] < window:
            filled[i] += 1
        if filled[i] < window or summary[i, RS.CODE] != BlowUp.NONE.value:
            continue
        total = 0.0
        positive = 0
        for j in range(window):
            total += hist[i, j]
            if hist[i, j] > 0.0:
                positive += 1
        if positive >= POSITIVE_SHARE * window and total > max(gain_abs, RELATIVE_GAIN * e_after[i]):
            summary[i, RS.CODE] = code


#: the energies over blocks of robots (a block: at least 32 robots)
_ENERGY = BlockKernel(energy_kernel, min_rows=32)


class EnergyCheck:
    """The per-robot state of the check (its ring of gains) for ``AzimutPhysics``: :meth:`before`
    at the start of a step, :meth:`after` once the step's summary is written, :meth:`clear` when a
    robot is reset."""

    def __init__(self, n_robots: int, limits: BlowUpLimits) -> None:
        self.limits = limits
        self.hist = np.zeros((n_robots, int(limits.energy_window)))
        self.filled = np.zeros(n_robots, dtype=np.int64)
        self.pos = np.zeros(n_robots, dtype=np.int64)
        self.e_before = np.zeros(n_robots)
        self.e_after = np.zeros(n_robots)

    def clear(self, robot: int) -> None:
        self.hist[robot] = 0.0
        self.filled[robot] = 0
        self.pos[robot] = 0

    def _energy(self, phys, out: np.ndarray) -> None:
        args = (phys._state, phys.body_inertia, phys.joint_state, phys.motor_state, phys.tire_state, phys.wheel_params,
                phys._axis_xy, phys._load_transfer, float(phys.params.chassis.com_height), phys.chassis_accel, out)
        if phys.num_threads == 1:  # the single env's path: the kernel itself, no dispatch
            energy_kernel(*args, 0, out.shape[0])
        else:
            _ENERGY.run(phys.num_threads, out.shape[0], *args)

    def before(self, phys) -> None:
        self._energy(phys, self.e_before)

    def after(self, phys) -> None:
        self._energy(phys, self.e_after)
        energy_gain_kernel(self.e_before, self.e_after, phys.acc, self.hist, self.filled, self.pos,
                           float(self.limits.energy_gain), phys.summary, int(BlowUp.ENERGY))
