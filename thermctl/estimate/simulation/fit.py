"""Fit (rbar_v, c_v): warm start from a coarse grid, IPOPT, checks, identifiability."""

from __future__ import annotations

import logging
import time
import warnings

import numpy as np

from ..._blas import single_thread_blas
from ...errors import BoundWarning, ConvergenceWarning, EstimationError
from ...model import ThermalModel
from .identifiability import identifiability_report
from ..bounds import RBAR_BOUNDS, T_MAX, T_MIN
from ..data import EstimationData
from .problem import CostProblem
from .result import EstimationResult

__all__ = ["fit", "SimulationEstimator", "METHODS"]

log = logging.getLogger(__name__)

METHODS = ("multiple_shooting", "single_shooting", "casadi_radau")


def _warm_start(problem, shape, progress):
    """Best point of a coarse (rbar_v, tau0) grid, exact simulator, shared parameters."""
    n_r, n_t = shape
    lo, hi = problem.rbar_bounds
    t_lo, t_hi = problem.tau_bounds
    # inside the bounds, so IPOPT does not start on them
    r = np.geomspace(lo, hi, n_r + 2)[1:-1]
    tau = np.geomspace(t_lo, t_hi, n_t + 2)[1:-1]
    T, R = np.meshgrid(tau, r, indexing="ij")
    m = problem.n_eta - 1
    etas = np.column_stack([np.repeat(np.log(R.ravel() / problem.theta_ref[0])[:, None], m, 1),
                            np.log((T / R).ravel() / problem.theta_ref[-1])])
    if progress:
        progress("warm start", 0, len(etas))
    _, obj = problem.simulator.cost_batch(etas, objective=True)
    if progress:
        progress("warm start", len(etas), len(etas))
    k = int(np.nanargmin(obj))
    return etas[k], float(obj[k])


def fit(problem: CostProblem, method: str = "multiple_shooting", *, theta0=None,
        warm_start=(9, 3), interval: float | None = None,
        substeps: int | None = None, ipopt_options=None, identifiability: bool = True,
        raise_on_failure: bool = False, progress=None) -> EstimationResult:
    """Minimise the paper's J with IPOPT.

    Parameters
    ----------
    problem : CostProblem
    method : {"multiple_shooting", "single_shooting", "casadi_radau"}
        ``multiple_shooting`` (default, :mod:`.shooting`): the states at shooting nodes
        every ``interval`` are decision variables tied by continuity constraints; steps,
        sensitivities and J come from the problem's simulator (exact ZOH by default: the
        grid's own J, no discretisation bias), the Hessian is Gauss–Newton.
        ``single_shooting`` (:class:`~.nlp.SingleShootingNLP`): the parameters only —
        the fast path for a handful of parameters.
        ``casadi_radau`` (:class:`~.nlp.CasadiMultipleShootingNLP`): a pure CasADi NLP
        with a node at every Radau IIA sub-step (``substeps`` per sample), the implicit
        step as equality constraints and CasADi's exact Hessian — fully inspectable,
        slower, and biased by the step error (checked against the exact J).
    theta0 : (rbar_v, c_v), optional
        Starting point ([K/(W m)], [J/K]); default: the best point of a coarse grid.
    warm_start : (int, int)
        Coarse grid size (rbar_v × tau0) for the default start.
    interval : float, optional
        Shooting interval [s] for ``multiple_shooting`` (default 1 h).
    substeps : int, optional
        Radau sub-steps per data step for ``casadi_radau`` (default one per minute).
    ipopt_options : dict, optional
        Merged over :data:`~.nlp.IPOPT_DEFAULTS` (quiet, ``tol`` 1e-9).
    identifiability : bool
        Profile J along each parameter and report (adds a few single-shooting solves).
    raise_on_failure : bool
        Raise :class:`EstimationError` instead of returning a flagged result when IPOPT fails.
    progress : callable, optional
        ``progress(stage, done, total)``; stages ``"warm start"``, ``"ipopt"``, ``"profile"``.

    Returns
    -------
    EstimationResult
        ``success=False`` flags a failed solve (with a :class:`ConvergenceWarning`); an
        estimate on a bound gives a :class:`BoundWarning`.

    Raises
    ------
    EstimationError
        Non-finite J at the estimate, non-finite iterates, or (``raise_on_failure``) an
        IPOPT failure.

    Examples
    --------
    >>> res = fit(CostProblem(net, data, initial_state="estimate"))   # doctest: +SKIP
    >>> print(res.summary())                                           # doctest: +SKIP
    """
    if method not in METHODS:
        raise EstimationError(f"method must be one of {METHODS}, found {method!r}")
    with single_thread_blas():
        return _fit(problem, method, theta0, warm_start, interval, substeps, ipopt_options,
                    identifiability, raise_on_failure, progress)


def _fit(problem, method, theta0, warm_start, interval, substeps, ipopt_options,
         identifiability, raise_on_failure, progress):
    from .nlp import CasadiMultipleShootingNLP, SingleShootingNLP
    from .shooting import MultipleShootingNLP

    t_start = time.perf_counter()
    sim = problem.simulator
    n_sim0 = sim.n_sim
    if theta0 is None:
        eta0, _ = _warm_start(problem, warm_start, progress)
    else:
        eta0 = problem.eta_from_theta(*theta0)
        if not problem.feasible(eta0):
            eta0 = problem.project(eta0)
            log.warning("theta0 outside the bounds; starting from the nearest feasible point %s",
                        problem.theta(eta0))
    if method == "single_shooting":
        nlp = SingleShootingNLP(problem, ipopt_options, progress)
        w0 = eta0
    else:
        if method == "multiple_shooting":
            nlp = MultipleShootingNLP(problem, interval, ipopt_options, progress)
        else:
            nlp = CasadiMultipleShootingNLP(problem, substeps, ipopt_options, progress)
        delta0 = sim.cost(eta0).x0[problem.free_index] - problem.x0_ref[problem.free_index]
        w0 = nlp.initial_guess(eta0, delta0)
    t_solve = time.perf_counter()
    try:
        sol = nlp.solve(w0)
    except RuntimeError as exc:   # CasADi wraps errors raised inside callbacks
        if isinstance(exc, EstimationError):
            raise
        raise EstimationError(f"IPOPT stopped with an error ({method}): "
                              f"{str(exc).splitlines()[-1]}") from exc
    solve_time = time.perf_counter() - t_solve
    eta = sol["eta"]
    if not np.all(np.isfinite(eta)):
        raise EstimationError(f"IPOPT returned non-finite parameters ({sol['status']})")
    if not problem.feasible(eta, tol=0.0):
        eta = problem.project(eta)   # IPOPT relaxes bounds by ~1e-8: put the estimate inside
    ev = sim.cost(eta)            # the grid's J at the estimate (raises if not finite)
    success = sol["success"] and np.isfinite(ev.J)
    message = "" if success else f"IPOPT did not converge: {sol['status']}"
    ev0 = sim.cost(eta0)
    if ev.objective > ev0.objective * (1.0 + 1e-9):
        # IPOPT may stop (acceptable level, iteration limit, an infeasible shooting node
        # within its constraint tolerance) at a point whose exact objective exceeds the
        # start's: never hand back worse than the start
        log.warning("%s ended at objective %.6g above its start's %.6g (%s); the start is "
                    "returned", method, ev.objective, ev0.objective, sol["status"])
        message = (message + "; " if message else "") + (
            f"IPOPT ended above its start (objective {ev.objective:.6g} > "
            f"{ev0.objective:.6g}): the start is returned")
        eta, ev = eta0, ev0
    if method == "casadi_radau" and ev.J > 0:
        gap = abs(sol["J"] - ev.J) / ev.J
        if gap > 1e-2:
            log.warning("the Radau J (%.4g) differs from the simulator's J (%.4g) by %.2g %%: "
                        "use more substeps", sol["J"], ev.J, 100 * gap)
    if not success and raise_on_failure:
        raise EstimationError(message)
    active = problem.active_bounds(eta)
    report = None
    if identifiability and success:
        report = identifiability_report(problem, eta, ev.J, progress=progress)
    theta = problem.theta(eta)
    n_r = problem.n_eta - 1
    rbar = theta[:n_r] if problem.per_edge else float(theta[0])
    res = EstimationResult(
        rbar_v=rbar, c_v=float(theta[-1]), tau0=rbar * theta[-1] if problem.per_edge
        else float(theta[0] * theta[-1]), J=ev.J, J_nlp=sol["f"], method=method,
        discretisation=nlp.discretisation, status=sol["status"], success=bool(success),
        iterations=sol["iterations"], n_sim=sim.n_sim - n_sim0,
        wall_time=time.perf_counter() - t_start, solve_time=solve_time, active_bounds=active,
        x0=ev.x0, theta0=problem.theta(eta0), initial_state=problem.initial_state,
        param_names=list(problem.param_names), identifiability=report,
        n_variables=nlp.n_variables, n_constraints=nlp.n_constraints, message=message.strip(),
        eta=eta)
    log.info(res.summary())
    if not success:
        warnings.warn(f"{method}: {res.message}", ConvergenceWarning, stacklevel=3)
    if active:
        warnings.warn("estimate on a bound — the criterion, not the building, chose it: "
                      + "; ".join(active), BoundWarning, stacklevel=3)
    return res


class SimulationEstimator:
    """Estimate the convection parameters of a network from data (paper III-B).

    The constructor only stores its arguments; :meth:`fit` builds the
    :class:`CostProblem`, solves it and sets the learned attributes.

    Parameters
    ----------
    network : ThermalNetwork
        With the convection edges to estimate.
    method, theta0, warm_start, interval, substeps, ipopt_options, identifiability,
    raise_on_failure, progress
        As :func:`fit`.
    window, K_T, start, zones, initial_state, burn_in, per_edge, t_min, t_max, rbar_bounds,
    alpha, x0_weight, simulator
        As :class:`CostProblem` (``window`` and ``burn_in`` [s], ``t_min``/``t_max`` [s/m],
        ``rbar_bounds`` [K/(W m)]).

    Attributes
    ----------
    rbar_v_ : float or ndarray
        [K/(W m)]
    c_v_ : float
        [J/K]
    J_ : float
        [K²]
    result_ : EstimationResult
    problem_ : CostProblem
    model_ : ThermalModel
        The network with the estimated parameters.

    Examples
    --------
    >>> est = SimulationEstimator(net, initial_state="estimate").fit(data)   # doctest: +SKIP
    >>> est.rbar_v_, est.c_v_                                                # doctest: +SKIP
    """

    def __init__(self, network, method: str = "multiple_shooting", *,
                 window: float = 12 * 3600.0, K_T: int | None = None, start: int | None = None,
                 zones=None, initial_state: str = "paper", burn_in: float = 24 * 3600.0,
                 per_edge: bool = False, t_min: float = T_MIN, t_max: float = T_MAX,
                 rbar_bounds=RBAR_BOUNDS, alpha: float | None = None, x0_weight: float = 1e-6,
                 simulator: str = "exact", theta0=None, warm_start=(9, 3),
                 interval: float | None = None,
                 substeps: int | None = None, ipopt_options=None, identifiability: bool = True,
                 raise_on_failure: bool = False, progress=None):
        self.network = network
        self.method = method
        self.window = window
        self.K_T = K_T
        self.start = start
        self.zones = zones
        self.initial_state = initial_state
        self.burn_in = burn_in
        self.per_edge = per_edge
        self.t_min = t_min
        self.t_max = t_max
        self.rbar_bounds = rbar_bounds
        self.alpha = alpha
        self.x0_weight = x0_weight
        self.simulator = simulator
        self.theta0 = theta0
        self.warm_start = warm_start
        self.interval = interval
        self.substeps = substeps
        self.ipopt_options = ipopt_options
        self.identifiability = identifiability
        self.raise_on_failure = raise_on_failure
        self.progress = progress

    def fit(self, data, x0=None) -> "SimulationEstimator":
        """Fit to ``data``.

        Parameters
        ----------
        data : EstimationData, pandas.DataFrame or thermctl.data.Measurements
            A table is read with :meth:`EstimationData.from_frame`.
        x0 : array_like, optional
            Initial state [°C] when ``initial_state="given"``.

        Returns
        -------
        self
        """
        network = self.network
        if not isinstance(data, EstimationData):
            data = EstimationData.from_frame(data, network)
        self.problem_ = CostProblem(
            network, data, window=self.window, K_T=self.K_T, start=self.start, zones=self.zones,
            initial_state=self.initial_state, burn_in=self.burn_in, x0=x0,
            per_edge=self.per_edge, t_min=self.t_min, t_max=self.t_max,
            rbar_bounds=self.rbar_bounds, alpha=self.alpha, x0_weight=self.x0_weight,
            simulator=self.simulator, substeps=self.substeps)
        self.result_ = fit(self.problem_, self.method, theta0=self.theta0,
                           warm_start=self.warm_start,
                           interval=self.interval, substeps=self.substeps,
                           ipopt_options=self.ipopt_options, identifiability=self.identifiability,
                           raise_on_failure=self.raise_on_failure, progress=self.progress)
        self.rbar_v_ = self.result_.rbar_v
        self.c_v_ = self.result_.c_v
        self.J_ = self.result_.J
        self.model_ = ThermalModel(network, self.rbar_v_, self.c_v_)
        return self
