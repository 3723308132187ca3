"""Maximum-likelihood (or k-step) estimation of a network model with unmeasured gains.

:class:`LikelihoodEstimator` is the public entry point: it builds a
:class:`~thermctl.estimate.likelihood.problem.LikelihoodProblem` for a network and data, minimises the
chosen criterion, and exposes the identified :class:`~thermctl.model.ThermalModel` and
everything a report needs.
"""

from __future__ import annotations

import logging
import math
import time
import warnings
from dataclasses import dataclass, field, fields

import numpy as np

from ..._blas import record_warnings, single_thread_blas
from ...errors import BoundWarning, DataError, EstimationError
from ...model import RBAR_V_PAPER, ConvectionParameters
from ...network import ThermalNetwork
from ..data import EstimationData, as_estimation_data
from ..result import FitResult
from .optimize import CRITERIA, minimize_criterion
from .problem import LikelihoodOptions, LikelihoodProblem

__all__ = ["LikelihoodEstimator", "LikelihoodResult"]

log = logging.getLogger(__name__)

@dataclass
class LikelihoodResult(FitResult):
    """What a grey-box fit found (a :class:`~thermctl.estimate.FitResult`).

    Attributes
    ----------
    criterion : str
    value : float
        Criterion at the optimum (negative log-likelihood, or k-step SSE [K²]).
    params : dict
        Every parameter in natural units (see :data:`~thermctl.estimate.likelihood.params.GROUP_UNITS`).
    rbar_v, c_v : ndarray
        Per convection edge [K/(W m)], [J/K].
    edges : list of str
    n_obs : int
        Scalar observations in the likelihood.
    n_free : int
        Free parameters.
    aic, bic : float
        ``2 nll + 2 k`` and ``2 nll + k ln n_obs`` (likelihood criterion only).
    active_bounds : list of str
    success : bool
    message : str
    iterations : int
    wall_time : float
        [s]
    starts : list of (dict, float)
        Start values of R̄_v tried and the criterion each reached.
    rows : str
        Which samples the likelihood used (``supply_off``, ``all``, ``given``).
    """

    criterion: str
    value: float
    params: dict
    rbar_v: np.ndarray
    c_v: np.ndarray
    edges: list
    n_obs: int
    n_free: int
    aic: float
    bic: float
    active_bounds: list
    success: bool
    message: str
    iterations: int
    wall_time: float
    starts: list = field(default_factory=list)
    rows: str = "all"

    @property
    def param_names(self) -> list:
        """Names of every estimated parameter, noise parameters included."""
        return list(self.params)

    @property
    def param_values(self) -> dict:
        """``{name: value}`` of every estimated parameter (:attr:`params`)."""
        return dict(self.params)

    def summary(self) -> str:
        lines = [f"grey-box fit ({self.criterion}): value {self.value:.6g}, "
                 f"{self.n_free} free parameters, {self.n_obs} observations ({self.rows}), "
                 f"{self.iterations} iterations, {self.wall_time:.1f} s"
                 + ("" if self.success else f" — NOT CONVERGED: {self.message}")]
        for e, r, c in zip(self.edges, self.rbar_v, self.c_v):
            lines.append(f"  {e}: rbar_v = {r:.4g} K/(W m), c_v = {c:.4g} J/K")
        for k, v in self.params.items():
            if ConvectionParameters.kind_of(k) not in ("rbar_v", "tau0"):
                lines.append(f"  {k} = {v:.4g}")
        if np.isfinite(self.aic):
            lines.append(f"  AIC {self.aic:.2f}, BIC {self.bic:.2f}")
        for b in self.active_bounds:
            lines.append(f"  at bound: {b}")
        return "\n".join(lines)


class LikelihoodEstimator:
    r"""Fit a thermal network with unmeasured gains by a Kalman-filter criterion.

    The model is the network's own (walls, zones, convection edges ``R = R̄_v d``,
    ``C = C_v``) plus a random-walk heat gain per measured zone, white heat noise per
    zone and sensor noise; see :mod:`thermctl.estimate.likelihood.problem`. Parameters are found by
    minimising the negative log-likelihood of the one-step innovations of the
    stationary Kalman filter (``criterion="likelihood"``) or the k-step-ahead squared
    prediction error from filtered states (``criterion="kstep"``), with exact CasADi
    derivatives.

    By default (``fit_rows="auto"``) only samples taken after at least 3 h with the
    supply air off in every zone (nights, weekends) enter the criterion; the filter still
    runs through all data. Why: a zone controller acts on readings the log does not
    hold (between samples, before rounding), so in closed loop the logged supply carries
    information about the state that the filter cannot see, and the likelihood then
    prefers too-strong mixing. Measured on 15 testbed buildings (benchmarks/
    identification.py): median R̄_v error 34 % using all samples, 7 % with the default.
    Data without such periods fall back to all samples (logged).

    Parameters
    ----------
    network : ThermalNetwork
        Structure to fit (its convection edges get R̄_v, C_v).
    criterion : {"likelihood", "kstep"}
    rbar_v : float or array_like
        Start value of R̄_v [K/(W m)].
    c_v : float, optional
        Start value of C_v [J/K] (default: τ0 in the middle of its bounds).
    solver : {"lbfgs", "ipopt"}
    rbar_starts : sequence of float, optional
        Several start values of R̄_v [K/(W m)]; the best optimum is kept.
    fix : dict, optional
        Parameters held at a value (natural units), e.g. ``{"tau0": 1.0}``.
    max_iter : int
    tol : float
        Tolerance on the criterion per observation (L-BFGS-B ``ftol``, IPOPT ``tol``) [-].
    stall : (int, float), optional
        L-BFGS-B stops once the criterion has gained less than ``stall[1]`` (nats) over
        the last ``stall[0]`` evaluations (a search's fits use
        :data:`~thermctl.estimate.likelihood.optimize.STALL`). Default: no such stop.
    options : LikelihoodOptions, optional
        Model and criterion options; keyword arguments below override its fields.
    **kwargs
        Any field of :class:`LikelihoodOptions` (``per_edge``, ``disturbance``, ``basis``,
        ``solar``, ``noise``, ``burn_in``, ``fit_rows``, ``holdoff``, ``horizon`` ...).

    Attributes
    ----------
    problem_ : LikelihoodProblem
    eta_ : ndarray
        Optimiser coordinates at the optimum.
    params_ : dict
        Parameters in natural units.
    rbar_v_, c_v_ : float or ndarray
        Shared values (floats) or per edge (arrays, ``per_edge=True``) [K/(W m)], [J/K].
    tau0_ : float
        ``rbar_v·c_v`` [s/m].
    model_ : ThermalModel
        The identified network model.
    value_ : float
        Criterion at the optimum.
    nll_ : float
        Negative log-likelihood at the optimum (also after a k-step fit).
    aic_, bic_ : float
    n_obs_, n_free_ : int
    step_scale_ : dict or None
        L-BFGS-B's scale of each free parameter's coordinate at the end (the square root of
        its last inverse-Hessian diagonal; None after IPOPT): a fit warm-started from this
        one passes it as ``fit(step_scale=)``.
    result_ : LikelihoodResult

    Examples
    --------
    >>> est = LikelihoodEstimator(net).fit(measurements)      # doctest: +SKIP
    >>> print(est.result_.summary())                      # doctest: +SKIP
    >>> from thermctl.estimate.likelihood import identifiability
    >>> print(identifiability(est))                       # doctest: +SKIP
    """

    def __init__(self, network: ThermalNetwork, criterion: str = "likelihood", *,
                 rbar_v=RBAR_V_PAPER, c_v=None, solver: str = "lbfgs", rbar_starts=None,
                 fix: dict | None = None, max_iter: int = 300, tol: float = 1e-9,
                 stall: tuple | None = None, options: LikelihoodOptions | None = None,
                 **kwargs):
        self.network = network
        self.criterion = criterion
        self.rbar_v = rbar_v
        self.c_v = c_v
        self.solver = solver
        self.rbar_starts = rbar_starts
        self.fix = fix
        self.max_iter = max_iter
        self.tol = tol
        self.stall = stall
        self.options = options
        self.kwargs = kwargs

    # ------------------------------------------------------------------ helpers
    def make_options(self) -> LikelihoodOptions:
        """The :class:`LikelihoodOptions` this estimator uses."""
        base = self.options or LikelihoodOptions()
        names = {f.name for f in fields(LikelihoodOptions)}
        bad = sorted(set(self.kwargs) - names)
        if bad:
            raise EstimationError(f"unknown option(s) {bad}; options are {sorted(names)}")
        vals = {f.name: getattr(base, f.name) for f in fields(LikelihoodOptions)}
        vals.update(self.kwargs)
        return LikelihoodOptions(**vals)

    def make_problem(self, data, init: dict | None = None) -> LikelihoodProblem:
        """The problem for ``data`` (same network and options), start values from ``init``."""
        data = as_estimation_data(data, self.network)
        pb = LikelihoodProblem(self.network, data, self.make_options(), rbar_v=self.rbar_v,
                            c_v=self.c_v, init=init)
        if self.fix:
            pb.layout = pb.layout.with_fixed(self.fix, self.fix)
        return pb

    # ------------------------------------------------------------------ fit
    def fit(self, data, init: dict | None = None,
            step_scale: dict | None = None) -> "LikelihoodEstimator":
        """Estimate the parameters from data.

        Parameters
        ----------
        data : EstimationData, thermctl.data.Measurements or pandas.DataFrame
        init : dict, optional
            Start values by parameter name (natural units), e.g. ``other.params_``.
        step_scale : dict, optional
            L-BFGS-B's coordinate scales by parameter name, e.g. ``other.step_scale_`` of
            the fit ``init`` comes from
            (:func:`~thermctl.estimate.likelihood.optimize.minimize_criterion`).

        Returns
        -------
        self
        """
        if self.criterion not in CRITERIA:
            raise EstimationError(f"criterion must be one of {CRITERIA}, found {self.criterion!r}")
        t0 = time.perf_counter()
        pb = self.make_problem(data, init)
        lay = pb.layout
        starts = [None]
        if self.rbar_starts is not None and pb.i_rbar:
            starts = list(self.rbar_starts)
        best, tried = None, []
        with single_thread_blas():
            for r0 in starts:
                eta0 = lay.eta0()
                if r0 is not None:
                    for i in set(pb.i_rbar):
                        if not lay.params[i].fixed:
                            eta0[i] = math.log(float(np.clip(r0, lay.params[i].lower,
                                                             lay.params[i].upper)))
                with record_warnings() as caught:
                    res = minimize_criterion(pb, self.criterion, eta0, solver=self.solver,
                                             max_iter=self.max_iter, tol=self.tol,
                                             stall=self.stall, step_scale=step_scale)
                tried.append(({"rbar_v": r0}, res.value))
                if best is None or res.value < best[0].value:
                    best = (res, caught)
            res, caught = best
            pb.release_buffers()        # the search keeps fitted problems; not their buffers
            for w in caught:
                warnings.warn(w.message, w.category, stacklevel=2)
            self.problem_ = pb
            self.eta_ = res.eta
            self.value_ = res.value
            self.step_scale_ = res.step_scale
            self.nll_ = res.value if self.criterion == "likelihood" else pb.nll(res.eta)
        self.params_ = lay.values(res.eta)
        rb, cv = pb.rbar_c(res.eta)
        if pb.options.per_edge or not len(rb):
            self.rbar_v_, self.c_v_ = rb, cv
        else:
            self.rbar_v_, self.c_v_ = float(rb[0]), float(cv[0])
        self.tau0_ = self.params_.get("tau0", float("nan"))
        self.n_obs_ = pb.n_obs
        self.n_free_ = int(lay.free().sum())
        if self.criterion == "likelihood":
            self.aic_ = 2 * self.nll_ + 2 * self.n_free_
            self.bic_ = 2 * self.nll_ + self.n_free_ * math.log(max(self.n_obs_, 1))
        else:
            self.aic_ = self.bic_ = float("nan")
        bounds = lay.at_bounds(res.eta)
        phys = [b for b in bounds if b.startswith(("rbar_v", "tau0"))]
        if phys:
            warnings.warn("; ".join(phys) + ": the criterion, not the building, chose this "
                          "value (see thermctl.estimate.likelihood.uncertainty)", BoundWarning, stacklevel=2)
        self.model_ = pb.thermal_model(res.eta, meta={"greybox": {
            "criterion": self.criterion, "params": self.params_, "nll": self.nll_}})
        self.wall_time_ = time.perf_counter() - t0
        self.result_ = LikelihoodResult(self.criterion, self.value_, dict(self.params_), rb, cv,
                                     [e.name for e in pb.edges], self.n_obs_, self.n_free_,
                                     self.aic_, self.bic_, bounds, res.success, res.message,
                                     res.n_iter, self.wall_time_, tried, pb.fit_rule)
        log.info("grey-box fit: %s", self.result_.summary().replace("\n", "; "))
        return self

    # ------------------------------------------------------------------ use
    def _check_fitted(self):
        if not hasattr(self, "eta_"):
            raise EstimationError("this LikelihoodEstimator is not fitted yet; call fit(data) first")

    def problem_for(self, data) -> LikelihoodProblem:
        """A problem on other data (same network and options) whose layout matches ``eta_``."""
        self._check_fitted()
        pb = self.make_problem(data, init=self.params_)
        if pb.layout.names != self.problem_.layout.names:
            raise DataError(f"these data give different parameters ({pb.layout.names}) than the "
                            f"fitted ones ({self.problem_.layout.names}); solar columns or time "
                            "stamps differ")
        return pb

    def score(self, data) -> float:
        """Negative log-likelihood per observation of other data at the fitted parameters."""
        pb = self.problem_for(data)
        with single_thread_blas():
            return pb.nll(self.eta_) / max(pb.n_obs, 1)
