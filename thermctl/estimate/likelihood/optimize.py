"""Minimise a :class:`~thermctl.estimate.likelihood.problem.LikelihoodProblem` criterion over ``eta``.

Two solvers, both fed the exact CasADi gradient:

* ``lbfgs`` — scipy's L-BFGS-B on the free coordinates (box bounds; noise intensities
  moved on ``asinh(σ/σ0)``, see :data:`NOISE_STEP`);
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

__all__ = ["OptResult", "minimize_criterion", "CRITERIA", "SOLVERS", "STALL"]

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
    step_scale : dict or None
        L-BFGS-B only: per free parameter (by name), the square root of the diagonal of its
        last inverse-Hessian approximation in the coordinates it moved (``log`` or
        ``asinh``, :data:`NOISE_STEP`): how far that coordinate may move for one unit of
        the scaled criterion. A fit warm-started from this one takes it as its
        ``step_scale`` (:func:`minimize_criterion`).
    """

    eta: np.ndarray
    value: float
    success: bool
    message: str
    n_iter: int
    n_eval: int
    time: float
    solver: str
    step_scale: dict | None = None


def _scale(problem, criterion):
    if criterion == "likelihood":
        return 1.0 / max(problem.n_obs, 1)
    return 1.0 / (max(problem.n_kstep, 1) * _KSTEP_REF)


def minimize_criterion(problem, criterion: str = "likelihood", eta0=None, *, solver: str = "lbfgs",
                       max_iter: int = 300, tol: float = 1e-9, free=None, hessian: str = "limited-memory",
                       stall: tuple | None = None, step_scale: dict | None = None) -> OptResult:
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
    stall : (int, float), optional
        L-BFGS-B only: ``(k, gain)`` stops the run, as converged, once the best criterion
        value has improved by less than ``gain`` (unscaled: nats, or K²) over the last ``k``
        evaluations (:data:`STALL` for a search's fits). Default: no such stop.
    step_scale : dict, optional
        L-BFGS-B only: the :attr:`OptResult.step_scale` of a fit this one is warm-started
        from. Each coordinate is divided by its scale (over their median; a parameter the
        dict lacks, 1), so that L-BFGS-B starts with the curvature that fit learned
        instead of the identity (:func:`_step_scales` says what it saves).
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
        res = _lbfgs(problem, criterion, eta0, free, lo, hi, s, max_iter, tol, stall,
                     step_scale)
    else:
        res = _ipopt(problem, criterion, eta0, free, lo, hi, s, max_iter, tol, hessian)
    res.time = time.perf_counter() - t0
    if not res.success:
        warnings.warn(f"{solver} stopped before converging on the {criterion} criterion after "
                      f"{res.n_iter} iterations: {res.message}", ConvergenceWarning, stacklevel=2)
    return res


NOISE_GROUPS = ("sigma_v", "sigma_q", "sigma_phi", "sigma_g", "sigma_e", "sigma_b")
"""Parameter groups that are noise intensities (L-BFGS-B moves them by :data:`NOISE_STEP`)."""

NOISE_STEP = "asinh"
"""How L-BFGS-B moves a noise intensity σ: ``"asinh"`` on ``z = asinh(σ / σ0)`` (σ0 its
value at the fit's start), ``"log"`` on ``log σ`` as the layout stores it.

Why: a noise term the data do not need drives its σ toward the lower bound, where the
likelihood is flat in ``log σ`` (its gradient there is σ·∂L/∂σ → 0), and L-BFGS-B crawls,
a few hundredths of a nat per iteration. ``z`` is linear in σ below σ0 and logarithmic
above, so the bound is one step away. On the twin house N2, 43 of the selection's 45
structures ended at the same or a lower likelihood (by up to 23 nats where the
200-iteration cap stops the fit; the other two 0.5-0.6 nats higher) in 11 % fewer
evaluations. It does not choose between the modes of the per-zone noise: a fit ends in the
one its start leads to. The fitted model and the intervals are in ``eta`` as before.
"""


STALL = (20, 0.05)
"""``(k, gain)``: a search's fit stops once its best value has gained less than ``gain``
nats over its last ``k`` likelihood evaluations (``minimize_criterion(stall=)``).

Why: L-BFGS-B's own tests (``ftol`` 1e-9 on the criterion per observation, ``gtol``) hold
on until a noise intensity that the data do not need has crept to its bound, a few
hundredths of a nat per iteration. On the twin house N2 a default ``identify`` made 3 916
evaluations without the rule and 3 431 with it (24 of its 60 L-BFGS-B runs ended on it, each
within 0.79 nats of where it ended before; 2:56 → 2:31 wall), the same selection path step
for step: a BIC margin of 10 is 5 nats. A test at its threshold can still flip (one of the
34 family buildings, docs/identification.md).
"""


def _noise_coords(problem, idx):
    """Which of the coordinates ``idx`` L-BFGS-B moves by :data:`NOISE_STEP`."""
    if NOISE_STEP != "asinh":
        return np.zeros(len(idx), dtype=bool)
    ps = problem.layout.params
    return np.array([ps[i].group in NOISE_GROUPS and ps[i].log for i in idx], dtype=bool)


def _step_scales(problem, idx, step_scale) -> np.ndarray:
    """The scale of each coordinate ``idx`` from ``step_scale`` (by name), over their median
    (a coordinate the dict lacks: 1; each within [1e-3, 1e3]).

    Why: warm-started, L-BFGS-B still begins with the identity for a Hessian, while the
    coordinates' curvatures differ by orders of magnitude (twin house N2, SIN's 9 picks: the
    square root of the inverse Hessian's diagonal runs from 0.58 to 28 around a median of
    1), and it spends its first tens of evaluations learning them again. The nine removal
    trials from that fit took 344 likelihood evaluations instead of 577 (30–103 each before,
    30–45 after), and each ended lower, by 0.2–0.6 nats. The square roots of those scales
    saved nothing (605 evaluations).
    """
    if not step_scale:
        return np.ones(len(idx))
    ps = problem.layout.params
    d = np.array([step_scale.get(getattr(ps[i], "name", None), np.nan) for i in idx],
                 dtype=float)
    ok = np.isfinite(d) & (d > 0)
    if not ok.any():
        return np.ones(len(idx))
    d = np.where(ok, d / np.median(d[ok]), 1.0)
    return np.clip(d, 1e-3, 1e3)


def _lbfgs(problem, criterion, eta0, free, lo, hi, s, max_iter, tol, stall=None,
           step_scale=None):
    fg = problem.nll_grad if criterion == "likelihood" else problem.kstep_grad
    idx = np.flatnonzero(free)
    n_eval = [0]
    best = []                        # best unscaled value after each evaluation
    stalled = [False]
    nz = _noise_coords(problem, idx)
    c = np.exp(eta0[idx][nz])        # σ0: z = asinh(σ/σ0), σ = σ0·sinh(z)
    d = _step_scales(problem, idx, step_scale)     # L-BFGS-B moves w = z / d

    def to_eta(z):
        e = z.copy()
        e[nz] = np.log(c * np.sinh(z[nz]))
        return e

    def to_z(e):
        z = np.array(e, dtype=float)
        z[nz] = np.arcsinh(np.exp(z[nz]) / c)
        return z

    def fun(w):
        z = w * d
        eta = eta0.copy()
        eta[idx] = to_eta(z)
        n_eval[0] += 1
        try:
            f, g = fg(eta)
        except RuntimeError as exc:      # CasADi numerical failure: step back
            if "KeyboardInterrupt" in str(exc):
                # Ctrl-C inside a callback reaches us as CasADi's RuntimeError: a user's
                # stop, not a failed evaluation to step back from
                raise KeyboardInterrupt from exc
            log.debug("criterion failed at %s: %s", eta, exc)
            return np.inf, np.zeros(len(idx))
        if not np.isfinite(f) or not np.all(np.isfinite(g)):
            return np.inf, np.zeros(len(idx))
        best.append(min(f, best[-1]) if best else f)
        g = g[idx] * s
        g[nz] = g[nz] / np.tanh(z[nz])
        return f * s, g * d

    if not len(idx):
        f = fun(np.zeros(0))[0] / s
        return OptResult(eta0, f, True, "nothing to optimise", 0, 1, 0.0, "lbfgs")
    zlo, zhi = to_z(lo[idx]), to_z(hi[idx])
    z0 = np.clip(to_z(eta0[idx]), zlo, zhi)
    wlo, whi = zlo / d, zhi / d

    def check(intermediate_result):  # once per iteration (scipy's callback protocol)
        k, gain = stall
        if len(best) > k and best[-k - 1] - best[-1] < gain:
            stalled[0] = True
            raise StopIteration

    r = minimize(fun, z0 / d, jac=True, method="L-BFGS-B",
                 bounds=list(zip(wlo, whi)), callback=None if stall is None else check,
                 options={"maxiter": max_iter, "ftol": tol, "gtol": 1e-7, "maxcor": 20})
    eta = eta0.copy()
    eta[idx] = np.clip(to_eta(r.x * d), lo[idx], hi[idx])
    ok = bool(r.success) or "REL_REDUCTION" in str(r.message).upper() or stalled[0]
    msg = (f"stalled: gained less than {stall[1]:g} over the last {stall[0]} evaluations"
           if stalled[0] else str(r.message))
    scale = None
    hinv = getattr(r, "hess_inv", None)
    if hinv is not None and hasattr(hinv, "todense"):
        # the inverse Hessian in w; in z each entry scales by d_i·d_j
        h = np.abs(np.diag(hinv.todense())) * d * d
        ps = problem.layout.params
        names = [getattr(ps[i], "name", None) for i in idx]     # (stand-ins may lack them)
        scale = {k: float(np.sqrt(v)) for k, v in zip(names, h) if k and np.isfinite(v)}
    return OptResult(eta, float(r.fun) / s, ok, msg, int(r.nit), n_eval[0], 0.0, "lbfgs",
                     scale)


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
