"""The structure-identification estimator: data and network in, convection edges out."""

from __future__ import annotations

import logging
import warnings

import numpy as np
import pandas as pd

from ..data.days import day_array
from ..errors import DataError, DataWarning
from ..network import ThermalNetwork
from .glasso import _glasso_cv, _gram, graphical_lasso_batch, level_penalty
from .selection import select_edges
from .sin import _partial, _sin_from_partial

__all__ = ["StructureIdentifier"]

logger = logging.getLogger(__name__)

_CHUNK_BYTES = 64e6  # size of one (chunk, n, n) float array when looping over time indices


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
            if d is None and frozenset(pair) in self.conduction_pairs_:
                d, _ = network.spec.air_path_length(*pair)   # a door beside the wall
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
