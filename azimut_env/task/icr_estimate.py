"""The estimation stage of the pipeline: the IT estimate (λ̂, μ̂) of the H state from the readings.

:func:`estimate` runs ``estimation``'s compiled IT (``estimation.estimate.estimate_eta_rows``,
the same bits as ``estimation.estimate_eta``) on the measured steering angles and wheel speeds
of the robots of ``rows``, into ``ta.lam_hat`` (N, 3), ``ta.mu_hat``, ``ta.qua`` (N,) and
``ta.beta_est`` (N, n) (S(λ̂)). The estimator's settings are the struct's constants
(:data:`azimut_env.task.arrays.FIELDS`: the geometry and ``ITParams``).
"""

from __future__ import annotations

from numba import njit

from estimation.estimate import _eta_it_rows
from estimation.quality import QUALITY_F

__all__ = ["estimate", "MU_TOL"]

#: below this |μ̂| [m/s] the estimate takes the canonical sign (``estimate_eta``'s ``mu_tol``)
MU_TOL = 1e-3


@njit(cache=True)
def estimate(ta, rows, action):
    """The IT estimate of the robots of ``rows``: one call per run of consecutive rows (every
    robot: one call), the same bits as robot by robot."""
    n_rows = rows.shape[0]
    # the geometry copied per call: IT passes these small arrays through every call of its loop,
    # and the struct's own arrays carry one reference count that the threads of a parallel
    # pipeline would contend for (measured: 256 robots on 2 threads 1.2x faster, with copies 1.9x)
    E, P, b_k, r_k = ta.a_minus_l.copy(), ta.a_perp.copy(), ta.b.copy(), ta.r.copy()
    a = 0
    while a < n_rows:
        if not rows[a]:
            a += 1
            continue
        b = a + 1
        while b < n_rows and rows[b]:
            b += 1
        _eta_it_rows(ta.beta_m[a:b], ta.phidot_m[a:b], E, P, b_k, r_k, ta.steer_min,
                     ta.steer_max, ta.unlimited, ta.eps_delta, ta.eps_lambda, ta.max_iter, ta.min_step, ta.n_starts,
                     ta.race, ta.accept_d2, MU_TOL, QUALITY_F, ta.lam_hat[a:b], ta.mu_hat[a:b], ta.beta_est[a:b],
                     ta.qua[a:b])
        a = b
