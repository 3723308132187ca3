r"""Structure identification: which zones exchange air (paper section III-A).

Each day is one sample of the zone temperatures at every time of day. For each
time-of-day index :math:`k = 0, \dots, K-1` (:math:`K = 86400\,\mathrm{s} / \Delta t`)
the :math:`N` days give a sample covariance :math:`S_k` of the :math:`n` measured
zone temperatures, and a concentration graph :math:`\hat G(k)`: an edge
:math:`i - j` when the partial correlation of zones :math:`i, j` given all others
is significantly non-zero. Conduction pairs (walls) are removed and every other
pair gets the score

.. math::

    s_{ij} = \frac{\#\{k : i - j \in \hat G(k)\}}{K}.

Two graph methods:

``sin``
    Drton & Perlman (2004), *Model selection for Gaussian concentration graphs*,
    Biometrika 91, 591-602: partial correlations
    :math:`\hat\rho_{ij} = -P_{ij}/\sqrt{P_{ii}P_{jj}}` with :math:`P = S^{-1}`, Fisher
    :math:`z_{ij} = \operatorname{atanh}(\hat\rho_{ij})\sqrt{N - n - 1}`, raw p-values
    :math:`2(1 - \Phi(|z_{ij}|))` and simultaneous p-values by Šidák,
    :math:`1 - (1 - p_{ij})^{E}` with :math:`E = n(n-1)/2`, or Holm's step-down.
    Needs :math:`N \ge n + 2` days.
``glasso``
    Graphical lasso on the per-time correlation matrix, with the scikit-learn
    objective (:func:`sklearn.covariance.graphical_lasso`: off-diagonal
    :math:`\ell_1` penalty), solved by ADMM vectorised over all time indices
    (scikit-learn's solver, called once per time index, is 10-100× slower here).
    The penalty is chosen by cross-validation over days by default, or set from the
    level (Banerjee et al. 2008), or given. Works for any :math:`N \ge 3`.

Selection rules: ``paper`` gives every measured zone its best-scoring partner;
``threshold`` keeps every pair with :math:`s_{ij} \ge s_{\min}`. Only pairs whose
air path length is known (spec ``distances``) can become convection edges.
"""

from __future__ import annotations

import logging
import math
import warnings
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import pandas as pd
from scipy.special import ndtr
from scipy.stats import t as student_t

from .errors import ConvergenceWarning, DataError, DataWarning
from .network import ThermalNetwork

__all__ = ["DayArray", "ScoredEdge", "StructureIdentifier", "day_array", "partial_correlations",
           "sin_pvalues", "graphical_lasso_batch", "level_penalty", "select_edges"]

logger = logging.getLogger(__name__)

_SINGULAR_PII = 1e10
"""Largest admissible diagonal of the inverse correlation matrix, 1/(1 − R²_i): above it a
zone is (numerically) a linear combination of the others and partial correlations
are rounding noise."""

_CHUNK_BYTES = 64e6  # size of one (chunk, n, n) float array when looping over time indices


# ---------------------------------------------------------------------------
# data shaping
# ---------------------------------------------------------------------------
@dataclass
class DayArray:
    """Zone temperatures arranged as day × time of day × zone.

    Attributes
    ----------
    values : ndarray, shape (N, K, n)
        Temperatures [°C] of the complete days.
    days : list of datetime.date
        The N days used, in order (calendar days in the index's time zone).
    zones : list of str
        The n zones, in column order of ``values``.
    step : float
        Sampling step [s]; ``K = 86400 / step``.
    dropped : list of (datetime.date, str)
        Days left out and why (incomplete, missing values, clock change).
    """

    values: np.ndarray
    days: list
    zones: list
    step: float
    dropped: list

    @property
    def n_times(self) -> int:
        """K, the number of time-of-day indices."""
        return self.values.shape[1]


def _zone_columns(data: pd.DataFrame, zones: Sequence[str]) -> list[str]:
    cols = []
    for z in zones:
        have = [c for c in (f"T:{z}", z) if c in data.columns]
        if not have:
            raise DataError(f"no temperature column for measured zone {z!r}: expected 'T:{z}' "
                            f"or {z!r}; columns are {list(data.columns)[:20]}")
        if len(have) == 2:
            raise DataError(f"zone {z!r} has two temperature columns, 'T:{z}' and {z!r}; keep one")
        cols.append(have[0])
    return cols


def day_array(data: pd.DataFrame, zones: Sequence[str]) -> DayArray:
    """Arrange zone temperatures as day × time-of-day samples.

    Parameters
    ----------
    data : pandas.DataFrame
        Index: a regular ``DatetimeIndex`` (time-zone aware or naive; days are the
        calendar days of the index's time zone), rows may be missing. Columns:
        ``T:<zone>`` or ``<zone>`` temperatures [°C]; other columns are ignored.
    zones : sequence of str
        Zones to use, in this order.

    Returns
    -------
    DayArray
        Complete days only; a day with a missing row, a missing value or a repeated
        time of day (clock change) is left out and listed in ``dropped``.

    Raises
    ------
    DataError
        If the index is not a sorted, duplicate-free DatetimeIndex on a grid whose step
        divides 24 h, or a zone has no column.

    Examples
    --------
    >>> da = day_array(df, ["r240", "r241"])  # doctest: +SKIP
    >>> da.values.shape  # (days, 288, 2) for 5-minute data  # doctest: +SKIP
    """
    idx = data.index
    if not isinstance(idx, pd.DatetimeIndex):
        raise DataError(f"data index must be a DatetimeIndex, found {type(idx).__name__}")
    if len(idx) < 2:
        raise DataError(f"data has {len(idx)} row(s); structure identification needs days of data")
    if not idx.is_monotonic_increasing or idx.has_duplicates:
        raise DataError("data index must be sorted and free of duplicate time stamps")
    cols = _zone_columns(data, zones)
    # wall-clock time: a day is a calendar day where the building is
    local = idx.tz_localize(None) if idx.tz is not None else idx
    idx = idx.as_unit("ns")
    local = local.as_unit("ns")
    ns = np.diff(idx.asi8)
    step_ns = int(ns.min())
    if np.any(ns % step_ns):
        bad = idx[1:][ns % step_ns != 0][0]
        raise DataError(f"data index is not on a regular grid of {step_ns / 1e9:g} s "
                        f"(first off-grid time stamp {bad}); resample first (thermctl.data)")
    day_ns = 86_400 * 10**9
    if day_ns % step_ns:
        raise DataError(f"data step {step_ns / 1e9:g} s does not divide 24 h; "
                        "resample to e.g. 5 min")
    K = day_ns // step_ns
    day = local.normalize()
    tod = (local - day).asi8
    if np.any(tod % step_ns != tod[0] % step_ns):
        raise DataError(f"time stamps are not aligned to a daily grid of {step_ns / 1e9:g} s")
    k = tod // step_ns
    codes, days = pd.factorize(day)
    try:
        vals = data[cols].to_numpy(dtype=float)
    except (TypeError, ValueError):
        bad = [c for c in cols if not pd.api.types.is_numeric_dtype(data[c])]
        raise DataError(f"temperature column(s) {bad} are not numeric [°C]") from None
    n_days = len(days)
    count = np.zeros((n_days, K), dtype=int)
    np.add.at(count, (codes, k), 1)
    arr = np.full((n_days, K, len(zones)), np.nan)
    arr[codes, k] = vals

    keep, dropped = [], []
    for d in range(n_days):
        date = days[d].date()
        if (count[d] > 1).any():
            dropped.append((date, "repeated time of day (clock change)"))
        elif (count[d] == 0).any():
            dropped.append((date, f"incomplete ({int((count[d] > 0).sum())} of {K} samples)"))
        else:
            nan_cols = [c for c, bad in zip(cols, np.isnan(arr[d]).any(axis=0)) if bad]
            if nan_cols:
                dropped.append((date, "gap in " + ", ".join(nan_cols)))
            else:
                keep.append(d)
    if dropped:
        logger.info("structure: %d day(s) left out: %s", len(dropped),
                    "; ".join(f"{d}: {r}" for d, r in dropped))
    if len(keep) < n_days:
        arr = arr[keep]
    return DayArray(arr, [days[d].date() for d in keep], list(zones), step_ns / 1e9, dropped)


# ---------------------------------------------------------------------------
# SIN
# ---------------------------------------------------------------------------
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


# ---------------------------------------------------------------------------
# graphical lasso, vectorised
# ---------------------------------------------------------------------------
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


# ---------------------------------------------------------------------------
# scores and selection
# ---------------------------------------------------------------------------
@dataclass(frozen=True)
class ScoredEdge:
    """A selected convection edge.

    Attributes
    ----------
    a, b : str
        The two zones (alphabetical order, as in :class:`~thermctl.network.ThermalNetwork`).
    score : float
        Fraction of time-of-day indices whose concentration graph has the edge [-].
    d : float
        Air path length between the zones [m].
    """

    a: str
    b: str
    score: float
    d: float


def select_edges(scores: dict, distances: dict, zones: Sequence[str], rule: str = "paper",
                 s_min: float = 0.25, max_per_zone: int | None = None) -> list[ScoredEdge]:
    """Choose convection edges from pair scores.

    Parameters
    ----------
    scores : dict of (str, str) to float
        Score of every candidate pair (only candidates: pairs allowed to become edges).
    distances : dict of (str, str) to float
        Air path length [m] of every candidate pair (same keys).
    zones : sequence of str
        The measured zones (order used by the paper rule).
    rule : {"paper", "threshold"}
        ``paper``: every zone gets its highest-scoring partner (ties: shorter path,
        then name); a zone whose best score is 0 gets none. ``threshold``: every pair
        with score >= ``s_min``, strongest first, at most ``max_per_zone`` per zone.
    s_min : float
        Score threshold of the ``threshold`` rule, in [0, 1].
    max_per_zone : int, optional
        Limit of the ``threshold`` rule.

    Returns
    -------
    list of ScoredEdge
        Sorted by decreasing score.
    """
    def key(pair):  # best first: high score, short path, names
        return (-scores[pair], distances[pair], pair)

    chosen = set()
    if rule == "paper":
        best = {}
        for p in scores:
            if scores[p] > 0:
                for z in p:
                    if z not in best or key(p) < key(best[z]):
                        best[z] = p
        chosen = set(best.values())
    elif rule == "threshold":
        count = dict.fromkeys(zones, 0)
        for p in sorted(scores, key=key):
            if scores[p] < s_min or scores[p] <= 0:
                break
            if max_per_zone is not None and (count[p[0]] >= max_per_zone
                                             or count[p[1]] >= max_per_zone):
                continue
            chosen.add(p)
            count[p[0]] += 1
            count[p[1]] += 1
    else:
        raise ValueError(f"rule must be 'paper' or 'threshold', found {rule!r}")
    return [ScoredEdge(*sorted(p), scores[p], distances[p]) for p in sorted(chosen, key=key)]


# ---------------------------------------------------------------------------
# estimator
# ---------------------------------------------------------------------------
class StructureIdentifier:
    r"""Identify convection edges from zone temperatures (paper section III-A).

    Parameters
    ----------
    method : {"sin", "glasso"}
        Concentration graph per time of day: Drton & Perlman's SIN (needs
        N >= n + 2 complete days for n measured zones) or the graphical lasso.
    level : float
        SIN significance level in (0, 1): an edge where the simultaneous p-value is
        <= level. Default 0.05 (paper).
    adjust : {"sidak", "holm"}
        SIN multiple-testing adjustment.
    alpha : float or {"cv", "level"}
        Graphical-lasso penalty on the correlation scale, the same at every time of
        day. ``"cv"`` (default): the penalty with the best held-out likelihood in
        ``n_folds``-fold cross-validation over days; it predicts best but keeps many
        false edges (measured precision 0.3-0.6 on Gaussian graphical models), so it
        suits ``rule="paper"`` better than ``"threshold"``. ``"level"``:
        :func:`level_penalty` at ``level`` (Banerjee et al. 2008), which controls
        false edges like SIN's level when the variables are not all strongly
        correlated. A float: that penalty, >= 0.
    rule : {"paper", "threshold"}
        Edge selection, see :func:`select_edges`.
    s_min : float
        Score threshold of the ``threshold`` rule, in [0, 1]. The default 0.25 asks
        for an edge in a quarter of the day; under SIN, a pair without an edge is in
        a graph with probability <= ``level`` at each time, so its expected score is
        below 0.05.
    max_per_zone : int, optional
        At most this many convection edges per zone (``threshold`` rule only).
    allow_parallel : bool
        Keep pairs joined by a wall as candidates (an open door beside a wall);
        the paper removes them.
    n_folds : int
        Cross-validation folds (blocks of days) for the glasso penalty.
    n_alphas : int
        Penalties tried, log-spaced over [0.01, 1] × the largest off-diagonal
        correlation.
    cv_times : int
        Number of evenly spaced times of day used for cross-validation (all if K is
        smaller); the chosen penalty is then used at every time.
    max_iter, tol : int, float
        ADMM limits for the graphical lasso.

    Attributes
    ----------
    zones_ : list of str
        Measured zones used, in the order of all (…, n, n) arrays.
    step_ : float
        Sampling step [s].
    times_ : ndarray of float, shape (K,)
        Time of day of each index [s after midnight].
    days_used_ : list of datetime.date
    days_dropped_ : list of (datetime.date, str)
        Days left out and why (as :meth:`thermctl.data.Measurements.day_time_array`).
    times_skipped_ : list of int
        Time indices without a graph (a zone with zero variance over the days, or a
        singular covariance); they count in K but contribute no edges.
    correlations_ : ndarray, shape (K, n, n)
        Marginal correlations per time of day.
    partial_correlations_ : ndarray, shape (K, n, n)
        Partial correlations per time of day (from :math:`S^{-1}` for SIN, from the
        lasso precision for glasso).
    pvalues_ : ndarray, shape (K, n, n) or None
        SIN simultaneous p-values (None for glasso).
    precisions_ : ndarray, shape (K, n, n)
        Precision of the standardised temperatures (inverse correlation for SIN,
        lasso estimate for glasso).
    alpha_ : float
        Glasso penalty used (glasso only); ``cv_alphas_``, ``cv_scores_``: the
        cross-validation curve for ``alpha="cv"``, else None.
    graphs_ : ndarray of bool, shape (K, n, n)
        Concentration graph adjacency per time of day.
    score_matrix_ : ndarray, shape (n, n)
        Fraction of times with each edge, for every pair (walls included).
    scores_ : dict of (str, str) to float
        The same per pair, keyed by the two zone names in alphabetical order (as in
        ``edges_`` and the network's convection edges).
    conduction_pairs_ : set of frozenset
        Measured-zone pairs joined by a wall.
    candidates_ : list of (str, str)
        Pairs that may become convection edges (no wall unless ``allow_parallel``,
        known distance).
    edges_ : list of ScoredEdge
        Selected convection edges.
    network_ : ThermalNetwork
        The input network's conduction edges plus the selected convection edges.

    Notes
    -----
    Days are treated as independent samples; a day with any gap is left out. The
    sample size N is the number of complete days, so SIN's power grows with
    :math:`\sqrt{N - n - 1}`. On the testbed's Pugh-Hall-like building (26 days,
    5 min) SIN scores the true air paths 0.46-0.88 and the best false candidate
    0.12; the graphical lasso gives nearly every pair a score near 1 there, because
    the zone temperatures are marginally correlated 0.8-1.0 at every time of day.

    Examples
    --------
    >>> sid = StructureIdentifier(method="sin", rule="paper").fit(df, network)  # doctest: +SKIP
    >>> [(e.a, e.b, round(e.score, 2)) for e in sid.edges_]  # doctest: +SKIP
    [('r240', 'r243', 0.81), ...]
    """

    def __init__(self, method: str = "sin", level: float = 0.05, adjust: str = "sidak",
                 alpha: float | str = "cv", rule: str = "paper", s_min: float = 0.25,
                 max_per_zone: int | None = None, allow_parallel: bool = False,
                 n_folds: int = 5, n_alphas: int = 12, cv_times: int = 24,
                 max_iter: int = 2000, tol: float = 1e-5):
        self.method = method
        self.level = level
        self.adjust = adjust
        self.alpha = alpha
        self.rule = rule
        self.s_min = s_min
        self.max_per_zone = max_per_zone
        self.allow_parallel = allow_parallel
        self.n_folds = n_folds
        self.n_alphas = n_alphas
        self.cv_times = cv_times
        self.max_iter = max_iter
        self.tol = tol

    def _check_params(self):
        if self.method not in ("sin", "glasso"):
            raise ValueError(f"method must be 'sin' or 'glasso', found {self.method!r}")
        if not 0 < self.level < 1:
            raise ValueError(f"level must be in (0, 1), found {self.level!r}")
        if self.adjust not in ("sidak", "holm"):
            raise ValueError(f"adjust must be 'sidak' or 'holm', found {self.adjust!r}")
        if isinstance(self.alpha, str):
            if self.alpha not in ("cv", "level"):
                raise ValueError(f"alpha must be 'cv', 'level' or a float >= 0, "
                                 f"found {self.alpha!r}")
        elif not self.alpha >= 0:
            raise ValueError(f"alpha must be 'cv', 'level' or a float >= 0, found {self.alpha!r}")
        if self.rule not in ("paper", "threshold"):
            raise ValueError(f"rule must be 'paper' or 'threshold', found {self.rule!r}")
        if not 0 <= self.s_min <= 1:
            raise ValueError(f"s_min must be in [0, 1], found {self.s_min!r}")
        if self.max_per_zone is not None:
            if self.rule != "threshold":
                raise ValueError("max_per_zone applies to rule='threshold' only")
            if int(self.max_per_zone) != self.max_per_zone or self.max_per_zone < 1:
                raise ValueError(f"max_per_zone must be a positive integer, "
                                 f"found {self.max_per_zone!r}")
        if self.n_folds < 2:
            raise ValueError(f"n_folds must be >= 2, found {self.n_folds!r}")

    def fit(self, data: pd.DataFrame, network: ThermalNetwork) -> "StructureIdentifier":
        """Compute the graphs, scores and selected convection edges.

        Parameters
        ----------
        data : pandas.DataFrame
            Zone temperatures [°C] on a regular DatetimeIndex, one column per measured
            zone named ``T:<zone>`` or ``<zone>`` (other columns are ignored).
        network : ThermalNetwork
            Gives the measured zones, the walls (conduction pairs) and, through its
            spec, the air path lengths. Its own convection edges are not used.

        Returns
        -------
        self

        Raises
        ------
        DataError
            Missing zone column, irregular index, too few complete days (SIN needs
            N >= n + 2; glasso needs N >= max(3, n_folds)).
        """
        self._check_params()
        zones = list(network.measured_zones)
        if len(zones) < 2:
            raise DataError(f"structure identification needs >= 2 measured zones, "
                            f"{network.spec.source} has {zones}")
        da = day_array(data, zones)
        X = da.values
        N, K, n = X.shape
        self.zones_, self.step_ = zones, da.step
        self.times_ = np.arange(K) * da.step
        self.days_used_, self.days_dropped_ = da.days, da.dropped
        need = n + 2 if self.method == "sin" else max(3, self.n_folds if self.alpha == "cv" else 3)
        if N < need:
            extra = ("SIN's Fisher z uses sqrt(N - n - 1); use method='glasso' or more days"
                     if self.method == "sin" else "add days")
            raise DataError(f"{self.method}: needs >= {need} complete days for {n} measured zones, "
                            f"found N = {N} ({len(da.dropped)} day(s) dropped: "
                            f"{[r for _, r in da.dropped[:3]]}); {extra}")
        logger.info("structure: %s on %d days x %d times x %d zones", self.method, N, K, n)

        mu = X.mean(axis=0)
        sd = X.std(axis=0)  # (K, n), MLE as in the paper's S
        flat = sd <= 1e-9 * np.maximum(1.0, np.abs(mu))
        Z = X  # standardise in place: for 200 zones the array is 100 MB
        Z -= mu
        Z /= np.where(flat, 1.0, sd)
        iu = np.triu_indices(n, 1)
        R = np.empty((K, n, n))
        self.pvalues_ = None
        if self.method == "sin":
            self.partial_correlations_ = np.empty((K, n, n))
            self.precisions_ = np.empty((K, n, n))
            self.pvalues_ = np.full((K, n, n), np.nan)
        bad = flat.any(axis=1)
        chunk = max(1, int(_CHUNK_BYTES // (8 * n * n)))
        for k0 in range(0, K, chunk):
            sl = slice(k0, min(K, k0 + chunk))
            Rc = _gram(Z[:, sl]) / N
            Rc[:, np.arange(n), np.arange(n)] = 1.0
            R[sl] = Rc
            if self.method == "sin":
                pc, P, sing = _partial(Rc)
                bad[sl] |= sing
                self.partial_correlations_[sl], self.precisions_[sl] = pc, P
                self.pvalues_[sl] = _sin_from_partial(pc, N, self.adjust)
        self.correlations_ = R
        if self.method == "glasso":
            self._fit_glasso(Z, R, bad)
            graphs = self.precisions_ != 0
        else:
            graphs = self.pvalues_ <= self.level
        graphs[bad] = False
        graphs[:, np.arange(n), np.arange(n)] = False
        self.graphs_ = graphs
        self.times_skipped_ = [int(k) for k in np.flatnonzero(bad)]
        if bad.all():
            raise DataError(f"{self.method}: no time of day has a usable covariance (a zone "
                            f"constant over the days, or zones that are linear combinations "
                            f"of each other): zones {[z for z, f in zip(zones, flat.any(0)) if f]}")
        if bad.any():
            flat_z = [z for z, f in zip(zones, flat.any(0)) if f]
            warnings.warn(f"structure: {int(bad.sum())} of {K} times of day have no graph "
                          f"(zero variance over the days in {flat_z or 'no zone'}, or a singular "
                          f"covariance); they count as times without edges", DataWarning,
                          stacklevel=2)

        self.score_matrix_ = graphs.sum(axis=0) / K
        self.scores_ = {tuple(sorted((zones[i], zones[j]))): float(self.score_matrix_[i, j])
                        for i, j in zip(*iu)}
        self.conduction_pairs_ = {frozenset((e.a, e.b)) for e in network.conduction_edges
                                  if e.a in zones and e.b in zones}
        # one lookup table: spec.distance() scans the list, too slow for 20 000 pairs
        known = {frozenset((x.a, x.b)): x.d for x in network.spec.distances}
        dist, no_d = {}, []
        for pair in self.scores_:
            if frozenset(pair) in self.conduction_pairs_ and not self.allow_parallel:
                continue
            d = known.get(frozenset(pair))
            if d is None:
                no_d.append(pair)
            else:
                dist[pair] = d
        self.candidates_ = list(dist)
        self.edges_ = select_edges({p: self.scores_[p] for p in dist}, dist, zones, self.rule,
                                   self.s_min, self.max_per_zone)
        weakest = min((e.score for e in self.edges_), default=1.0)
        strong = [p for p in no_d if self.scores_[p] >= max(self.s_min, weakest)]
        if strong:
            logger.warning("structure: %d pair(s) score as high as selected edges but the spec "
                           "gives no air path length (add them under 'distances' to consider "
                           "them): %s", len(strong), strong[:10])
        self.network_ = network.with_convection([(e.a, e.b, e.d) for e in self.edges_])
        logger.info("structure: selected %s", [(e.a, e.b, round(e.score, 3)) for e in self.edges_])
        return self

    def _fit_glasso(self, Z, R, bad):
        K, n = R.shape[0], R.shape[-1]
        N = Z.shape[0]
        good = np.flatnonzero(~bad)
        self.cv_alphas_ = self.cv_scores_ = None
        if isinstance(self.alpha, str) and self.alpha == "level":
            self.alpha_ = level_penalty(N, n, self.level)
        elif isinstance(self.alpha, str):  # "cv"
            times = good[np.unique(np.linspace(0, len(good) - 1, min(self.cv_times, len(good)))
                                   .round().astype(int))]
            iu = np.triu_indices(n, 1)
            a_max = float(np.abs(R[good][:, iu[0], iu[1]]).max())
            alphas = a_max * np.logspace(0, -2, self.n_alphas)
            self.cv_alphas_ = alphas
            self.cv_scores_ = _glasso_cv(Z, alphas, self.n_folds, times, self.max_iter, self.tol)
            self.alpha_ = float(alphas[int(np.argmax(self.cv_scores_))])
            if self.alpha_ == alphas[-1]:
                logger.warning("structure: glasso CV chose the smallest penalty tried (%.3g): "
                               "the graphs are nearly complete", self.alpha_)
            elif self.alpha_ == alphas[0]:
                logger.warning("structure: glasso CV chose the largest penalty tried (%.3g): "
                               "the graphs are empty (too few days?)", self.alpha_)
        else:
            self.alpha_ = float(self.alpha)
        P = np.broadcast_to(np.eye(n), (K, n, n)).copy()
        self.n_iter_ = np.zeros(K, dtype=int)
        chunk = max(1, int(_CHUNK_BYTES / 4 // (8 * n * n)))  # ADMM holds ~10 such arrays
        for c in range(0, len(good), chunk):
            ks = good[c:c + chunk]
            P[ks], _, self.n_iter_[ks] = graphical_lasso_batch(
                R[ks], self.alpha_, max_iter=self.max_iter, tol=self.tol)
        self.precisions_ = P
        dP = np.sqrt(np.diagonal(P, axis1=1, axis2=2))
        pc = -P / dP[:, :, None] / dP[:, None, :]
        pc[:, np.arange(n), np.arange(n)] = 1.0
        self.partial_correlations_ = pc

    def pair_index(self, a: str, b: str) -> tuple[int, int]:
        """Indices of two measured zones into the (…, n, n) arrays."""
        try:
            return self.zones_.index(a), self.zones_.index(b)
        except ValueError:
            raise DataError(f"({a!r}, {b!r}): both must be measured zones of the fit, "
                            f"{self.zones_}") from None
