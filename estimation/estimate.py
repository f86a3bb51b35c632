"""One entry point for every ICR estimator: :func:`estimate_icr`.

IT, IT+, ORACLE and the μ̂ / S(λ̂) fit of :func:`estimate_eta` run over the samples in blocks,
one per thread (``num_threads``, :mod:`estimation.threads`; None: the cores this process may
use). A sample's estimate does not depend on its block: the same bits for any count.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from estimation.geometry import RobotGeometry
from estimation.hrep import _canonicalize_batch
from estimation.it import ITParams, it_kernel_batch
from estimation.kinematics import _eta_kernel
from estimation.operational import ls_kernel_batch, ne_kernel_batch, ns_batch
from estimation.oracle import OracleParams, oracle_kernel_batch, oracle_tables
from estimation.quality import QUALITY_F
from estimation.threads import BlockKernel, check_threads
from estimation.validation import check_nonnegative

__all__ = ["METHODS", "ITDiagnostics", "estimate_icr", "estimate_icr_it", "estimate_eta", "estimate_eta_rows",
           "IT_BEST", "IT_PAPER"]

#: Method names accepted by :func:`estimate_icr`. "IT+" is the improved IT (``IT_BEST``).
METHODS = ("IT", "IT+", "NE", "LS", "NS", "ORACLE")

#: The paper's IT: Algorithm 1 with the documented default thresholds.
IT_PAPER = ITParams()

#: The improved IT: every kept start run to convergence, the closest result kept.
IT_BEST = ITParams(n_starts=6, race_iter=2, accept_rms=0.25)

#: ORACLE's default search density (OracleParams is frozen, so one shared instance is safe).
ORACLE_DEFAULT = OracleParams()


def _real_array(x, name: str) -> np.ndarray:
    """x as a float64 array; complex, object and string inputs raise ``TypeError`` (NumPy would
    drop an imaginary part silently)."""
    arr = np.asarray(x)
    if arr.dtype.kind not in "biuf":
        raise TypeError(f"{name} must hold real numbers, got dtype {arr.dtype}")
    return arr.astype(np.float64, copy=False)


def _prepare(q, geom: RobotGeometry, shifts: bool = False):
    """Validate q ((n,) or (N, n), real, finite) and return it as contiguous (N, n) in the
    steering range, plus the batch shape (and, with ``shifts``, the (N, n) multiples of π taken
    off each angle, or None when none was). Kept lean: it is on the single-call hot path.

    Only the angles outside the steering range are wrapped (β and β + π are the same axis): an
    angle in range is never touched, so each row's result is independent of the rest of its
    batch, bit for bit. (With unlimited steering the measured angles are anywhere in ]−π, π], and
    about half of them are wrapped.)"""
    if not isinstance(geom, RobotGeometry):
        raise TypeError(f"geom must be a RobotGeometry, got {type(geom).__name__}")
    arr = _real_array(q, "q")
    if arr.ndim not in (1, 2) or arr.shape[-1] != geom.n:
        raise ValueError(f"q must have shape ({geom.n},) or (N, {geom.n}) for this robot, got {arr.shape}")
    if not np.isfinite(arr).all():
        raise ValueError("q contains NaN or inf")
    batch = arr.shape[:-1]
    flat = arr.reshape(-1, geom.n)
    shift = None
    if flat.size and (flat.max() > geom.steer_max or flat.min() <= geom.steer_min):
        outside = (flat > geom.steer_max) | (flat <= geom.steer_min)
        wrapped = np.where(outside, geom.wrap_steering(flat), flat)  # β and β + π: the same propulsion axis
        if shifts:
            shift = flat - wrapped
        flat = wrapped
    elif not flat.flags.c_contiguous:
        flat = np.ascontiguousarray(flat)
    return (flat, batch, shift) if shifts else (flat, batch)


@dataclass(frozen=True)
class ITDiagnostics:
    """Per-point diagnostics of IT, arrays of shape (N,) (or 0-d for a single point).

    Attributes:
        iterations: Newton iterations, summed over the starts tried.
        starts_tried: starting points evaluated.
        converged: whether the returned λ comes from a converged start (or a start on the surface).
        distance: ‖q − S(λ̂)‖ [rad], the joint-space distance to the estimate.
    """

    iterations: np.ndarray
    starts_tried: np.ndarray
    converged: np.ndarray
    distance: np.ndarray


@njit(cache=True)
def _it_block(q, E, P, steer_max, eps_delta, eps_lambda, max_iter, min_step, n_starts, race_iter, accept_d2, lam,
              d2, iters, starts, conv, periodic, lo, hi):
    """:func:`~estimation.it.it_kernel_batch` on the samples ``lo`` to ``hi - 1`` (a block)."""
    it_kernel_batch(q[lo:hi], E, P, steer_max, eps_delta, eps_lambda, max_iter, min_step, n_starts, race_iter,
                    accept_d2, lam[lo:hi], d2[lo:hi], iters[lo:hi], starts[lo:hi], conv[lo:hi], periodic)


@njit(cache=True)
def _oracle_block(q, E, P, steer_max, grid, grid_beta, s_unit, refine, lam, d2, periodic, lo, hi):
    """:func:`~estimation.oracle.oracle_kernel_batch` on the samples ``lo`` to ``hi - 1``."""
    oracle_kernel_batch(q[lo:hi], E, P, steer_max, grid, grid_beta, s_unit, refine, lam[lo:hi], d2[lo:hi], periodic)


@njit(cache=True)
def _eta_block(lam, q, phidot, E, P, b, r, steer_max, mu_tol, f, beta, mu, qua, periodic, lo, hi):
    """:func:`~estimation.kinematics._eta_kernel` (μ̂, S(λ̂), qua, the sign) on samples ``lo`` to ``hi - 1``."""
    _eta_kernel(lam[lo:hi], q[lo:hi], phidot[lo:hi], E, P, b, r, steer_max, mu_tol, f, beta[lo:hi], mu[lo:hi],
                qua[lo:hi], np.empty(E.shape[0]), periodic)


#: the estimators over blocks of samples (a block: at least 64 samples, ~100 µs of IT; IT and
#: ORACLE through the parallel twin on one thread too, where they run faster)
_IT = BlockKernel(_it_block, min_rows=64, twin_on_one_thread=True)
_ORACLE = BlockKernel(_oracle_block, min_rows=8, twin_on_one_thread=True)
_ETA = BlockKernel(_eta_block, min_rows=256)


def _it_flat(flat: np.ndarray, geom: RobotGeometry, params: ITParams, threads: int = 1):
    """IT's kernel on validated (N, n) angles: λ (N, 3), not yet canonical, and diagnostics."""
    N = flat.shape[0]
    lam = np.empty((N, 3))
    d2 = np.empty(N)
    iters = np.empty(N, dtype=np.int64)
    starts = np.empty(N, dtype=np.int64)
    conv = np.empty(N, dtype=np.bool_)
    _IT.run(threads, N, flat, geom.a_minus_l, geom.a_perp, float(geom.steer_max), params.eps_delta,
            params.eps_lambda, int(params.max_iter), params.min_step, int(params.n_starts), params.race_iter_or_paper,
            params.accept_d2(geom.n), lam, d2, iters, starts, conv, bool(geom.unlimited_steering))
    return lam, d2, iters, starts, conv


def _estimate_flat(flat: np.ndarray, geom: RobotGeometry, method: str, it_params: ITParams | None,
                   oracle_params: OracleParams, threads: int = 1) -> np.ndarray:
    """Every method on validated (N, n) angles: λ (N, 3), not yet canonical."""
    if it_params is not None and not isinstance(it_params, ITParams):
        raise TypeError(f"it_params must be ITParams or None, got {type(it_params).__name__}")
    if not isinstance(oracle_params, OracleParams):
        raise TypeError(f"oracle_params must be OracleParams, got {type(oracle_params).__name__}")
    if method in ("IT", "IT+"):
        params = it_params if it_params is not None else (IT_PAPER if method == "IT" else IT_BEST)
        return _it_flat(flat, geom, params, threads)[0]
    lam = np.empty((flat.shape[0], 3))
    if method == "NE":
        ne_kernel_batch(flat, geom.a_minus_l, geom.a_perp, lam)
    elif method == "LS":
        ls_kernel_batch(flat, geom.alpha, geom.axis_xy, lam)
    elif method == "NS":
        lam[:] = ns_batch(flat, geom)
    else:
        grid, grid_beta = oracle_tables(geom, oracle_params)
        d2 = np.empty(flat.shape[0])
        _ORACLE.run(threads, flat.shape[0], flat, geom.a_minus_l, geom.a_perp, float(geom.steer_max), grid,
                    grid_beta, np.ascontiguousarray(geom.s_unit), int(oracle_params.refine), lam, d2,
                    bool(geom.unlimited_steering))
    return lam


def estimate_icr_it(q, geom: RobotGeometry, params: ITParams = IT_PAPER, diagnostics: bool = False, *,
                    num_threads: int | None = None):
    """IT, Algorithm 1 (§3.1). See :mod:`estimation.it`.

    Args:
        q: (n,) or (N, n) measured steering angles [rad]. Angles outside the steering range are
            wrapped into it (β and β + π are the same propulsion axis).
        geom: the robot.
        params: thresholds; defaults reproduce the paper, ``IT_BEST`` is the improved variant.
        diagnostics: also return an :class:`ITDiagnostics`.
        num_threads: threads (blocks of samples; None: the cores this process may use).

    Returns:
        λ̂ (3,) or (N, 3), canonical sign (:func:`canonical_lambda`), and the diagnostics if asked.
    """
    if not isinstance(params, ITParams):
        raise TypeError(f"params must be ITParams, got {type(params).__name__}")
    threads = check_threads(num_threads)
    flat, batch = _prepare(q, geom)
    lam, d2, iters, starts, conv = _it_flat(flat, geom, params, threads)
    _canonicalize_batch(lam)
    lam = lam.reshape(batch + (3,))
    if not diagnostics:
        return lam
    diag = ITDiagnostics(iters.reshape(batch), starts.reshape(batch), conv.reshape(batch), np.sqrt(d2).reshape(batch))
    return lam, diag


def _check_method(method: str) -> None:
    if not isinstance(method, str) or method not in METHODS:
        raise ValueError(f"unknown method {method!r}; choose from {METHODS}")


def estimate_icr(q, geom: RobotGeometry, method: str = "IT", *, it_params: ITParams | None = None,
                 oracle_params: OracleParams = ORACLE_DEFAULT, num_threads: int | None = None) -> np.ndarray:
    """Estimate the ICR λ̂ ∈ Λ from measured steering angles q.

    Args:
        q: (n,) or (N, n) steering angles [rad]; NaN or inf raise ``ValueError``.
        geom: the robot.
        method: "IT" (Algorithm 1, §3.1), "IT+" (improved IT, see :mod:`estimation.it`), "NE"
            (§3.2.1), "LS" (§3.2.2), "NS" (§3.2.3) or "ORACLE" (exhaustive projection, the yardstick).
        it_params: thresholds for "IT" (default ``IT_PAPER``) or "IT+" (default ``IT_BEST``).
        oracle_params: search density for "ORACLE".
        num_threads: threads of IT, IT+ and ORACLE (blocks of samples; None: the cores this
            process may use; any count gives the same bits).

    Returns:
        (3,) or (N, 3) unit vectors with the canonical sign of :func:`canonical_lambda`.
    """
    _check_method(method)
    threads = check_threads(num_threads)
    flat, batch = _prepare(q, geom)
    lam = _estimate_flat(flat, geom, method, it_params, oracle_params, threads)
    _canonicalize_batch(lam)
    return lam.reshape(batch + (3,))


def estimate_eta(q, phidot, geom: RobotGeometry, method: str = "IT", *, it_params: ITParams | None = None,
                 mu_tol: float = 1e-3, oracle_params: OracleParams = ORACLE_DEFAULT, num_threads: int | None = None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The H state η̂ = (λ̂, μ̂) from the sensors: steering angles q and wheel speeds φ̇.

    λ̂ is :func:`estimate_icr` (default IT); μ̂ the least-squares fit of r_k φ̇_k = μ c_k(λ̂) over
    the wheels (:func:`~estimation.kinematics.mu_from_wheel_speeds`, with S(λ̂) for the angles);
    (λ̂, μ̂) then takes the sign of :func:`~estimation.hrep.canonical_eta` (μ̂ > 0 when
    |μ̂| > ``mu_tol``).

    Args:
        q: (n,) or (N, n) measured steering angles [rad]; phidot: same shape, wheel speeds [rad/s].
        method, it_params, oracle_params, num_threads: as :func:`estimate_icr`.

    Returns:
        ``(λ̂, μ̂, S(λ̂), qua)``: (3,)/(N, 3); scalar/(N,); the steering configuration of the
        estimate (n,)/(N, n), a wheel whose axis holds λ̂ taking its measured angle; and
        ``quality(S(λ̂), q)`` of eq. (28)–(29), scalar/(N,): how well the propulsion axes define
        the ICR.

    Unlimited steering (``geom.unlimited_steering``): q may be any angle; each wheel's distance
    to the surface is taken modulo π (:meth:`RobotGeometry.steering_difference`) and S(λ̂) is the
    angle of each axis nearest the measured one. A measured angle outside the steering range
    is the same axis as its wrapped angle with the wheel rolling the other
    way, so its φ̇ counts with the opposite sign in μ̂ (unlimited steering; with stops a measured
    angle past a stop is wrapped to the other stop, its φ̇ unchanged).
    """
    _check_method(method)
    mu_tol = check_nonnegative("mu_tol [m/s]", mu_tol)
    threads = check_threads(num_threads)
    flat, batch, shift = _prepare(q, geom, shifts=True)
    ph = np.array(_real_array(phidot, "phidot"), dtype=np.float64)  # a private copy: the kernel scales it in place
    if ph.shape != np.shape(q):
        raise ValueError(f"phidot must have the shape of q {np.shape(q)}, got {ph.shape}")
    if not np.isfinite(ph).all():
        raise ValueError("phidot contains NaN or inf")
    ph = ph.reshape(-1, geom.n)
    if shift is not None and geom.unlimited_steering:
        # a wheel whose angle was taken by an odd multiple of π rolls the other way at the
        # wrapped angle: its speed changes sign with it (r φ̇ = μ c(β), c(β + π) = −c(β)).
        # (Limited steering: a measured angle past a stop is noise at the stop; wrapping it to
        # the other stop without turning its speed is the behaviour the default figures were
        # measured with, kept as it is.)
        ph = np.where(np.mod(np.rint(shift / np.pi), 2.0) != 0.0, -ph, ph)
    lam = _estimate_flat(flat, geom, method, it_params, oracle_params, threads)
    beta = np.empty_like(flat)
    mu = np.empty(flat.shape[0])
    qua = np.empty(flat.shape[0])
    _ETA.run(threads, flat.shape[0], lam, flat, ph, geom.a_minus_l, geom.a_perp, geom.b, geom.r, float(geom.steer_max),
             float(mu_tol), QUALITY_F, beta, mu, qua, bool(geom.unlimited_steering))
    if shift is not None and geom.unlimited_steering:
        beta += shift  # S(λ̂) as the angles nearest the measured ones
    return lam.reshape(batch + (3,)), mu.reshape(batch), beta.reshape(batch + (geom.n,)), qua.reshape(batch)


@njit(cache=True)
def _eta_it_rows(q, phidot, E, P, b, r, steer_min, steer_max, unlimited, eps_delta, eps_lambda, max_iter, min_step,
                 n_starts, race, accept_d2, mu_tol, f, lam, mu, beta, qua) -> None:
    """:func:`estimate_eta` with IT on (N, n) rows in one compiled call: the angles outside the
    steering range wrapped as :func:`_prepare` wraps them (unlimited steering: a wheel taken by an
    odd multiple of π has its speed turned, and S(λ̂) is moved back by the shift), IT, then μ̂,
    S(λ̂), qua and the sign."""
    N, n = q.shape
    flat, ph, shift = np.empty((N, n)), np.empty((N, n)), np.zeros((N, n))
    wrapped = False
    for i in range(N):
        for k in range(n):
            wrapped = wrapped or q[i, k] > steer_max or q[i, k] <= steer_min
    for i in range(N):
        for k in range(n):
            x = q[i, k]
            w = x
            if x > steer_max or x <= steer_min:
                w = steer_max - np.mod(steer_max - x, np.pi)  # RobotGeometry.wrap_steering
            flat[i, k] = w
            shift[i, k] = x - w
            p = phidot[i, k]
            if unlimited and wrapped and np.mod(np.rint(shift[i, k] / np.pi), 2.0) != 0.0:
                p = -p
            ph[i, k] = p
    d2, iters, starts = np.empty(N), np.empty(N, dtype=np.int64), np.empty(N, dtype=np.int64)
    it_kernel_batch(flat, E, P, steer_max, eps_delta, eps_lambda, max_iter, min_step, n_starts, race, accept_d2, lam,
                    d2, iters, starts, np.empty(N, dtype=np.bool_), unlimited)
    _eta_kernel(lam, flat, ph, E, P, b, r, steer_max, mu_tol, f, beta, mu, qua, np.empty(n), unlimited)
    if unlimited and wrapped:
        for i in range(N):
            for k in range(n):
                beta[i, k] = beta[i, k] + shift[i, k]


def estimate_eta_rows(q: np.ndarray, phidot: np.ndarray, geom: RobotGeometry, mu_tol: float, lam: np.ndarray,
                      mu: np.ndarray, beta: np.ndarray, qua: np.ndarray, params: ITParams = IT_PAPER) -> None:
    """:func:`estimate_eta` (IT) of (N, n) measurements the caller already checked (finite float64
    arrays of the right shapes: the env's sensor readings), written into ``lam`` (N, 3), ``mu``
    (N,), ``beta`` (N, n), ``qua`` (N,): the same bits, without the per-call checks and
    allocations (the env's hot path; ``tests/estimation/test_estimators.py`` pins it against
    :func:`estimate_eta`)."""
    _eta_it_rows(q, phidot, geom.a_minus_l, geom.a_perp, geom.b, geom.r, float(geom.steer_min), float(geom.steer_max),
                 bool(geom.unlimited_steering), params.eps_delta, params.eps_lambda, int(params.max_iter),
                 params.min_step, int(params.n_starts), params.race_iter_or_paper, params.accept_d2(geom.n),
                 float(mu_tol), QUALITY_F, lam, mu, beta, qua)
