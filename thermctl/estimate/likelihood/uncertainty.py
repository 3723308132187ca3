"""Parameter intervals and a plain-words identifiability verdict for grey-box fits.

Two kinds of interval, both on the likelihood criterion:

* **Wald** — from the Hessian of the negative log-likelihood in the optimiser's
  coordinates (log R̄_v, log τ0, ...): ``Cov(η̂) ≈ H⁻¹``; a log-coordinate interval maps
  to a multiplicative one. The Hessian is the central difference of the *exact*
  CasADi gradient (accurate to ~1e-6 relative, and robust where the Riccati solution
  is a callback). Cheap, but it trusts a quadratic picture of the likelihood.
* **Profile likelihood** — fix the parameter on a grid, re-optimise all others, and keep
  the values with ``2 (nll_p − nll̂) ≤ χ²₁(level)``. It is what exposes practical
  non-identifiability (Raue et al. 2009; Brastein et al. 2020 for building RC models):
  a profile that stays below the threshold up to a bound means the data do not
  determine that side.

:func:`identifiability` runs both for R̄_v and τ0 = R̄_v·C_v and writes the verdict in
plain words; C_v follows from τ0 and R̄_v.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2, gmean, norm

from ..._blas import ignore_warnings, single_thread_blas
from ..._parallel import thread_map
from ...errors import ConvergenceWarning, EstimationError
from ...model import ConvectionParameters
from .optimize import minimize_criterion

__all__ = ["ParameterInterval", "IdentifiabilityReport", "hessian_fd", "wald_intervals",
           "profile_likelihood", "identifiability", "random_effects_inflation"]

log = logging.getLogger(__name__)


@dataclass
class ParameterInterval:
    """An interval for one parameter.

    Attributes
    ----------
    name : str
    value : float
        Estimate (natural units).
    lower, upper : float
        Interval ends (natural units); a bound of the search range where the data do
        not close the interval.
    level : float
        Confidence level [-].
    method : {"wald", "profile"}
        ``wald`` uses the robust (sandwich) variance when ``inflation`` > 1.
    unit : str
    closed_lower, closed_upper : bool
        Whether the data close each side (profile: the threshold was crossed inside the
        allowed range; Wald: always, unless the Hessian is singular there).
    inflation : float
        Robust-over-model variance ratio applied (sandwich / inverse Hessian, ≥ 1).
    grid, profile : ndarray
        Profile only: parameter values and ``nll_p − nll̂`` at each.
    """

    name: str
    value: float
    lower: float
    upper: float
    level: float
    method: str
    unit: str
    closed_lower: bool = True
    closed_upper: bool = True
    inflation: float = 1.0
    grid: np.ndarray = field(default=None, repr=False)
    profile: np.ndarray = field(default=None, repr=False)

    @property
    def identifiable(self) -> bool:
        return self.closed_lower and self.closed_upper

    def covers(self, value: float) -> bool:
        return self.lower <= value <= self.upper


@dataclass
class IdentifiabilityReport:
    """Intervals, weak Hessian directions and a verdict per parameter.

    Attributes
    ----------
    intervals : dict
        Name → :class:`ParameterInterval` (the profile one where computed, else Wald).
    wald : dict
        Name → Wald :class:`ParameterInterval` for every free parameter.
    weak_directions : list of (float, str)
        Hessian eigenvalues (per observation-scaled) below a threshold and the parameter
        combination each belongs to.
    verdicts : dict
        Name → one sentence.
    level : float
    short_calibration_days : float or None
        Set when the calibration was too short to call anything identified [d]; a widened
        interval keeps that verdict.
    paths_disagree : tuple or None
        Set when the per-path R̄_v of the selected structure disagree
        (:func:`thermctl.identify.paths_disagree`): the shared R̄_v is not identified as one
        value.
    heterogeneity : dict or None
        Set when the shared R̄_v's interval was widened because the paths' own values scatter
        beyond their intervals: ``paths``, Cochran's ``Q``, ``tau`` (between-path spread of
        log R̄_v), ``ratio`` (variance factor) and the per-path ``rbar_v``.
    """

    intervals: dict
    wald: dict
    weak_directions: list
    verdicts: dict
    level: float
    short_calibration_days: float | None = None
    paths_disagree: tuple | None = None
    heterogeneity: dict | None = None

    def widen(self, name: str, lower: float, upper: float, why: str,
              closed: tuple[bool, bool] = (True, True)) -> None:
        """Widen the interval of ``name`` to take in ``[lower, upper]`` and say ``why`` in
        its verdict: an uncertainty of the model itself, which one model's likelihood does
        not see (its verdict is recomputed from the widened interval). ``closed``: whether
        the data close each side of ``[lower, upper]``; a side that moves out takes its
        flag (an end on a search bound stays open)."""
        iv = self.intervals[name]
        if lower < iv.lower:
            iv.lower, iv.closed_lower = lower, closed[0]
        if upper > iv.upper:
            iv.upper, iv.closed_upper = upper, closed[1]
        if self.short_calibration_days:
            # too few calibration days: nothing is called identified, wider or not
            self.verdicts[name] = self.verdicts[name].rstrip(".") + f"; {why}."
            return
        self.verdicts[name] = _verdict(iv, None)[:-1] + f"; {why}."

    def __str__(self):
        lines = [f"identifiability ({100 * self.level:.0f} % intervals):"]
        lines += [f"  {v}" for v in self.verdicts.values()]
        for ev, combo in self.weak_directions:
            lines.append(f"  weakly determined combination (eigenvalue {ev:.2g}): {combo}")
        return "\n".join(lines)


def hessian_fd(problem, eta, free=None, criterion: str = "likelihood", rel_step: float = 1e-4,
               threads: int = 1):
    """Hessian of the criterion in ``eta`` by central differences of its exact gradient.

    Parameters
    ----------
    problem : LikelihoodProblem
    eta : array_like
    free : array_like of bool, optional
        Coordinates to differentiate (default: the layout's free ones).
    criterion : {"likelihood", "kstep"}
    rel_step : float
        Step in ``eta`` [-] (log coordinates: a relative step of the parameter).
    threads : int
        Columns computed side by side.

    Returns
    -------
    ndarray, shape (n_free, n_free)
    """
    eta = np.asarray(eta, dtype=float)
    free = problem.layout.free() if free is None else np.asarray(free, bool)
    idx = np.flatnonzero(free)
    grad = problem.nll_grad if criterion == "likelihood" else problem.kstep_grad

    def column(i):
        h = rel_step * max(1.0, abs(eta[i]))
        ep, em = eta.copy(), eta.copy()
        ep[i] += h
        em[i] -= h
        return (grad(ep)[1][idx] - grad(em)[1][idx]) / (2 * h)
    with single_thread_blas():
        cols = thread_map(column, idx, threads)
    H = np.column_stack(cols) if cols else np.zeros((0, 0))
    return 0.5 * (H + H.T)


def wald_intervals(problem, eta, level: float = 0.9, free=None, H=None, robust: bool = True,
                   block: float = 86400.0, threads: int = 1) -> tuple[dict, list]:
    """Wald intervals of every free parameter and the weak Hessian directions.

    Parameters at a bound are left out of the inversion (treated as fixed), and so are
    parameters the data do not fix (a flat or negative-curvature direction of the
    Hessian, e.g. a noise level fitted to about 0): their interval is the search range,
    and the others' variances are conditional on them.

    With ``robust`` the variance is the sandwich ``H⁻¹ J H⁻¹``, ``J`` the covariance of
    the likelihood's gradient contributions of consecutive ``block``-long stretches of
    data (days by default). A model that is only approximately right (closed-loop
    inputs, gains that jump rather than drift, quantised sensors) has innovations that
    are not white; its inverse Hessian then understates the spread of the estimate,
    and the blocks' scatter measures by how much. The ratio is never taken below 1.

    Returns
    -------
    intervals : dict
        Name → :class:`ParameterInterval`.
    weak : list of (float, str)
        Eigenvalues of the per-observation Hessian below 1e-6 of its largest and the
        combination (largest eigenvector entries).
    """
    lay = problem.layout
    eta = np.asarray(eta, dtype=float)
    free = lay.free() if free is None else np.asarray(free, bool) & lay.free()
    at_bound = lay.at_bound_names(eta)
    use = free & np.array([p.name not in at_bound for p in lay.params])
    idx = np.flatnonzero(use)
    if H is None:
        H = hessian_fd(problem, eta, use, threads=threads)
    z = norm.ppf(0.5 + level / 2)
    out = {}
    weak = []
    if len(idx):
        w, V = np.linalg.eigh(H)
        scale = max(abs(w).max(), 1e-300)
        for k in np.flatnonzero(w <= 1e-6 * scale):
            comp = V[:, k]
            top = np.argsort(-np.abs(comp))[:3]
            combo = " ".join(f"{comp[t]:+.2f}·{_coord(lay.params[idx[t]])}" for t in top
                             if abs(comp[t]) > 0.1)
            weak.append((float(w[k] / max(problem.n_obs, 1)), combo))
        # a direction the data do not fix (curvature ≤ 1e-12 of the largest, or negative:
        # a noise variance fitted to about 0) made the whole inverse NaN, and with it every
        # parameter's interval and variance ratio (measured on the twin house N2 with a noise
        # level per zone: all 23 intervals the search range, every ratio read as 1): such
        # parameters are dropped one by one and the others' variances are conditional on them
        keep, wk, Vk = _determined(H, w, V)
        var = np.full(len(idx), np.nan)
        infl = np.ones(len(idx))
        if len(keep):
            Hinv = (Vk / wk) @ Vk.T
            var[keep] = np.diag(Hinv)
            if robust:
                G = problem.block_scores(eta, block, threads=threads)[:, idx[keep]]
                nb = G.shape[0]
                if nb >= 3:
                    Gc = G - G.mean(axis=0)
                    J = Gc.T @ Gc * nb / (nb - 1)
                    vr = np.diag(Hinv @ J @ Hinv)
                    with np.errstate(invalid="ignore", divide="ignore"):
                        infl[keep] = np.where(var[keep] > 0, np.maximum(vr / var[keep], 1.0), 1.0)
                else:
                    log.info("robust intervals need at least 3 blocks of %g h; using the "
                             "Hessian", block / 3600)
        if len(keep) < len(idx):
            log.info("Wald intervals: %s not determined by the data (flat or negative "
                     "curvature); the others' variances are conditional on them",
                     ", ".join(lay.params[idx[j]].name for j in range(len(idx)) if j not in keep))
        se = np.sqrt(np.where(var > 0, var * infl, np.nan))
        for j, i in enumerate(idx):
            p = lay.params[i]
            lo_e, hi_e = eta[i] - z * se[j], eta[i] + z * se[j]
            ok = np.isfinite(se[j])
            lo = p.from_eta(lo_e) if ok else p.lower
            hi = p.from_eta(hi_e) if ok else p.upper
            out[p.name] = ParameterInterval(p.name, p.from_eta(eta[i]), max(lo, p.lower),
                                            min(hi, p.upper), level, "wald", p.unit,
                                            bool(ok and lo > p.lower), bool(ok and hi < p.upper),
                                            float(infl[j]) if np.isfinite(infl[j]) else 1.0)
    for i in np.flatnonzero(free & ~use):
        p = lay.params[i]
        v = p.from_eta(eta[i])
        near_lo = v - p.lower < p.upper - v if not p.log else \
            math.log(v / p.lower) < math.log(p.upper / v)
        out[p.name] = ParameterInterval(p.name, v, p.lower if near_lo else v,
                                        v if near_lo else p.upper, level, "wald", p.unit,
                                        False, False)
    return out, weak


def random_effects_inflation(values, variances) -> tuple[float, float, float]:
    """How much more a pooled value varies when its estimates disagree beyond their own
    variances (DerSimonian & Laird, Controlled Clinical Trials 7, 1986).

    ``k`` estimates ``y_i`` of one quantity with variances ``v_i``: ``Q = Σ w_i (y_i − ȳ)²``
    with ``w_i = 1 / v_i`` and ``ȳ`` the inverse-variance mean; the between-estimate
    variance ``τ² = max(0, (Q − (k − 1)) / (Σw − Σw² / Σw))``; the pooled value's variance
    grows from ``1 / Σw`` (one common value) to ``1 / Σ 1 / (v_i + τ²)``. With equal
    variances the ratio is ``max(1, Q / (k − 1))``.

    Parameters
    ----------
    values, variances : array_like
        The estimates and their variances (same units squared), at least two.

    Returns
    -------
    Q : float
        Cochran's heterogeneity statistic [-] (χ² with k − 1 degrees of freedom when the
        estimates share one value).
    tau2 : float
        Between-estimate variance (units of ``values`` squared).
    ratio : float
        Pooled variance with τ² over without it (≥ 1) [-].
    """
    y = np.asarray(values, dtype=float)
    v = np.asarray(variances, dtype=float)
    if y.shape != v.shape or y.size < 2 or not np.all(v > 0) or not np.all(np.isfinite(y)):
        raise EstimationError("random_effects_inflation needs at least two finite estimates "
                              "with positive variances")
    w = 1.0 / v
    ybar = float(np.sum(w * y) / np.sum(w))
    Q = float(np.sum(w * (y - ybar) ** 2))
    tau2 = max(0.0, (Q - (y.size - 1)) / float(np.sum(w) - np.sum(w ** 2) / np.sum(w)))
    ratio = float(np.sum(w) / np.sum(1.0 / (v + tau2)))
    return Q, tau2, max(ratio, 1.0)


def _determined(H, w, V, tol: float = 1e-12):
    """``(keep, w_k, V_k)``: the indices of ``H`` whose sub-Hessian is positive definite
    (eigenvalues above ``tol`` of the largest) and that sub-Hessian's eigen-decomposition;
    ``w, V`` are ``H``'s own. The parameter with the largest weight in the flattest
    direction is dropped until none is at or below it."""
    keep = list(range(H.shape[0]))
    while keep:
        if w.min() > tol * max(abs(w).max(), 1e-300):
            break
        keep.pop(int(np.argmax(np.abs(V[:, int(np.argmin(w))]))))
        w, V = np.linalg.eigh(H[np.ix_(keep, keep)])
    return keep, w, V


def _coord(p):
    return f"log {p.name}" if p.log else p.name


def profile_likelihood(problem, eta, name: str, level: float = 0.9, *, step: float | None = None,
                       max_points: int = 8, nll_hat: float | None = None, solver: str = "lbfgs",
                       max_iter: int = 150, inflation: float = 1.0) -> ParameterInterval:
    """Profile-likelihood interval of one log-parameter.

    Parameters
    ----------
    problem : LikelihoodProblem
    eta : array_like
        The optimum.
    name : str
        Parameter to profile (a log-transformed one: ``rbar_v``, ``tau0``, ``sigma_*``).
    level : float
    step : float, optional
        First step in log units (default 0.15, i.e. ×1.16); it grows ×1.6 per point.
    max_points : int
        Per side.
    nll_hat : float, optional
        Likelihood at the optimum (recomputed if not given).
    solver : {"lbfgs", "ipopt"}
    max_iter : int
        Per re-optimisation.
    inflation : float
        Robust variance ratio (:func:`wald_intervals`); the threshold ``χ²₁(level)/2`` is
        multiplied by it, which widens the interval as the sandwich widens a Wald one.
    """
    ctx = _profile_setup(problem, eta, name, level, nll_hat, inflation)
    sides = [_profile_side(ctx, sign, step, max_points, solver, max_iter) for sign in (-1.0, 1.0)]
    return _profile_interval(ctx, sides)


def _profile_setup(problem, eta, name, level, nll_hat, inflation) -> dict:
    """What both sides of :func:`profile_likelihood` share."""
    lay = problem.layout
    i = lay.index(name)
    p = lay.params[i]
    if not p.log:
        raise EstimationError(f"profile_likelihood: {name} is not a log-parameter")
    eta = np.asarray(eta, dtype=float)
    free = lay.free().copy()
    free[i] = False
    if nll_hat is None:
        with single_thread_blas():
            nll_hat = problem.nll(eta)
    thr = chi2.ppf(level, 1) / 2.0 * max(1.0, float(inflation))
    return dict(name=name, problem=problem, eta=eta, i=i, p=p, free=free, f_hat=nll_hat, thr=thr,
                bounds=lay.bounds(), level=level, inflation=max(1.0, float(inflation)))


def _profile_side(ctx, sign, step=None, max_points=8, solver="lbfgs", max_iter=150):
    """One side of a profile: ``({log value: nll − nll_hat}, closed)``, walking from the
    optimum until the criterion rises past the threshold. The two sides are independent
    (each starts at the optimum), so they may run side by side."""
    problem, eta, i, free, f_hat, thr = (ctx[k] for k in ("problem", "eta", "i", "free",
                                                          "f_hat", "thr"))
    lo_b, hi_b = ctx["bounds"]
    pts = {eta[i]: 0.0}
    cur = eta.copy()
    h = 0.15 if step is None else step
    x = eta[i]
    closed = False
    n_pts = 0
    with single_thread_blas():
        while n_pts < max_points:
            x_new = float(np.clip(x + sign * h, lo_b[i], hi_b[i]))
            if x_new == x:
                break
            trial = cur.copy()
            trial[i] = x_new
            with ignore_warnings(ConvergenceWarning):
                r = minimize_criterion(problem, "likelihood", trial, solver=solver, free=free,
                                       max_iter=max_iter)
            d = r.value - f_hat
            d_prev = pts[x]
            if d > 4 * thr and d_prev < thr and h > 1e-4:
                # overshot the threshold by far: a sharp profile; bracket it more tightly
                # (for a quadratic profile √d is linear in x)
                h *= max(0.1, 0.8 * (math.sqrt(thr) - math.sqrt(max(d_prev, 0.0)))
                         / max(math.sqrt(d) - math.sqrt(max(d_prev, 0.0)), 1e-12))
                n_pts += 1
                continue
            if d < 0:           # found a better optimum on the way
                log.info("profile of %s: nll %.3f below the optimum at %s", ctx["name"], d,
                         x_new)
            pts[x_new] = d
            cur = r.eta.copy()
            x = x_new
            n_pts += 1
            if d > thr:
                closed = True
                break
            h *= 1.6
    return pts, closed


def _profile_interval(ctx, sides) -> ParameterInterval:
    """The interval from the two sides (lower, upper) of :func:`_profile_side`."""
    eta, i, p, thr = ctx["eta"], ctx["i"], ctx["p"], ctx["thr"]
    lo_b, hi_b = ctx["bounds"]
    pts = {**sides[0][0], **sides[1][0]}
    xs = np.array(sorted(pts))
    ds = np.array([pts[x] for x in xs])
    k0 = int(np.argmin(np.abs(xs - eta[i])))
    lo = _crossing(xs[:k0 + 1][::-1], ds[:k0 + 1][::-1], thr, lo_b[i])
    hi = _crossing(xs[k0:], ds[k0:], thr, hi_b[i])
    return ParameterInterval(ctx["name"], p.from_eta(eta[i]), p.from_eta(lo), p.from_eta(hi),
                             ctx["level"], "profile", p.unit, sides[0][1], sides[1][1],
                             ctx["inflation"], np.exp(xs), ds)


def _crossing(xs, ds, thr, bound):
    """First x (walking outwards) where the profile crosses ``thr``.

    Interpolates √d linearly (exact for a quadratic profile); a straight line through d
    would put the end far too close when a step overshoots the threshold.
    """
    for k in range(1, len(xs)):
        if ds[k] > thr:
            r0, r1 = math.sqrt(max(ds[k - 1], 0.0)), math.sqrt(ds[k])
            t = (math.sqrt(thr) - r0) / (r1 - r0) if r1 != r0 else 1.0
            return xs[k - 1] + t * (xs[k] - xs[k - 1])
    return bound        # not crossed: the data do not close this side (conservative)


def identifiability(estimator, params=("rbar_v", "tau0"), level: float = 0.9,
                    method: str = "profile", robust: bool = True,
                    threads: int = 1, wald=None) -> "IdentifiabilityReport":
    """Intervals and a verdict in plain words for R̄_v, τ0 (and so C_v).

    Parameters
    ----------
    estimator : LikelihoodEstimator
        Fitted with ``criterion="likelihood"``.
    params : sequence of str
        Parameters to profile (others get Wald intervals only). With ``per_edge=True``
        name the edge parameters, e.g. ``"rbar_v[air:a-b]"``.
    level : float
    method : {"profile", "wald"}
        ``wald`` skips the profiles (fast; trusts a quadratic likelihood).
    robust : bool
        Widen both kinds of interval by the sandwich variance ratio (see
        :func:`wald_intervals`).
    threads : int
        Profiles, Hessian columns and block scores computed side by side (the result is
        the same).
    wald : tuple, optional
        :func:`wald_intervals` of this fit at ``level`` with ``robust``, computed already.

    Returns
    -------
    IdentifiabilityReport
    """
    if getattr(estimator, "criterion", "likelihood") != "likelihood":
        raise EstimationError("identifiability needs a likelihood fit (criterion='likelihood')")
    estimator._check_fitted()
    pb, eta = estimator.problem_, estimator.eta_
    lay = pb.layout
    wald, weak = wald if wald is not None else wald_intervals(pb, eta, level, robust=robust,
                                                               threads=threads)
    intervals = dict(wald)
    names = [n for n in params if n in lay.names and not lay.params[lay.index(n)].fixed]
    if method == "profile":
        solver = getattr(estimator, "solver", "lbfgs")
        ctx = {n: _profile_setup(pb, eta, n, level, estimator.nll_,
                                 wald[n].inflation if n in wald else 1.0) for n in names}
        # each side of each profile is a task: on the twin house N2 the three R̄_v profiles
        # and τ0's, one per thread, left a core idle for a third of the 17 s
        jobs = [(n, sign) for n in names for sign in (-1.0, 1.0)]
        # one warnings context here, none in the threads (see ignore_warnings)
        with ignore_warnings(ConvergenceWarning):
            sides = thread_map(lambda j: _profile_side(ctx[j[0]], j[1], solver=solver), jobs,
                               threads)
        for k, n in enumerate(names):
            intervals[n] = _profile_interval(ctx[n], sides[2 * k: 2 * k + 2])
    pb.release_buffers()            # one set per thread used above; the fit keeps none
    verdicts = {}
    for n in names:
        verdicts[n] = _verdict(intervals[n], pb)
    if "tau0" in names and any(ConvectionParameters.is_rbar(k) for k in names):
        verdicts["c_v"] = _cv_verdict(intervals["tau0"], estimator)
    return IdentifiabilityReport(intervals, wald, weak, verdicts, level)


def _fmt(x):
    return f"{x:.3g}"


LOOSE = 1.0
"""Relative half-width of a closed interval above which it is not called identified [-]:
an interval reaching past twice the estimate (±100 %) bounds the value, it does not
measure it."""


def _verdict(iv: ParameterInterval, pb) -> str:
    what = {"rbar_v": "R̄_v", "tau0": "τ0 = R̄_v·C_v"}.get(ConvectionParameters.kind_of(iv.name),
                                                          iv.name)
    if ConvectionParameters.is_rbar(iv.name, per_edge=True):
        what = "R̄_v of " + ConvectionParameters.edge_of(iv.name)
    span = f"[{_fmt(iv.lower)}, {_fmt(iv.upper)}] {iv.unit}"
    how = iv.method + (f", widened ×{math.sqrt(iv.inflation):.1f} for non-white innovations"
                       if iv.inflation > 1.05 else "")
    head = f"{what} = {_fmt(iv.value)} {iv.unit}, {100 * iv.level:.0f} % interval {span} ({how})"
    if iv.identifiable:
        rel = max(iv.upper / iv.value - 1.0, 1.0 - iv.lower / iv.value)
        if rel > LOOSE:
            # closed on both sides, but "identified within ±274 %" (the twin house's bath
            # door per path) says more than the data do
            return (f"{head}: bounded by the data on both sides, but only within a factor "
                    f"{iv.upper / iv.lower:.1f}: not identified to a useful precision.")
        return f"{head}: identified (within ±{100 * rel:.0f} %)."
    if not iv.closed_lower and not iv.closed_upper:
        return (f"{head}: NOT identifiable from these data — the criterion changes by less than "
                f"the {100 * iv.level:.0f} % threshold over the whole allowed range; the value is "
                "where the optimiser stopped, not a measurement.")
    if not iv.closed_lower:
        return (f"{head}: bounded above only — the data cannot tell the estimate from any "
                f"smaller value down to the search bound {_fmt(iv.lower)} {iv.unit}.")
    return (f"{head}: bounded below only — the data cannot tell the estimate from any "
            f"larger value up to the search bound {_fmt(iv.upper)} {iv.unit}.")


def _cv_verdict(tau: ParameterInterval, est) -> str:
    # one R̄_v per path: C_v = τ0/R̄_v per path too; the interval on their geometric mean
    per = np.atleast_1d(est.rbar_v_) if np.ndim(est.rbar_v_) else None
    rb = est.rbar_v_ if per is None else float(gmean(per))
    lo, hi = tau.lower / rb, tau.upper / rb
    val = (_fmt(tau.value / rb) if per is None or per.size < 2 else
           ", ".join(_fmt(tau.value / r) for r in per) + " (one per path)")
    if tau.identifiable:
        return (f"C_v = {val} J/K (from τ0 and R̄_v), interval about "
                f"[{_fmt(lo)}, {_fmt(hi)}] J/K: identified.")
    # one side closed by the data, the other open with the estimate on it: the bound decides
    on_bound = (tau.closed_lower and not tau.closed_upper
                and tau.upper - tau.value <= 1e-3 * tau.upper) or \
        (tau.closed_upper and not tau.closed_lower and tau.value - tau.lower <= 1e-3 * tau.lower)
    if on_bound:
        return (f"C_v: not identifiable — τ0 = R̄_v·C_v sits on its search bound "
                f"({_fmt(tau.value)} s/m, from t_min/α or t_max/α), so C_v = τ0/R̄_v = "
                f"{val} J/K is set by that bound, not by the data; the convection "
                "edge's own time constant (seconds) is far below the data step, so the data only "
                "see its resistance. The reported C_v is not a measurement.")
    return (f"C_v: not identifiable — any value in about [{_fmt(lo)}, {_fmt(hi)}] J/K "
            f"(τ0 ∈ [{_fmt(tau.lower)}, {_fmt(tau.upper)}] s/m) fits as well; the convection "
            "edge's own time constant (seconds) is far below the data step, so the data only "
            "see its resistance. The reported C_v is not a measurement.")
