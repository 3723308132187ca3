r"""Can the data pin each parameter? Profiles of J and the log-space Hessian.

For each parameter the *profile* fixes it at multiples of its estimate and re-optimises
the others (single shooting, warm-started): how much J rises over a decade says in
plain numbers how strongly the data determine it. The likelihood-ratio 95 % interval
uses ``n·log(J_p/Ĵ) ≤ 3.84`` with ``n`` the number of residuals, which assumes white
residuals; with model error (unknown gains, closed-loop data) it is optimistic, so the
verdict thresholds are on the interval *and* shown beside the plain rise.

The Gauss–Newton Hessian of J in ``log θ`` (initial states projected out) gives the
local picture: a tiny eigenvalue names a direction the data cannot see, typically
``c_v`` at 5-minute data — the convection capacitance only shapes the first seconds of
an exchange whose time constant is seconds.
"""

from __future__ import annotations

import logging
import math

import numpy as np
from scipy.optimize import minimize_scalar

from .result import ProfileReport, ParameterProfile

__all__ = ["identifiability_report", "PROFILE_FACTORS"]

log = logging.getLogger(__name__)

PROFILE_FACTORS = tuple(10.0 ** np.array([-0.5, -0.25, 0.25, 0.5]))
"""Multiples of the estimate at which each parameter is profiled (a decade centred on it)."""

_CHI2_95 = 3.841458820694124


def _start_with_fixed(problem, eta, i, value):
    """A feasible start with ``eta[i] = value``, or None if no feasible point has it."""
    e = np.array(eta, dtype=float)
    e[i] = value
    if not (problem.eta_lb[i] - 1e-12 <= value <= problem.eta_ub[i] + 1e-12):
        return None
    n_r = problem.n_eta - 1
    if i == n_r:   # c_v fixed: move every rbar_v into the tau range
        lo = np.maximum(problem.eta_lb[:n_r], problem.tau_lb - value)
        hi = np.minimum(problem.eta_ub[:n_r], problem.tau_ub - value)
        if np.any(lo > hi + 1e-12):
            return None
        e[:n_r] = np.clip(e[:n_r], lo, hi)
    else:          # one rbar_v fixed: c_v must keep every edge's tau in range
        g_other = e[:n_r]
        lo = max(problem.eta_lb[-1], float(np.max(problem.tau_lb - g_other)))
        hi = min(problem.eta_ub[-1], float(np.min(problem.tau_ub - g_other)))
        if lo > hi + 1e-12:
            lo_c = problem.tau_lb[i] - value
            hi_c = problem.tau_ub[i] - value
            c = float(np.clip(e[-1], max(lo_c, problem.eta_lb[-1]), min(hi_c, problem.eta_ub[-1])))
            e[-1] = c
            others = [k for k in range(n_r) if k != i]
            e[others] = np.clip(e[others], problem.tau_lb[others] - c, problem.tau_ub[others] - c)
        else:
            e[-1] = float(np.clip(e[-1], lo, hi))
    return e


def _profile_point(problem, solver, start, i):
    """min J over the other parameters with parameter ``i`` fixed at ``start[i]``."""
    sim = problem.simulator
    if problem.n_eta == 2:
        # one free parameter: a bounded scalar search on its feasible interval
        j = 1 - i
        if j == 1:   # c_v free, rbar_v fixed
            lo = max(problem.eta_lb[1], problem.tau_lb[0] - start[0])
            hi = min(problem.eta_ub[1], problem.tau_ub[0] - start[0])
        else:        # rbar_v free, c_v fixed
            lo = max(problem.eta_lb[0], problem.tau_lb[0] - start[1])
            hi = min(problem.eta_ub[0], problem.tau_ub[0] - start[1])
        e = start.copy()

        def J(v):
            e[j] = v
            return sim.cost(e).J

        if hi - lo < 1e-9:
            return J(lo)
        r = minimize_scalar(J, bounds=(lo, hi), method="bounded", options={"xatol": 1e-4})
        return float(min(r.fun, J(lo), J(hi), sim.cost(start).J))
    lbx, ubx = problem.eta_lb.copy(), problem.eta_ub.copy()
    lbx[i] = ubx[i] = start[i]
    sol = solver.solve(start, lbx, ubx)
    return float(min(sim.cost(sol["eta"]).J, sim.cost(start).J))


def _crossing(log_f, rise, thr):
    """Factor where the profile first exceeds ``thr`` going outward from 0 (or None)."""
    prev_x, prev_y = 0.0, 0.0
    for x, y in zip(log_f, rise):
        if not np.isfinite(y):
            return None
        if y >= thr:
            if prev_x == 0.0:   # from the optimum J grows quadratically
                return math.exp(x * math.sqrt(thr / y))
            t = (thr - prev_y) / (y - prev_y) if y != prev_y else 1.0
            return math.exp(prev_x + t * (x - prev_x))
        prev_x, prev_y = x, y
    return None


def identifiability_report(problem, eta_hat, J_hat: float | None = None, *, solver=None,
                           factors=PROFILE_FACTORS, progress=None) -> ProfileReport:
    """Profiles of J along each parameter and the Hessian's eigenvalues in log space.

    Parameters
    ----------
    problem : CostProblem
    eta_hat : array_like, shape (n_eta,)
        The estimate (scaled log-parameters).
    J_hat : float, optional
        J at the estimate [K²] (recomputed if not given).
    solver : SingleShootingNLP, optional
        Re-optimises the other parameters at each profile point when there are more than
        two (built if not given); with two, a bounded scalar search does it.
    factors : sequence of float
        Multiples of the estimate to profile at (default ``10**[-0.5, -0.25, 0.25, 0.5]``).
    progress : callable, optional
        ``progress("profile", done, total)``.

    Returns
    -------
    ProfileReport
    """
    from .nlp import SingleShootingNLP

    eta_hat = np.asarray(eta_hat, dtype=float)
    sim = problem.simulator
    ev = sim.cost(eta_hat, grad=True)
    J_hat = ev.J if J_hat is None else float(J_hat)
    H = ev.hess
    lam, V = np.linalg.eigh(H)
    cond = float(lam[-1] / lam[0]) if lam[0] > 0 else math.inf
    if solver is None and problem.n_eta > 2:
        # loose tolerances: a profile value needs ~4 digits, not 9
        solver = SingleShootingNLP(problem, {"tol": 1e-6, "acceptable_tol": 1e-4,
                                             "max_iter": 50})
    factors = np.sort(np.asarray(factors, dtype=float))
    ne = problem.n_eta
    total = ne * len(factors)
    done = 0
    thr = math.expm1(_CHI2_95 / problem.n_res)       # relative rise of the 95 % interval
    J_ref = max(J_hat, 1e-300)
    profiles = {}
    for i, name in enumerate(problem.param_names):
        Jp = np.full(len(factors), np.nan)
        for k, f in enumerate(factors):
            start = _start_with_fixed(problem, eta_hat, i, eta_hat[i] + math.log(f))
            if start is not None:
                Jp[k] = _profile_point(problem, solver, start, i)
            done += 1
            if progress:
                progress("profile", done, total)
        rise = (Jp - J_hat) / J_ref
        lf = np.log(factors)
        up, down = lf > 0, lf < 0
        ends = [rise[np.argmax(lf)], rise[np.argmin(lf)]]
        finite = [r for r in ends if np.isfinite(r)]
        rise_decade = float(min(finite)) if finite else float("nan")
        hi = _crossing(lf[up], rise[up], thr)
        lo = _crossing(-lf[down][::-1], rise[down][::-1], thr)
        lo = None if lo is None else 1.0 / lo
        bound_lo = bool(np.any(~np.isfinite(Jp[down])))
        bound_hi = bool(np.any(~np.isfinite(Jp[up])))
        verdict = _verdict(lo, hi, bound_lo, bound_hi)
        if (eta_hat[i] - problem.eta_lb[i] < 1e-3) or (problem.eta_ub[i] - eta_hat[i] < 1e-3):
            verdict = "on a bound"
        ci = (lo if lo is not None else (float("nan") if bound_lo else factors[0]),
              hi if hi is not None else (float("nan") if bound_hi else factors[-1]))
        profiles[name] = ParameterProfile(name, factors, Jp, rise_decade, ci, verdict)
    text = _text(problem, eta_hat, J_hat, profiles, lam, V, cond, thr)
    log.info(text)
    return ProfileReport(profiles, H, lam, V, cond, text, J_hat)


def _verdict(lo, hi, bound_lo, bound_hi):
    """Each side of the estimate must close within the range; a side cut by a bound
    does not count against (the active-bound report says that part)."""
    sides = [(lo is None and bound_lo, None if lo is None else 1.0 / lo),
             (hi is None and bound_hi, hi)]
    open_sides = [f for blocked, f in sides if not blocked]
    if not open_sides:
        return "weakly identified"
    if any(f is None for f in open_sides):
        return "not identifiable"
    if all(f <= 10 ** 0.25 + 1e-9 for f in open_sides):
        return "well identified"
    return "weakly identified"


def _end(f, edge, side):
    if not np.isfinite(f):
        return "the bound"
    if abs(f - edge) < 1e-12 * edge:
        return f"{side} ×{f:.3g} (not reached)"
    return f"×{f:.4g}"


def _text(problem, eta_hat, J_hat, profiles, lam, V, cond, thr):
    theta = problem.theta(eta_hat)
    n_r = problem.n_eta - 1
    lines = [f"Identifiability (J = {J_hat:.4g} K², {problem.n_res} residuals; a rise of "
             f"{100 * thr:.2g} % bounds the 95 % profile interval):"]
    for i, (name, prof) in enumerate(profiles.items()):
        unit = "K/(W m)" if i < n_r else "J/K"
        rise = prof.rise_decade
        rise_s = "n/a (bounds)" if not np.isfinite(rise) else f"{100 * rise:.3g} %"
        lo, hi = prof.ci95
        ci_s = (_end(lo, prof.factors[0], "below") + " … " + _end(hi, prof.factors[-1], "above"))
        if prof.verdict == "on a bound":
            words = ("ON ITS BOUND: the criterion pushes it there, the data do not determine "
                     "it; the profile only says how steeply J rises away from the bound")
        elif prof.verdict == "well identified":
            words = "well identified: the data pin it"
        elif prof.verdict == "weakly identified":
            words = "weakly identified: the data bound it only within a decade"
        else:
            words = ("NOT identifiable from these data: J barely changes over a decade, so its "
                     "value is set by the bounds and the starting point, not by the building")
            if name == "c_v" or name.startswith("c_v"):
                words += (" (expected for c_v at this sample step: the convective capacitance "
                          "only shapes the first seconds of an exchange; report it as a choice "
                          "within the tau0 bounds, not as a measurement)")
        lines.append(f"  {name} = {theta[i]:.4g} {unit}: {words}; J rises {rise_s} over a decade, "
                     f"95 % interval {ci_s}.")
    g = problem.tau_matrix @ eta_hat
    if np.any(g - problem.tau_lb < 1e-3) or np.any(problem.tau_ub - g < 1e-3):
        lines.append("  tau0 = rbar_v·c_v sits on its bound (t_min/alpha or t_max/alpha): the "
                     "profiles run along that bound.")
    weakest = V[:, 0]
    k = int(np.argmax(np.abs(weakest)))
    lines.append(f"  Hessian of J in log θ: eigenvalues {', '.join(f'{v:.3g}' for v in lam)} K² "
                 f"(condition {cond:.3g}); the flattest direction is mostly "
                 f"{problem.param_names[k]}.")
    return "\n".join(lines)
