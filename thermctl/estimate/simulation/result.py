"""Result objects of the estimation: grid table, fit, identifiability report."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..result import FitResult

__all__ = ["GridResult", "EstimationResult", "ProfileReport", "ParameterProfile"]


@dataclass
class GridResult:
    """The paper's exhaustive search: J on a grid of (rbar_v, tau0).

    Attributes
    ----------
    rbar_v : ndarray, shape (n_rbar,)
        Grid of rbar_v [K/(W m)] (log-spaced).
    tau0 : ndarray, shape (n_tau,)
        Grid of ``tau0 = rbar_v·c_v`` [s/m].
    J : ndarray, shape (n_tau, n_rbar)
        The cost at every point [K²].
    best_rbar_v, best_c_v, best_tau0, best_J : float
        The grid's minimiser and its cost ([K/(W m)], [J/K], [s/m], [K²]). Points are
        ranked by what the NLPs minimise, ``J + x0_weight·Σδ²``, which is J itself unless
        the initial states are estimated.
    best_index : (int, int)
        ``(i_tau, i_rbar)`` of the minimum.
    active_bounds : list of str
        Bounds of the search range the minimum lies on.
    n_sim : int
        Number of simulations.
    wall_time : float
        [s]
    simulator : str
    initial_state : str
    """

    rbar_v: np.ndarray
    tau0: np.ndarray
    J: np.ndarray
    best_rbar_v: float
    best_c_v: float
    best_tau0: float
    best_J: float
    best_index: tuple
    active_bounds: list
    n_sim: int
    wall_time: float
    simulator: str
    initial_state: str

    @property
    def c_v(self) -> np.ndarray:
        """``c_v`` at every grid point [J/K], shape (n_tau, n_rbar)."""
        return self.tau0[:, None] / self.rbar_v[None, :]

    @property
    def on_bound(self) -> bool:
        return bool(self.active_bounds)

    def to_frame(self):
        """The table as a long pandas DataFrame (rbar_v, tau0, c_v, J)."""
        import pandas as pd
        R, T = np.meshgrid(self.rbar_v, self.tau0)
        return pd.DataFrame({"rbar_v": R.ravel(), "tau0": T.ravel(),
                             "c_v": (T / R).ravel(), "J": self.J.ravel()})

    def summary(self) -> str:
        s = (f"grid {len(self.tau0)} tau0 × {len(self.rbar_v)} rbar_v ({self.simulator}, "
             f"initial state '{self.initial_state}'): best J = {self.best_J:.6g} K² at "
             f"rbar_v = {self.best_rbar_v:.4g} K/(W m), c_v = {self.best_c_v:.4g} J/K "
             f"(tau0 = {self.best_tau0:.3g} s/m); {self.n_sim} simulations in "
             f"{self.wall_time:.2f} s")
        if self.active_bounds:
            s += "\nON A BOUND: " + "; ".join(self.active_bounds)
        return s


@dataclass
class ParameterProfile:
    """J along one parameter, the others re-optimised (a profile).

    Attributes
    ----------
    name : str
    factors : ndarray
        Multiples of the estimate at which J was profiled [-].
    J : ndarray
        Profiled cost [K²] (NaN where the factor was outside the bounds).
    rise_decade : float
        Relative rise of J, ``(J_p − Ĵ)/Ĵ`` [-], over a decade centred on the estimate
        (the smaller of the two ends ×√10 and ×1/√10 inside the bounds).
    ci95 : (float, float)
        Factors bounding the likelihood-ratio 95 % interval (``n·log(J_p/Ĵ) ≤ 3.84``,
        interpolated in log space; the profiled range's end if not reached) [-].
    verdict : str
        ``"well identified"``, ``"weakly identified"``, ``"not identifiable"`` or
        ``"on a bound"`` (the estimate sits on one of this parameter's bounds).
    """

    name: str
    factors: np.ndarray
    J: np.ndarray
    rise_decade: float
    ci95: tuple
    verdict: str


@dataclass
class ProfileReport:
    """Can the data pin each parameter? Profiles of J and the log-space Hessian.

    Attributes
    ----------
    profiles : dict of str → ParameterProfile
    hessian : ndarray, shape (n_eta, n_eta)
        Gauss–Newton Hessian of J in log-parameters [K²] (initial states projected out).
    eigenvalues : ndarray
        Its eigenvalues [K²], ascending.
    eigenvectors : ndarray
        Columns: the matching directions in ``log θ``.
    condition : float
        Largest over smallest eigenvalue [-].
    text : str
        The verdict in plain words.
    J : float
        J at the estimate [K²].
    """

    profiles: dict
    hessian: np.ndarray
    eigenvalues: np.ndarray
    eigenvectors: np.ndarray
    condition: float
    text: str
    J: float = float("nan")

    def __str__(self):
        return self.text


@dataclass
class EstimationResult(FitResult):
    """A fitted (rbar_v, c_v) and how it was found (a :class:`~thermctl.estimate.FitResult`).

    Attributes
    ----------
    rbar_v : float or ndarray
        [K/(W m)]; one per convection edge for a per-edge fit.
    c_v : float
        [J/K]
    tau0 : float or ndarray
        ``rbar_v·c_v`` [s/m].
    J : float
        Paper eq. (3) at the estimate with the exact simulator [K²] (for free initial
        states: minimised over them), i.e. the grid's function.
    J_nlp : float
        The objective the solver saw (its discretisation; includes the initial-state
        penalty) [K²].
    method : str
        ``"multiple_shooting"`` or ``"single_shooting"``.
    discretisation : str
    status : str
        IPOPT's return status.
    success : bool
        IPOPT converged and J is finite. False = flagged: do not use without looking.
    iterations : int
        IPOPT iterations.
    n_sim : int
        Simulations run (single shooting, warm-start grid, identifiability).
    wall_time : float
        [s], whole fit (warm start and identifiability included).
    solve_time : float
        [s], the IPOPT call alone.
    active_bounds : list of str
        Bounds the estimate lies on; non-empty means the criterion, not the building,
        chose the value.
    x0 : ndarray, shape (n_states,)
        Initial state of the window (estimated for ``initial_state="estimate"``) [°C].
    theta0 : ndarray
        Starting point ``[rbar_v..., c_v]``.
    initial_state : str
    param_names : list of str
    identifiability : ProfileReport or None
    n_variables, n_constraints : int
        Size of the NLP.
    message : str
    """

    rbar_v: object
    c_v: float
    tau0: object
    J: float
    J_nlp: float
    method: str
    discretisation: str
    status: str
    success: bool
    iterations: int
    n_sim: int
    wall_time: float
    solve_time: float
    active_bounds: list
    x0: np.ndarray
    theta0: np.ndarray
    initial_state: str
    param_names: list
    identifiability: ProfileReport | None = None
    n_variables: int = 0
    n_constraints: int = 0
    message: str = ""
    eta: np.ndarray = field(default=None, repr=False)

    @property
    def theta(self) -> dict:
        """``{name: value}`` of the estimated parameters."""
        r = np.atleast_1d(self.rbar_v)
        return dict(zip(self.param_names, list(r) + [self.c_v]))

    @property
    def param_values(self) -> dict:
        """``{name: value}`` of the estimated parameters (:attr:`theta`)."""
        return self.theta

    def summary(self) -> str:
        th = ", ".join(f"{k} = {v:.4g}" for k, v in self.theta.items())
        s = (f"{self.method} ({self.discretisation}): {th}; J = {self.J:.6g} K²; "
             f"IPOPT {self.status} after {self.iterations} iterations; "
             f"{self.wall_time:.2f} s ({self.solve_time:.2f} s in IPOPT)")
        if not self.success:
            s += f"\nFAILED: {self.message}"
        if self.active_bounds:
            s += ("\nON A BOUND (the criterion, not the building, chose this value): "
                  + "; ".join(self.active_bounds))
        if self.identifiability is not None:
            s += "\n" + self.identifiability.text
        return s
