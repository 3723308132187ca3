r"""Continuous–discrete Kalman filtering for linear stochastic models, in CasADi and numpy.

The model is

.. math::

    dx = (A x + B w)\,dt + d\beta, \quad \mathrm{Cov}(d\beta) = \Sigma\,dt, \qquad
    y_k = C x_k + v_k, \quad v_k \sim N(0, R),

with the input ``w`` held over each step ``dt`` (zero-order hold). Its exact
discretisation is :math:`x_{k+1} = \Phi x_k + \Gamma w_k + \varepsilon_k`,
:math:`\mathrm{Cov}(\varepsilon_k) = Q_d = \int_0^{dt} e^{As}\Sigma e^{A^T s} ds`.

Why the functions below look the way they do:

* **Stiff modes.** Convection edges have time constants of seconds and the data step is
  minutes (``|λ|·dt`` up to ~10³). Van Loan's block exponential contains
  :math:`e^{-A\,dt}`, which overflows there. :func:`discretize` therefore evaluates Van
  Loan's blocks at ``h = dt/2^s`` (norm ≤ 1/4, Taylor series) and doubles back with the
  exact recurrences :math:`\Phi(2h) = \Phi(h)^2`, :math:`\Gamma(2h) = \Gamma(h) + \Phi(h)\Gamma(h)`,
  :math:`Q(2h) = \Phi(h) Q(h) \Phi(h)^T + Q(h)`; every operation is stable and
  differentiable, so CasADi gives exact derivatives (there is no SX ``expm``).
* **Cost.** A time-varying covariance recursion costs ~2n³ per step, and its reverse-mode
  derivative stores every ``P_k``. On gap-free stretches of an LTI model, ``P_k``
  converges to the stationary solution of the filter Riccati equation, which
  :func:`dare_sda` computes by the structure-preserving doubling algorithm in a few
  dozen n³ operations per parameter value. The likelihood with ``P_0 = P_∞`` is then
  *exact* and its recursion is linear in the data (:func:`chunked_recursion`).
* **BLAS.** The dense products of the recursion and of the doubling go through
  :func:`thermctl.estimate.likelihood._dense.dense_mtimes` (numpy inside the graph, exact
  derivatives of every order): CasADi's own dense product runs at 0.5–1.4 Gflop/s.
* :class:`DareCallback` solves the same Riccati equation in numpy and gives CasADi its
  exact reverse derivative through the adjoint Stein equation (≈3× faster than the
  doubling graph for 60 states; used by default).
* :func:`kalman_filter` is the plain time-varying filter (Joseph form, missing outputs
  dropped row by row) in numpy: the reference for tests and for diagnostics. Its two steps,
  :func:`filter_update` and :func:`filter_predict`, and :func:`process_noise_np` (the
  numpy form of :func:`discretize`'s ``Q_d``) are what every other filter in the package
  uses (the export's stationary filter, the MPC examples' online filter).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.linalg as sla

from ..._blas import single_thread_blas
from ...errors import EstimationError
from ._dense import _view, dense_mtimes, linear_recursion

__all__ = ["n_squarings", "discretize", "discretize_np", "dare_sda", "dare_np",
           "stein_np", "DareCallback", "process_noise_np",
           "stationary_filter", "kalman_filter", "filter_update", "filter_predict",
           "KalmanResult", "chunked_recursion", "LOG2PI"]

LOG2PI = math.log(2.0 * math.pi)


_TAYLOR_ORDER = 10      # with ||M|| <= 1/4 the truncation error is 0.25^11/11! ≈ 6e-15
_NORM_TARGET = 0.25


def _eye(n):
    return ca.DM.eye(n)


def n_squarings(norm_dt: float, target: float = _NORM_TARGET) -> int:
    """Number of halvings of ``dt`` that brings ``‖A‖·dt`` below ``target``.

    Parameters
    ----------
    norm_dt : float
        An upper bound of ``‖A‖₁·dt`` over the parameter range [-].
    target : float
        Norm at which :func:`discretize`'s Taylor polynomials are used [-].
    """
    if not np.isfinite(norm_dt):
        raise EstimationError(f"state matrix norm bound is not finite ({norm_dt})")
    return max(0, int(math.ceil(math.log2(max(norm_dt, 1e-300) / target))))


def discretize(A, B, Sigma, dt: float, squarings: int, order: int = _TAYLOR_ORDER):
    r"""Exact ZOH discretisation with process noise, differentiable in CasADi.

    Parameters
    ----------
    A : casadi.MX or DM, shape (n, n)
        State matrix [1/s].
    B : casadi.MX or DM, shape (n, m)
        Input matrix [state unit per input unit per s].
    Sigma : casadi.MX or DM, shape (n, n)
        Diffusion (process noise intensity) [state unit² / s], symmetric PSD.
    dt : float
        Step [s].
    squarings : int
        ``s`` with ``‖A‖·dt/2^s ≤ 1/4`` over the whole parameter range
        (:func:`n_squarings`).
    order : int
        Taylor degree at the small step.

    Returns
    -------
    Phi : shape (n, n)
        :math:`e^{A\,dt}`.
    Gamma : shape (n, m)
        :math:`\int_0^{dt} e^{As} ds\, B`.
    Qd : shape (n, n)
        :math:`\int_0^{dt} e^{As}\Sigma e^{A^T s} ds` (symmetrised).
    """
    n = A.shape[0]
    h = dt / 2.0 ** squarings
    mt = dense_mtimes if isinstance(A, ca.MX) else ca.mtimes
    # Σ is diagonal in every model of this package: its products are row scalings (n²),
    # which CasADi's sparse product does; a dense Σ goes through BLAS like the rest
    mts = ca.mtimes if Sigma.nnz() <= n else mt
    P, G, S = A * h, B * h, Sigma * h
    I = _eye(n)
    # The Taylor polynomial (Horner form) of two block matrices, by blocks:
    #   [[P, G], [0, 0]]     -> [[Phi, Gamma], [0, I]]
    #   [[-P, S], [0, P^T]]  -> [[*, F12], [0, F22]]   (Van Loan: Q = F22^T F12)
    # F22 is Phi^T at every Horner stage (a polynomial in P commutes with P), the top-left
    # block of Van Loan's is not needed and the bottom-right of the first stays I. So a stage
    # costs two n×n products and one n×m, where the whole blocks cost an (n+m)-square and a
    # 2n-square product (8 n³): on the twin house N2 (123 states) the default identify took
    # 175 s instead of 187 s (279 instead of 303 CPU s), the same selection path. The
    # products go through BLAS (dense_mtimes): the blocks fill in after a few terms, and
    # CasADi's own loop was slower (twin house, 116 states: a gradient 0.128 → 0.095 s).
    E = I + P / order
    Gm = G / order
    F12 = S / order
    for k in range(order - 1, 0, -1):
        F12 = (mts(S, E.T) - mt(P, F12)) / k
        Gm = (G + mt(P, Gm)) / k
        E = I + mt(P, E) / k
    Phi, Gam = E, Gm
    Q = mt(Phi, F12)
    Q = 0.5 * (Q + Q.T)
    for _ in range(squarings):
        Q = mt(mt(Phi, Q), Phi.T) + Q
        Gam = Gam + mt(Phi, Gam)
        Phi = mt(Phi, Phi)
    Q = 0.5 * (Q + Q.T)
    return Phi, Gam, Q


def discretize_np(A, B, Sigma, dt: float):
    """Numpy reference of :func:`discretize`: scipy ``expm`` and the modal formula for ``Q_d``.

    ``Q_d`` is computed modally (``A`` must be diagonalisable with real eigenvalues, true
    for RC networks and their random-walk augmentation):
    ``Q̃_ij = Σ̃_ij (e^{(λ_i+λ_j)dt} − 1)/(λ_i+λ_j)`` with ``Q̃ = V⁻¹ Q V⁻ᵀ``, and ``dt`` where
    ``λ_i + λ_j = 0``. An independent route for tests.

    Parameters
    ----------
    A : ndarray, shape (n, n)
        [1/s]
    B : ndarray, shape (n, m)
    Sigma : ndarray, shape (n, n)
        [unit²/s]
    dt : float
        [s]
    """
    A = np.asarray(A, dtype=float)
    B = np.asarray(B, dtype=float)
    n, m = A.shape[0], B.shape[1]
    Mx = np.zeros((n + m, n + m))
    Mx[:n, :n], Mx[:n, n:] = A * dt, B * dt
    E = sla.expm(Mx)
    lam, V = np.linalg.eig(A)
    lam, V = lam.real, V.real
    Vi = np.linalg.inv(V)
    St = Vi @ np.asarray(Sigma, dtype=float) @ Vi.T
    s = lam[:, None] + lam[None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        f = np.where(np.abs(s) * dt > 1e-12, np.expm1(s * dt) / s, dt)
    Q = V @ (St * f) @ V.T
    return E[:n, :n], E[:n, n:], 0.5 * (Q + Q.T)


def process_noise_np(A, Sigma, dt: float):
    r"""``Q_d = ∫₀^dt e^{As} Σ e^{Aᵀs} ds`` in numpy, the way :func:`discretize` computes it.

    Van Loan's block exponential at the full step holds ``e^{-A dt}``, which overflows for
    the convection edges (time constants of seconds against a step of minutes), so it is
    taken at ``h = dt/2^s`` with ``‖A‖₁ h ≤ 1/4`` and doubled exactly:
    ``Q(2h) = Φ(h) Q(h) Φ(h)ᵀ + Q(h)``, ``Φ(2h) = Φ(h)²``. Unlike :func:`discretize_np`
    (the modal reference) it needs no eigen-decomposition, so it also holds for
    augmented models with defective eigenvalues.

    Parameters
    ----------
    A : ndarray, shape (n, n)
        State matrix [1/s].
    Sigma : ndarray, shape (n, n)
        Process noise intensity [state unit²/s], symmetric PSD.
    dt : float
        Step [s].

    Returns
    -------
    ndarray, shape (n, n)
        ``Q_d`` [state unit²] (symmetrised).
    """
    A = np.asarray(A, dtype=float)
    n = A.shape[0]
    norm = float(np.abs(A).sum(axis=0).max()) * dt
    s = n_squarings(norm) if norm > _NORM_TARGET else 0
    h = dt / 2.0 ** s
    M = np.zeros((2 * n, 2 * n))
    M[:n, :n] = -A * h
    M[:n, n:] = np.asarray(Sigma, dtype=float) * h
    M[n:, n:] = A.T * h
    E = sla.expm(M)
    Phi = E[n:, n:].T
    Qd = Phi @ E[:n, n:]
    for _ in range(s):
        Qd = Phi @ Qd @ Phi.T + Qd
        Phi = Phi @ Phi
    return 0.5 * (Qd + Qd.T)


def dare_sda(Phi, C, Qd, R, iterations: int = 40):
    r"""Stationary predicted covariance of the Kalman filter by structure-preserving doubling.

    Solves :math:`P = \Phi P \Phi^T - \Phi P C^T (C P C^T + R)^{-1} C P \Phi^T + Q_d`
    (Chu, Fan & Lin 2005): with :math:`A_0 = \Phi^T`, :math:`G_0 = C^T R^{-1} C`,
    :math:`H_0 = Q_d`, iterate
    :math:`W = I + G H`, :math:`A \leftarrow A W^{-1} A`,
    :math:`G \leftarrow G + A W^{-1} G A^T`, :math:`H \leftarrow H + A^T H W^{-1} A`;
    ``H`` converges quadratically to ``P``: after ``k`` iterations the error is of the
    order of :math:`\rho^{2^{k+1}}`, ρ the spectral radius of the closed-loop filter, so
    40 iterations suffice even for modes with time constants of years. Requires
    ``(Φ, C)`` detectable (random-walk states only on measured outputs).

    Parameters
    ----------
    Phi : shape (n, n)
    C : shape (ny, n)
    Qd : shape (n, n)
    R : shape (ny, ny)
    iterations : int

    Returns
    -------
    P : shape (n, n)
        Stationary one-step-ahead (predicted) state covariance.
    change : scalar
        Max-abs change of ``P`` in the last iteration (convergence check).
    """
    n = Phi.shape[0]
    I = _eye(n)
    Ak = Phi.T
    Gk = ca.mtimes([C.T, ca.solve(R, C)])
    Gk = 0.5 * (Gk + Gk.T)
    Hk = Qd
    change = None
    for _ in range(iterations):
        W = I + ca.mtimes(Gk, Hk)
        WiA = ca.solve(W, Ak)
        WiG = ca.solve(W, Gk)
        A_new = ca.mtimes(Ak, WiA)
        G_new = Gk + ca.mtimes([Ak, WiG, Ak.T])
        H_new = Hk + ca.mtimes([Ak.T, Hk, WiA])
        change = ca.mmax(ca.fabs(H_new - Hk))
        Ak = A_new
        Gk = 0.5 * (G_new + G_new.T)
        Hk = 0.5 * (H_new + H_new.T)
    return Hk, change


def stationary_filter(Phi, C, Qd, R, iterations: int = 40, dare=None):
    """Stationary gains: ``P`` (predicted), ``S = C P Cᵀ + R``, filter gain ``Kf = P Cᵀ S⁻¹``.

    Parameters
    ----------
    Phi, C, Qd, R
        As in :func:`dare_sda`.
    iterations : int
        Doubling iterations in the graph (ignored with ``dare``).
    dare : DareCallback, optional
        Solve the Riccati equation in numpy with an implicit derivative instead.

    Returns
    -------
    P, S, Kf, change
    """
    if dare is not None:
        P = dare(ca.densify(Phi), ca.densify(Qd), ca.densify(R))
        change = ca.MX(0)
    else:
        P, change = dare_sda(Phi, C, Qd, R, iterations)
    S = ca.mtimes([C, P, C.T]) + R
    S = 0.5 * (S + S.T)
    Kf = ca.solve(S, ca.mtimes(C, P)).T
    return P, S, Kf, change


def chunked_recursion(F, GZ, starts, restart, L: int, regime=None):
    r"""All states of ``x_{k+1} = F x_k + g_k`` with a few dozen dense matrix products.

    The time axis is cut into ``M`` chunks of ``L`` steps. Column ``j·M + c`` of ``GZ``
    holds ``g`` at step ``j`` of chunk ``c``. Pass 1 runs all chunks at once from zero;
    the chunk starts are then chained with ``F^L`` (or restarted at a segment's initial
    state); pass 2 adds :math:`F^j x_{c,0}`: ``2L + M`` dense products instead of ``L·M``
    matrix-vector steps. The whole recursion is one graph node evaluated by numpy
    (:func:`~thermctl.estimate.likelihood._dense.linear_recursion`), whose derivatives
    are again recursions: exact gradients and Hessians.

    Parameters
    ----------
    F : casadi.MX, shape (n, n) or (n, n·R)
        With ``regime``: R matrices side by side.
    GZ : casadi.MX, shape (n, L·M)
        Forcing in the chunk layout.
    starts : casadi.MX, shape (n, n_segments)
        Initial state of each segment.
    restart : list of int, length M
        ``restart[c]`` is the segment that chunk ``c`` starts, or -1 if the chunk continues
        the previous one.
    L : int
        Chunk length.
    regime : sequence of int, length L·M, optional
        ``regime[k]``: the matrix of the step out of column ``k`` (a filter whose gain
        switches with the hour). Default: one matrix.

    Returns
    -------
    X : casadi.MX, shape (n, L·M)
        ``x`` at every step, in the chunk layout.
    """
    if not len(restart) or restart[0] < 0:
        raise EstimationError("chunk layout: the first chunk must start a segment")
    return linear_recursion(F, GZ, starts, restart, L, regime)


@dataclass
class KalmanResult:
    """Output of :func:`kalman_filter`.

    Attributes
    ----------
    nll : float
        Negative log-likelihood of the observed outputs (2π term included).
    x_pred, x_filt : ndarray, shape (N, n)
        ``x̂_{k|k-1}`` and ``x̂_{k|k}``.
    innovations : ndarray, shape (N, ny)
        ``y_k − C x̂_{k|k-1}`` (NaN where ``y`` is missing).
    S_diag : ndarray, shape (N, ny)
        Diagonal of the innovation covariance (NaN where missing).
    standardized : ndarray, shape (N, ny)
        ``innovations / sqrt(S_diag)``.
    P_last : ndarray, shape (n, n)
        Predicted covariance after the last step.
    n_obs : int
        Number of scalar observations in ``nll``.
    """

    nll: float
    x_pred: np.ndarray
    x_filt: np.ndarray
    innovations: np.ndarray
    S_diag: np.ndarray
    standardized: np.ndarray
    P_last: np.ndarray
    n_obs: int


def kalman_filter(Phi, Gamma, Qd, C, R, W, Y, x0, P0, skip: int = 0) -> KalmanResult:
    """Time-varying Kalman filter (Joseph form) with missing outputs, in numpy.

    Step ``k``: update with ``y_k`` (rows that are NaN are dropped), add the
    log-likelihood term, then predict with ``w_k``.

    Parameters
    ----------
    Phi, Gamma, Qd : ndarray
        Discrete model (:func:`discretize_np`).
    C : ndarray, shape (ny, n)
    R : ndarray, shape (ny, ny)
        Measurement noise covariance [K²].
    W : ndarray, shape (N, m)
        Inputs held over each step.
    Y : ndarray, shape (N, ny)
        Outputs; NaN where missing.
    x0 : ndarray, shape (n,)
        Prior mean of ``x_0``.
    P0 : ndarray, shape (n, n)
        Prior covariance of ``x_0``.
    skip : int
        Steps at the start whose terms are left out of ``nll`` (burn-in); they still
        update the state.
    """
    with single_thread_blas():
        return _kalman_filter(Phi, Gamma, Qd, C, R, W, Y, x0, P0, skip)


def _kalman_filter(Phi, Gamma, Qd, C, R, W, Y, x0, P0, skip):
    Phi, Gamma, Qd, C, R = (np.asarray(a, dtype=float) for a in (Phi, Gamma, Qd, C, R))
    W = np.asarray(W, dtype=float)
    Y = np.asarray(Y, dtype=float)
    N, ny = Y.shape
    n = Phi.shape[0]
    x = np.asarray(x0, dtype=float).copy()
    P = np.asarray(P0, dtype=float).copy()
    xp = np.empty((N, n))
    xf = np.empty((N, n))
    inn = np.full((N, ny), np.nan)
    Sd = np.full((N, ny), np.nan)
    nll = 0.0
    n_obs = 0
    for k in range(N):
        xp[k] = x
        try:
            x, P, up = filter_update(x, P, Y[k], C, R)
        except FloatingPointError as exc:
            raise FloatingPointError(f"{exc} at step {k}") from None
        if up is not None:
            e, S, Lc, obs = up
            inn[k, obs] = e
            Sd[k, obs] = np.diag(S)
            if k >= skip:
                z = sla.solve_triangular(Lc, e, lower=True)
                nll += 0.5 * (2.0 * np.sum(np.log(np.diag(Lc))) + z @ z + obs.sum() * LOG2PI)
                n_obs += int(obs.sum())
        xf[k] = x
        if k < N - 1:
            x, P = filter_predict(x, P, Phi, Qd, Gamma @ W[k])
    std = inn / np.sqrt(Sd)
    return KalmanResult(float(nll), xp, xf, inn, Sd, std, P, n_obs)


def filter_update(x, P, y, C, R):
    """Measurement update of a Kalman filter (Joseph form), rows of ``y`` that are NaN dropped.

    Parameters
    ----------
    x : ndarray, shape (n,)
        Predicted state ``x̂_{k|k-1}``.
    P : ndarray, shape (n, n)
        Its covariance.
    y : ndarray, shape (ny,)
        Measured outputs; NaN where missing.
    C : ndarray, shape (ny, n)
    R : ndarray, shape (ny, ny)
        Measurement noise covariance [output unit²].

    Returns
    -------
    x, P : ndarray
        Filtered state ``x̂_{k|k}`` and its covariance (unchanged if nothing is observed).
    update : tuple or None
        ``(e, S, Lc, obs)``: innovations of the observed rows, their covariance, its lower
        Cholesky factor and the mask of observed rows; ``None`` if nothing is observed.
    """
    obs = np.isfinite(y)
    if not obs.any():
        return x, P, None
    Ck = C[obs]
    Rk = R[np.ix_(obs, obs)]
    e = y[obs] - Ck @ x
    S = Ck @ P @ Ck.T + Rk
    S = 0.5 * (S + S.T)
    try:
        Lc = np.linalg.cholesky(S)
    except np.linalg.LinAlgError:
        raise FloatingPointError("innovation covariance not positive definite") from None
    K = sla.cho_solve((Lc, True), Ck @ P).T      # = (S^{-1} C P)^T
    x = x + K @ e
    IKC = np.eye(x.shape[0]) - K @ Ck
    # Joseph form: P stays symmetric positive semi-definite whatever the gain's round-off
    P = IKC @ P @ IKC.T + K @ Rk @ K.T
    P = 0.5 * (P + P.T)
    return x, P, (e, S, Lc, obs)


def filter_predict(x, P, Phi, Qd, drift):
    """Time update of a Kalman filter over one step: ``x⁺ = Φ x + drift``, ``P⁺ = Φ P Φᵀ + Q_d``.

    Parameters
    ----------
    x : ndarray, shape (n,)
    P : ndarray, shape (n, n)
    Phi : ndarray, shape (n, n)
        State transition over the step.
    Qd : ndarray, shape (n, n)
        Process noise covariance over the step (:func:`process_noise_np`).
    drift : ndarray, shape (n,)
        Effect of the inputs held over the step (``Γ w``).

    Returns
    -------
    x, P : ndarray
    """
    x = Phi @ x + drift
    P = Phi @ P @ Phi.T + Qd
    return x, 0.5 * (P + P.T)


# ---------------------------------------------------------------------------------------
# Stationary Riccati solution as a CasADi callback with an implicit (adjoint) derivative.
#
# The doubling graph above costs ~30 dense n³ steps and their reverse sweep on every
# evaluation; CasADi's own dense kernels are unblocked loops. Solving the DARE in numpy
# (doubling with BLAS, converged to round-off) and differentiating it implicitly is ~10×
# cheaper. With P_f = (I − K C) P and F = Φ(I − K C), the DARE's differential is the
# Stein equation dP = F dP Fᵀ + dΦ P_f Φᵀ + Φ P_f dΦᵀ + dQ + Φ K dR Kᵀ Φᵀ; its adjoint:
# Λ = Fᵀ Λ F + P̄, then Φ̄ = Λ Φ P_f + Λᵀ Φ P_f, Q̄ = Λ, R̄ = Kᵀ Φᵀ Λ Φ K.

def _converged(change: float, last: float, scale: float, tol: float) -> bool:
    """Whether a doubling iteration with max-abs change ``change`` (the one before it:
    ``last``) leaves an error below ``tol·scale``.

    Doubling converges quadratically: near the end the next change is ``K·change²``, and
    it is the error left. ``K`` is read off the last two changes (``change / last²``). On
    the twin house N2 the relative changes ran 4.6e-7, 1.9e-9, 4.6e-14, 8e-29: the third
    is predicted as 3.3e-14 from the first two, so the iteration that only confirmed it
    (one of 13 on every evaluation) is not made. Predictions are trusted only once the
    changes fall fast (each below a hundredth of the one before) and are small.
    """
    if change <= tol * scale:
        return True
    if not (np.isfinite(last) and change <= 1e-6 * scale and change <= 1e-2 * last):
        return False
    return (change / last ** 2) * change ** 2 <= tol * scale


def dare_np(Phi, C, Q, R, tol: float = 1e-13, max_iter: int = 60):
    """Stationary predicted covariance by doubling (numpy; see :func:`dare_sda`).

    Returns
    -------
    P : ndarray, shape (n, n)
    n_iter : int
    """
    n = Phi.shape[0]
    I = np.eye(n)
    Ak = Phi.T.copy()
    Gk = C.T @ np.linalg.solve(R, C)
    Hk = Q.copy()
    last = np.inf
    for it in range(1, max_iter + 1):
        W = I + Gk @ Hk
        lu = sla.lu_factor(W)
        WiA = sla.lu_solve(lu, Ak)
        WiG = sla.lu_solve(lu, Gk)
        H_new = Hk + Ak.T @ Hk @ WiA
        Gk = Gk + Ak @ WiG @ Ak.T
        Gk = 0.5 * (Gk + Gk.T)
        Ak = Ak @ WiA
        H_new = 0.5 * (H_new + H_new.T)
        change = np.max(np.abs(H_new - Hk))
        Hk = H_new
        if _converged(change, last, max(np.max(np.abs(Hk)), 1e-300), tol):
            return Hk, it
        last = change
    if not np.all(np.isfinite(Hk)):
        raise FloatingPointError("stationary Riccati solution diverged (is the model detectable?)")
    return Hk, max_iter


def stein_np(F, M, tol: float = 1e-14, max_iter: int = 64):
    """``X = F X Fᵀ + M`` by doubling (``F`` stable)."""
    X = M.copy()
    Ak = F.copy()
    last = np.inf
    for _ in range(max_iter):
        dX = Ak @ X @ Ak.T
        X = X + dX
        change = np.max(np.abs(dX))
        if _converged(change, last, max(np.max(np.abs(X)), 1e-300), tol):
            break
        Ak = Ak @ Ak
        last = change
    return X


class _DareArgs:
    """What the two Riccati callbacks share: their matrices are n×n, but for ``R`` (argument
    and result 2: ny×ny), and they are read from CasADi's buffers (``eval_buffer``): turning
    DM arguments into numpy arrays went through nested lists and took 10 % of a twin-house
    gradient (py-spy)."""

    def _shape(self, i):
        m = self.ny if i == 2 else self.n
        return (m, m)

    def get_sparsity_in(self, i):
        return ca.Sparsity.dense(*self._shape(i))

    def has_eval_buffer(self):
        return True

    def _views(self, bufs):
        return [_view(b, self._shape(i)) for i, b in enumerate(bufs)]


class _DareReverse(_DareArgs, ca.Callback):
    def __init__(self, name, C, n, ny, opts):
        ca.Callback.__init__(self)
        self.C, self.n, self.ny = C, n, ny
        self.construct(name, {**opts, "enable_fd": True})

    def get_n_in(self):
        return 5          # Phi, Q, R, P (nominal output), P_bar (adjoint seed)

    def get_n_out(self):
        return 3

    def get_sparsity_out(self, i):
        return ca.Sparsity.dense(*self._shape(i))       # Φ̄, Q̄ (n×n), R̄ (ny×ny)

    def eval_buffer(self, arg, res):
        with single_thread_blas():
            out = self._eval(*self._views(arg))
        for r, o in zip(self._views(res), out):
            r[...] = o
        return 0

    def _eval(self, Phi, Q, R, P, Pb):
        C = self.C
        S = C @ P @ C.T + R
        K = np.linalg.solve(S, C @ P).T
        Pf = P - K @ C @ P
        F = Phi - Phi @ K @ C
        Lam = stein_np(F.T, Pb)
        PhiK = Phi @ K
        return [Lam @ Phi @ Pf + Lam.T @ Phi @ Pf, Lam, PhiK.T @ Lam @ PhiK]


class DareCallback(_DareArgs, ca.Callback):
    """``P = dare(Phi, Q, R)`` for a fixed ``C``: numpy doubling, implicit reverse derivative.

    Parameters
    ----------
    name : str
    C : ndarray, shape (ny, n)
    """

    def __init__(self, name: str, C):
        ca.Callback.__init__(self)
        self.C = np.asarray(C, dtype=float)
        self.ny, self.n = self.C.shape
        self.n_iter = 0
        self._rev = None
        self.construct(name, {"enable_fd": False})

    def get_n_in(self):
        return 3

    def get_n_out(self):
        return 1

    def get_sparsity_out(self, i):
        return ca.Sparsity.dense(self.n, self.n)

    def eval_buffer(self, arg, res):
        Phi, Q, R = self._views(arg)
        with single_thread_blas():
            P, self.n_iter = dare_np(Phi, self.C, 0.5 * (Q + Q.T), 0.5 * (R + R.T))
        _view(res[0], (self.n, self.n))[...] = P
        return 0

    def has_reverse(self, nadj):
        return nadj == 1

    def get_reverse(self, nadj, name, inames, onames, opts):
        if self._rev is None:
            self._rev = _DareReverse(name + "_impl", self.C, self.n, self.ny, {})
        Phi = ca.MX.sym("Phi", self.n, self.n)
        Q = ca.MX.sym("Q", self.n, self.n)
        R = ca.MX.sym("R", self.ny, self.ny)
        P = ca.MX.sym("P", self.n, self.n)
        Pb = ca.MX.sym("Pb", self.n, self.n)
        out = self._rev(Phi, Q, R, P, Pb)
        return ca.Function(name, [Phi, Q, R, P, Pb], list(out), inames, onames, opts)
