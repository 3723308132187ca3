"""The paper's exhaustive search over (rbar_v, tau0): the reference for the NLP."""

from __future__ import annotations

import logging
import math
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ..._blas import single_thread_blas
from ...errors import BoundWarning, EstimationError
from .result import GridResult
from .sim import ExactSimulator

__all__ = ["grid_search"]

log = logging.getLogger(__name__)

def grid_search(problem, n_rbar: int = 41, n_tau: int = 9, *, rbar_range=None, tau_range=None,
                n_jobs: int = 2, chunk: int | None = None, progress=None,
                warn: bool = True) -> GridResult:
    """J on a grid: rbar_v log-spaced, ``tau0 = rbar_v·c_v`` evenly spaced (paper IV-B).

    Every point is simulated exactly (:class:`~.sim.ExactSimulator`: the symmetric
    eigendecomposition of each distinct supply-flow state matrix, vectorised over the
    grid points). For ``initial_state="estimate"`` each point's J is minimised over the
    free initial states (a linear least-squares problem per point).

    Parameters
    ----------
    problem : CostProblem
        Must have shared parameters (``per_edge=False``); a grid cannot follow more.
    n_rbar : int
        Points in rbar_v (default 41).
    n_tau : int
        Points in tau0 (default 9).
    rbar_range : (float, float), optional
        [K/(W m)]; default ``problem.rbar_bounds`` (the paper's [1e-6, 1e-2]).
    tau_range : (float, float), optional
        [s/m]; default ``problem.tau_bounds`` = ``[t_min/alpha, t_max/alpha]``.
    n_jobs : int
        Threads (numpy releases the GIL in the linear algebra); default 2.
    chunk : int, optional
        Grid points per vectorised batch (default: about a quarter of a thread's share).
    progress : callable, optional
        ``progress(stage, done, total)`` after each batch, ``stage = "grid"``.
    warn : bool
        Emit :class:`~thermctl.errors.BoundWarning` when the minimum is on the edge of
        the search range.

    Returns
    -------
    GridResult

    Examples
    --------
    >>> g = grid_search(CostProblem(net, data))        # doctest: +SKIP
    >>> g.best_rbar_v, g.best_c_v                       # doctest: +SKIP
    """
    import warnings

    if problem.per_edge:
        raise EstimationError("grid_search covers the shared (rbar_v, tau0) only; a grid over "
                              f"{problem.n_eta} parameters is out of reach: use fit(..., "
                              "per_edge=True)")
    if n_rbar < 1 or n_tau < 1:
        raise EstimationError(f"grid needs at least 1 point per axis, found {n_rbar} × {n_tau}")
    t0 = time.perf_counter()
    r_lo, r_hi = problem.rbar_bounds if rbar_range is None else rbar_range
    t_lo, t_hi = problem.tau_bounds if tau_range is None else tau_range
    rbar = np.geomspace(r_lo, r_hi, n_rbar) if n_rbar > 1 else np.array([math.sqrt(r_lo * r_hi)])
    tau = np.linspace(t_lo, t_hi, n_tau) if n_tau > 1 else np.array([math.sqrt(t_lo * t_hi)])
    T, R = np.meshgrid(tau, rbar, indexing="ij")
    etas = np.column_stack([np.log(R.ravel() / problem.theta_ref[0]),
                            np.log((T / R).ravel() / problem.theta_ref[1])])
    sim = problem.simulator
    G = len(etas)
    n_jobs = max(1, int(n_jobs))
    if not isinstance(sim, ExactSimulator):
        n_jobs = 1    # the others evaluate CasADi functions per point: keep them in this thread
    if chunk is None:
        chunk = max(4, min(64, math.ceil(G / (4 * n_jobs))))
    pieces = [slice(i, min(i + chunk, G)) for i in range(0, G, chunk)]
    J = np.empty(G)
    O = np.empty(G)          # J + x0_weight·Σδ²: the NLPs' objective, which ranks the points
    if progress:
        progress("grid", 0, G)
    # CasADi evaluations (matrix assembly) stay in this thread; the workers only do numpy
    n_sim0 = sim.n_sim
    prepared = [sim.prepare(etas[s]) for s in pieces]
    with single_thread_blas():
        _run(sim, etas, pieces, prepared, J, O, n_jobs, progress, G)
    J = J.reshape(n_tau, n_rbar)
    O = O.reshape(n_tau, n_rbar)
    if not np.all(np.isfinite(J)):
        bad = np.argwhere(~np.isfinite(J))[0]
        raise EstimationError(f"J is not finite at rbar_v = {rbar[bad[1]]:.3g}, tau0 = "
                              f"{tau[bad[0]]:.3g}: check the data window for inf values")
    # ranked by the objective, not J: with free initial states the two differ by the
    # ridge term (2.8 of 41 K² on a 12-h window of a finite-volume plant), and an NLP
    # started at the J-best point then ends "above" it while lowering its own objective
    i_t, i_r = np.unravel_index(np.argmin(O), O.shape)
    active = []
    if n_rbar > 1 and i_r == 0:
        active.append(f"rbar_v at the lower end of the search range {rbar[0]:.3g} K/(W m)")
    if n_rbar > 1 and i_r == n_rbar - 1:
        active.append(f"rbar_v at the upper end of the search range {rbar[-1]:.3g} K/(W m)")
    if n_tau > 1 and i_t == 0:
        active.append(f"tau0 at its lower bound t_min/alpha = {tau[0]:.3g} s/m")
    if n_tau > 1 and i_t == n_tau - 1:
        active.append(f"tau0 at its upper bound t_max/alpha = {tau[-1]:.3g} s/m")
    res = GridResult(rbar, tau, J, float(rbar[i_r]), float(tau[i_t] / rbar[i_r]), float(tau[i_t]),
                     float(J[i_t, i_r]), (int(i_t), int(i_r)), active, sim.n_sim - n_sim0,
                     time.perf_counter() - t0,
                     sim.description,
                     problem.initial_state)
    log.info(res.summary())
    if warn and active:
        warnings.warn("grid minimum on a bound — the criterion, not the building, chose it: "
                      + "; ".join(active), BoundWarning, stacklevel=2)
    return res


def _run(sim, etas, pieces, prepared, J, O, n_jobs, progress, G):
    done = 0
    if n_jobs == 1:
        for s, prep in zip(pieces, prepared):
            J[s], O[s] = sim.cost_batch(etas[s], prep, objective=True)
            done += s.stop - s.start
            if progress:
                progress("grid", done, G)
        return
    with ThreadPoolExecutor(n_jobs) as pool:
        futures = [(s, pool.submit(sim.cost_batch, etas[s], prep, True))
                   for s, prep in zip(pieces, prepared)]
        for s, fut in futures:
            J[s], O[s] = fut.result()
            done += s.stop - s.start
            if progress:
                progress("grid", done, G)
