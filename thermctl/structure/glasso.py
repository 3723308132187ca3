r"""Graphical lasso vectorised over time indices: ADMM solver, level penalty, CV over days.

The per-time-of-day concentration graph of ``method="glasso"``: the scikit-learn
objective (:func:`sklearn.covariance.graphical_lasso`) solved by ADMM for a whole stack
of correlation matrices at once, the Banerjee et al. (2008) penalty for a level, and
the held-out likelihood of a penalty grid in cross-validation over blocks of days.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
from scipy.stats import t as student_t

from ..errors import ConvergenceWarning, DataError

__all__ = ["graphical_lasso_batch", "level_penalty"]


def _soft_offdiag(A, t):
    Z = np.sign(A) * np.maximum(np.abs(A) - t[:, None, None], 0.0)
    n = A.shape[-1]
    Z[:, np.arange(n), np.arange(n)] = A[:, np.arange(n), np.arange(n)]
    return Z


def graphical_lasso_batch(S, alpha, *, max_iter: int = 2000, tol: float = 1e-5,
                          init=None):
    r"""Graphical lasso for a stack of covariance matrices, solved by ADMM.

    Minimises, independently for every matrix of the stack, the objective of
    :func:`sklearn.covariance.graphical_lasso`,

    .. math::

        \operatorname{tr}(S\Theta) - \log\det\Theta + \alpha \sum_{i \ne j} |\Theta_{ij}|,

    by the ADMM of Boyd et al. (2011, §6.5) with residual balancing of the step ρ.
    The returned precision is the sparse ADMM variable, so its zeros are exact.

    Parameters
    ----------
    S : array_like, shape (B, n, n)
        Covariance (usually correlation) matrices.
    alpha : float or array_like, shape (B,)
        Penalty, >= 0.
    max_iter : int
        Iteration limit; unconverged entries raise a :class:`ConvergenceWarning`.
    tol : float
        Relative primal and dual residual tolerance.
    init : tuple (Z, U) of ndarray, optional
        Warm start (the ``state`` of an earlier call on the same shapes).

    Returns
    -------
    precision : ndarray, shape (B, n, n)
        Sparse symmetric precision matrices.
    state : tuple (Z, U)
        For a warm start.
    n_iter : ndarray of int, shape (B,)
    """
    S = np.asarray(S, dtype=float)
    B, n, _ = S.shape
    alpha = np.broadcast_to(np.asarray(alpha, dtype=float), (B,)).copy()
    if np.any(alpha < 0):
        raise ValueError(f"alpha must be >= 0, found {alpha.min()}")
    if init is None:
        Z = np.broadcast_to(np.eye(n), (B, n, n)).copy()
        U = np.zeros((B, n, n))
    else:
        Z, U = (np.array(a, dtype=float) for a in init)
    rho = np.ones(B)
    n_iter = np.zeros(B, dtype=int)
    active = np.arange(B)
    for it in range(1, max_iter + 1):
        Za, Ua, ra, Sa = Z[active], U[active], rho[active], S[active]
        lam, Q = np.linalg.eigh(ra[:, None, None] * (Za - Ua) - Sa)
        th = (lam + np.sqrt(lam**2 + 4 * ra[:, None])) / (2 * ra[:, None])
        Th = (Q * th[:, None, :]) @ np.swapaxes(Q, -1, -2)
        Zn = _soft_offdiag(Th + Ua, alpha[active] / ra)
        Un = Ua + Th - Zn
        r = np.linalg.norm(Th - Zn, axis=(1, 2))
        s = ra * np.linalg.norm(Zn - Za, axis=(1, 2))
        eps_p = tol * (n + np.maximum(np.linalg.norm(Th, axis=(1, 2)),
                                      np.linalg.norm(Zn, axis=(1, 2))))
        eps_d = tol * (n + ra * np.linalg.norm(Un, axis=(1, 2)))
        Z[active], U[active] = Zn, Un
        n_iter[active] = it
        done = (r <= eps_p) & (s <= eps_d)
        # residual balancing (Boyd et al. 2011, eq. 3.13); U is scaled by 1/rho
        up, down = (r > 10 * s) & ~done, (s > 10 * r) & ~done
        rho[active[up]] *= 2.0
        U[active[up]] /= 2.0
        rho[active[down]] /= 2.0
        U[active[down]] *= 2.0
        active = active[~done]
        if active.size == 0:
            break
    if active.size:
        warnings.warn(f"graphical lasso (ADMM): {active.size} of {B} problems not converged "
                      f"after max_iter={max_iter} iterations", ConvergenceWarning, stacklevel=2)
    Z = 0.5 * (Z + np.swapaxes(Z, -1, -2))
    return Z, (Z.copy(), U), n_iter


def level_penalty(n_samples: int, n: int, level: float = 0.05) -> float:
    r"""Graphical-lasso penalty that controls false connections at a given level.

    Banerjee, El Ghaoui & d'Aspremont (2008), *Model selection through sparse maximum
    likelihood estimation*, JMLR 9, Theorem 2, on the correlation scale:

    .. math::

        \lambda(\alpha) = \frac{t}{\sqrt{N - 2 + t^2}},\qquad
        t = t_{N-2}^{-1}\!\left(1 - \frac{\alpha}{2n^2}\right),

    with which the probability that the estimate joins two variables that are in
    different connectivity components of the true graph is at most α. It plays the
    role of SIN's level for the graphical lasso.

    Parameters
    ----------
    n_samples : int
        Number of samples N (days), >= 3.
    n : int
        Number of variables (zones).
    level : float
        α in (0, 1).

    Returns
    -------
    float
        Penalty on the correlation scale, in (0, 1).
    """
    if n_samples < 3:
        raise DataError(f"the level penalty needs n_samples >= 3, found {n_samples}")
    t = float(student_t.isf(level / (2.0 * n * n), n_samples - 2))
    return t / math.sqrt(n_samples - 2 + t * t)


def _gram(A: np.ndarray) -> np.ndarray:
    """(N, K, n) -> (K, n, n) sums of outer products over the first axis (BLAS matmul)."""
    return np.matmul(A.transpose(1, 2, 0), A.transpose(1, 0, 2))


def _glasso_cv(X: np.ndarray, alphas: np.ndarray, n_folds: int, times: np.ndarray,
               max_iter: int, tol: float):
    """Held-out Gaussian log-likelihood of each penalty, summed over folds and times.

    X: (N, K, n) standardised data. Folds are contiguous blocks of days. Penalties not
    tried (early stop) score -inf.
    """
    N = X.shape[0]
    folds = np.array_split(np.arange(N), n_folds)
    Rtr, Ste = [], []
    for test in folds:
        train = np.setdiff1d(np.arange(N), test)
        Xtr, Xte = X[train][:, times], X[test][:, times]
        mu, sd = Xtr.mean(0), Xtr.std(0)
        sd = np.where(sd > 0, sd, 1.0)
        A = (Xtr - mu) / sd
        Rtr.append(_gram(A) / len(train))
        Bte = (Xte - mu) / sd
        Ste.append(_gram(Bte) / len(test))
    Rtr, Ste = np.concatenate(Rtr), np.concatenate(Ste)
    scores = np.full(len(alphas), -np.inf)
    state = None
    for a_i, a in enumerate(alphas):  # decreasing: warm start from the sparser solution
        P, state, _ = graphical_lasso_batch(Rtr, a, max_iter=max_iter, tol=tol, init=state)
        sign, logdet = np.linalg.slogdet(P)
        ll = np.where(sign > 0, logdet - np.einsum("kij,kji->k", Ste, P), -np.inf)
        scores[a_i] = ll.sum()
        # stop once two smaller penalties in a row predict worse than the best: small
        # penalties are the slow ones (near-singular when a fold has fewer days than zones)
        if a_i >= 2 and max(scores[a_i], scores[a_i - 1]) < scores[:a_i - 1].max():
            break
    return scores
