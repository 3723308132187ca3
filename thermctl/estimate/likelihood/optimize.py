"""Minimise a :class:`~thermctl.estimate.likelihood.problem.LikelihoodProblem` criterion over ``eta``.

Two solvers, both fed the exact CasADi gradient:

* ``lbfgs`` — scipy's L-BFGS-B on the free coordinates (box bounds);
* ``ipopt`` — CasADi's IPOPT interface on the same MX graph (limited-memory Hessian by
  default; ``hessian="exact"`` makes CasADi build the exact one).

Objectives are scaled to O(1) per observation (likelihood / n_obs, k-step MSE / (0.1 K)²)
so that the default tolerances mean the same thing on short and long data.
"""

from __future__ import annotations

import logging
import time
import warnings
from dataclasses import dataclass

import casadi as ca
import numpy as np
from scipy.optimize import minimize

from ...errors import ConvergenceWarning, EstimationError

__all__ = ["OptResult", "minimize_criterion", "CRITERIA", "SOLVERS"]

log = logging.getLogger(__name__)

CRITERIA = ("likelihood", "kstep")
SOLVERS = ("lbfgs", "ipopt")
_KSTEP_REF = 0.1 ** 2     # [K²]: k-step MSE is divided by this (a 0.1 K error is "1")


@dataclass
class OptResult:
    """One optimiser run.

    Attributes
    ----------
    eta : ndarray
        Minimiser (all coordinates, fixed ones included).
    value : float
        Criterion at ``eta``, unscaled (negative log-likelihood, or k-step SSE [K²]).
    success : bool
    message : str
    n_iter, n_eval : int
    time : float
        [s]
    solver : str
    """

    eta: np.ndarray
    value: float
    success: bool
    message: str
    n_iter: int
    n_eval: int
    time: float
    solver: str


def _scale(problem, criterion):
    if criterion == "likelihood":
        return 1.0 / max(problem.n_obs, 1)
    return 1.0 / (max(problem.n_kstep, 1) * _KSTEP_REF)


def minimize_criterion(problem, criterion: str = "likelihood", eta0=None, *, solver: str = "lbfgs",
                       max_iter: int = 300, tol: float = 1e-9, free=None, hessian: str = "limited-memory"
                       ) -> OptResult:
    """Minimise the criterion from ``eta0`` within the layout's bounds.

    Parameters
    ----------
    problem : LikelihoodProblem
    criterion : {"likelihood", "kstep"}
    eta0 : array_like, optional
        Start (default: the layout's start values).
    solver : {"lbfgs", "ipopt"}
    max_iter : int
    tol : float
        Tolerance on the scaled objective (L-BFGS-B ``ftol``/``gtol``; IPOPT ``tol``).
    free : array_like of bool, optional
        Coordinates to optimise (default: the layout's free parameters); the others stay
        at ``eta0``.
    hessian : {"limited-memory", "exact"}
        IPOPT only.
    """
    if criterion not in CRITERIA:
        raise EstimationError(f"criterion must be one of {CRITERIA}, found {criterion!r}")
    if solver not in SOLVERS:
        raise EstimationError(f"solver must be one of {SOLVERS}, found {solver!r}")
    lay = problem.layout
    lo, hi = lay.bounds()
    eta0 = lay.eta0() if eta0 is None else np.array(eta0, dtype=float)
    free = lay.free() if free is None else np.asarray(free, dtype=bool) & lay.free()
    eta0 = np.clip(eta0, lo, hi)
    s = _scale(problem, criterion)
    t0 = time.perf_counter()
    if solver == "lbfgs":
        res = _lbfgs(problem, criterion, eta0, free, lo, hi, s, max_iter, tol)
    else:
        res = _ipopt(problem, criterion, eta0, free, lo, hi, s, max_iter, tol, hessian)
    res.time = time.perf_counter() - t0
    if not res.success:
        warnings.warn(f"{solver} stopped before converging on the {criterion} criterion after "
                      f"{res.n_iter} iterations: {res.message}", ConvergenceWarning, stacklevel=2)
    return res


def _lbfgs(problem, criterion, eta0, free, lo, hi, s, max_iter, tol):
    fg = problem.nll_grad if criterion == "likelihood" else problem.kstep_grad
    idx = np.flatnonzero(free)
    n_eval = [0]

    def fun(z):
        eta = eta0.copy()
        eta[idx] = z
        n_eval[0] += 1
        try:
            f, g = fg(eta)
        except RuntimeError as exc:      # CasADi numerical failure: step back
            log.debug("criterion failed at %s: %s", eta, exc)
            return np.inf, np.zeros(len(idx))
        if not np.isfinite(f) or not np.all(np.isfinite(g)):
            return np.inf, np.zeros(len(idx))
        return f * s, g[idx] * s

    if not len(idx):
        f = fun(np.zeros(0))[0] / s
        return OptResult(eta0, f, True, "nothing to optimise", 0, 1, 0.0, "lbfgs")
    r = minimize(fun, eta0[idx], jac=True, method="L-BFGS-B",
                 bounds=list(zip(lo[idx], hi[idx])),
                 options={"maxiter": max_iter, "ftol": tol, "gtol": 1e-7, "maxcor": 20})
    eta = eta0.copy()
    eta[idx] = r.x
    ok = bool(r.success) or "REL_REDUCTION" in str(r.message).upper()
    return OptResult(eta, float(r.fun) / s, ok, str(r.message), int(r.nit), n_eval[0], 0.0, "lbfgs")


def _ipopt(problem, criterion, eta0, free, lo, hi, s, max_iter, tol, hessian):
    expr = problem._nll if criterion == "likelihood" else problem._kstep
    if expr is None:
        problem._need_kstep()
    x = problem._eta
    lbx = np.where(free, lo, eta0)
    ubx = np.where(free, hi, eta0)
    opts = {"ipopt.print_level": 0, "print_time": False, "ipopt.max_iter": max_iter,
            "ipopt.tol": tol, "ipopt.hessian_approximation": hessian,
            "ipopt.sb": "yes", "error_on_fail": False}
    key = (criterion, hessian)
    cache = problem.__dict__.setdefault("_ipopt_cache", {})
    if key not in cache:
        cache[key] = ca.nlpsol(f"gb_{criterion}", "ipopt", {"x": x, "f": expr * s}, opts)
    S = cache[key]
    sol = S(x0=eta0, lbx=lbx, ubx=ubx)
    st = S.stats()
    eta = np.asarray(sol["x"], dtype=float).ravel()
    ok = bool(st.get("success", False))
    status = str(st.get("return_status", ""))
    it = int(st.get("iter_count", -1))
    return OptResult(eta, float(sol["f"]) / s, ok, status, it, -1, 0.0, "ipopt")
