r"""Partial correlations and SIN simultaneous p-values (Drton & Perlman 2004).

The per-time-of-day concentration graph of ``method="sin"``: partial correlations
:math:`\hat\rho_{ij} = -P_{ij}/\sqrt{P_{ii}P_{jj}}` with :math:`P = S^{-1}`, Fisher z
statistics and Šidák or Holm simultaneous p-values. Everything works on stacks
(..., n, n) of covariance or correlation matrices.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.special import ndtr

from ..errors import DataError

__all__ = ["partial_correlations", "sin_pvalues"]

_SINGULAR_PII = 1e10
"""Largest admissible diagonal of the inverse correlation matrix, 1/(1 − R²_i): above it a
zone is (numerically) a linear combination of the others and partial correlations
are rounding noise."""


def _as_stack(S, name="S") -> np.ndarray:
    S = np.asarray(S, dtype=float)
    if S.ndim < 2 or S.shape[-1] != S.shape[-2]:
        raise DataError(f"{name} must be a square matrix or a stack of them (..., n, n), "
                        f"found shape {S.shape}")
    if S.shape[-1] < 2:
        raise DataError(f"{name} must have at least 2 variables, found {S.shape[-1]}")
    if not np.all(np.isfinite(S)):
        raise DataError(f"{name} has non-finite entries")
    if not np.allclose(S, np.swapaxes(S, -1, -2), rtol=1e-10, atol=0):
        raise DataError(f"{name} is not symmetric")
    return S


def _where(idx, batch_shape) -> str:
    return f" at index {tuple(int(i) for i in idx)}" if batch_shape else ""


def _correlation(S: np.ndarray):
    """Correlation matrices and a mask of stack entries with a zero/negative variance."""
    var = np.diagonal(S, axis1=-2, axis2=-1)
    bad = (var <= 0).any(axis=-1)
    d = np.sqrt(np.where(var > 0, var, 1.0))
    R = S / d[..., :, None] / d[..., None, :]
    return R, bad


def _partial(R: np.ndarray):
    """Partial correlations and precision of correlation matrices; mask of singular ones."""
    B = R.reshape((-1,) + R.shape[-2:])
    P = np.empty_like(B)
    bad = np.zeros(len(B), dtype=bool)
    try:
        P[:] = np.linalg.inv(B)
    except np.linalg.LinAlgError:  # an exactly singular entry: find it one by one
        for i, M in enumerate(B):
            try:
                P[i] = np.linalg.inv(M)
            except np.linalg.LinAlgError:
                P[i], bad[i] = np.eye(len(M)), True
    P = P.reshape(R.shape)
    bad = bad.reshape(R.shape[:-2])
    dP = np.diagonal(P, axis1=-2, axis2=-1)
    # for a positive definite correlation matrix P_ii = 1/(1 - R²_i) >= 1
    bad |= (~np.isfinite(P).all(axis=(-2, -1)) | (dP < 1 - 1e-8).any(-1)
            | (dP > _SINGULAR_PII).any(-1))
    dP = np.sqrt(np.where(dP > 0, dP, 1.0))
    pc = -P / dP[..., :, None] / dP[..., None, :]
    n = R.shape[-1]
    pc[..., np.arange(n), np.arange(n)] = 1.0
    return np.clip(pc, -1.0, 1.0), P, bad


def partial_correlations(S) -> np.ndarray:
    r"""Partial correlation of every pair given all other variables.

    .. math:: \rho_{ij \cdot \text{rest}} = -P_{ij} / \sqrt{P_{ii} P_{jj}},\quad P = S^{-1}

    Parameters
    ----------
    S : array_like, shape (n, n) or (..., n, n)
        Covariance or correlation matrix (the result is the same).

    Returns
    -------
    ndarray, same shape as S
        Partial correlations, ones on the diagonal.

    Raises
    ------
    DataError
        If S is not symmetric, has a variable with zero variance, or is (numerically)
        singular; the message gives the offending index of a stack.
    """
    S = _as_stack(S)
    R, bad_var = _correlation(S)
    pc, _, bad = _partial(R)
    _raise_bad(bad_var, bad, S.shape[:-2])
    return pc


def _raise_bad(bad_var, bad, batch_shape):
    if np.any(bad_var):
        idx = np.argwhere(np.atleast_1d(bad_var))[0]
        raise DataError(f"S has a variable with zero variance{_where(idx, batch_shape)}")
    if np.any(bad):
        idx = np.argwhere(np.atleast_1d(bad))[0]
        raise DataError(f"S is singular or not positive definite{_where(idx, batch_shape)}: a "
                        "variable is a linear combination of the others")


def _check_n_samples(n_samples, n):
    if int(n_samples) != n_samples or n_samples < 1:
        raise DataError(f"n_samples must be a positive integer, found {n_samples!r}")
    if n_samples < n + 2:
        raise DataError(f"SIN needs n_samples >= n + 2 = {n + 2} (Fisher z uses sqrt(N - n - 1)); "
                        f"found N = {int(n_samples)} samples for n = {n} variables; use more "
                        "samples (days) or method='glasso'")


def _sin_from_partial(pc: np.ndarray, n_samples: int, adjust: str) -> np.ndarray:
    n = pc.shape[-1]
    iu = np.triu_indices(n, 1)
    r = pc[..., iu[0], iu[1]]
    with np.errstate(divide="ignore"):
        z = np.arctanh(np.abs(r)) * math.sqrt(n_samples - n - 1)
    p_raw = 2.0 * ndtr(-z)
    E = r.shape[-1]
    if adjust == "sidak":
        with np.errstate(divide="ignore"):
            p = -np.expm1(E * np.log1p(-p_raw))  # 1 - (1 - p)^E without cancellation
    elif adjust == "holm":
        order = np.argsort(p_raw, axis=-1, kind="stable")
        ps = np.take_along_axis(p_raw, order, axis=-1)
        ps = np.maximum.accumulate(np.minimum(1.0, (E - np.arange(E)) * ps), axis=-1)
        p = np.empty_like(ps)
        np.put_along_axis(p, order, ps, axis=-1)
    elif adjust == "none":
        p = p_raw
    else:
        raise ValueError(f"adjust must be 'sidak', 'holm' or 'none', found {adjust!r}")
    out = np.full(pc.shape, np.nan)
    out[..., iu[0], iu[1]] = p
    out[..., iu[1], iu[0]] = p
    return out


def sin_pvalues(S, n_samples: int, adjust: str = "sidak") -> np.ndarray:
    r"""Simultaneous p-values of the partial correlations (Drton & Perlman 2004, SIN).

    For every pair :math:`i < j` of the :math:`n` variables,

    .. math::

        z_{ij} = \operatorname{atanh}(\hat\rho_{ij\cdot\text{rest}})\sqrt{N - n - 1},\qquad
        p_{ij} = 2\,(1 - \Phi(|z_{ij}|)),

    and the simultaneous p-value is Šidák's :math:`1 - (1 - p_{ij})^{n(n-1)/2}`
    (``adjust="sidak"``) or Holm's step-down adjusted p-value (``"holm"``). The edge
    :math:`i - j` belongs to the SIN graph at level :math:`\alpha` when its simultaneous
    p-value is :math:`\le \alpha`; then the probability of any false edge is at most
    :math:`\alpha` (asymptotically).

    Parameters
    ----------
    S : array_like, shape (n, n) or (K, n, n)
        Sample covariance or correlation matrix (same answer), or a stack of them.
    n_samples : int
        Number of samples N behind S. Needs ``N >= n + 2``.
    adjust : {"sidak", "holm", "none"}
        Multiple-testing adjustment; "none" returns the raw p-values.

    Returns
    -------
    ndarray, same shape as S
        Symmetric p-values in [0, 1]; NaN on the diagonal.

    Raises
    ------
    DataError
        If ``N < n + 2``, S is not symmetric, has a zero variance or is singular.

    Examples
    --------
    >>> S = [[1, .5, .5], [.5, 1, .5], [.5, .5, 1]]
    >>> round(float(sin_pvalues(S, 20)[0, 1]), 4)
    0.4192
    """
    S = _as_stack(S)
    n = S.shape[-1]
    _check_n_samples(n_samples, n)
    R, bad_var = _correlation(S)
    pc, _, bad = _partial(R)
    _raise_bad(bad_var, bad, S.shape[:-2])
    return _sin_from_partial(pc, int(n_samples), adjust)
