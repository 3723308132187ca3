"""The paper's J summed over local problems: its simulation criterion at building scale.

The paper's J simulates the whole building open loop (eq. 3). With exact zero-order hold
that is one eigendecomposition of the full state matrix per supply-flow pattern and grid
point: at 49 zones (661 states) the 41 × 9 grid did not finish its first batch in 4
minutes. Each measured zone's local model (:func:`thermctl.local.local_problems`: the
zone, the unmeasured zones it reaches, their walls; measured neighbours as inputs) is a
:class:`~.problem.CostProblem` of 10-30 states, and the composite criterion

.. math:: J(\\theta) = \\sum_i J_i(\\theta)

counts every measured zone's simulation error once, each simulated with its neighbours'
measured temperatures (as the local likelihoods do; Varin, Reid & Firth, Statistica Sinica
2011, for composite criteria). :class:`CompositeCostProblem` offers what
:func:`~.grid.grid_search`, :class:`~.nlp.SingleShootingNLP`, :func:`~.fit.fit`
(``method="single_shooting"``) and the identifiability report use of a CostProblem, so
the grid, the IPOPT refinement and the profiles run on it unchanged.
"""

from __future__ import annotations

import numpy as np

from ...errors import EstimationError
from .sim import CostEval

__all__ = ["CompositeCostProblem"]

# parameter attributes the parts must share (one (rbar_v, c_v) for every local problem)
_SHARED = ("n_eta", "theta_ref", "theta_lb", "theta_ub", "eta_lb", "eta_ub", "tau_matrix",
           "tau_lb", "tau_ub", "rbar_bounds", "tau_bounds", "alpha", "param_names",
           "initial_state", "x0_weight")


class CompositeCostProblem:
    """Several :class:`~.problem.CostProblem` s over one shared ``(rbar_v, c_v)``.

    Parameters
    ----------
    problems : sequence of CostProblem
        Shared parameters (``per_edge=False``), the same bounds and ``alpha`` (pass the
        building's ``alpha`` to each), the same initial-state handling.
    names : sequence of str, optional
        A label per part for messages (the local problem's zone).

    Attributes
    ----------
    parts : list of CostProblem
    n_res : int
        Residuals over every part.
    simulator : CompositeSimulator
    """

    per_edge = False

    def __init__(self, problems, names=None):
        self.parts = list(problems)
        if not self.parts:
            raise EstimationError("a composite cost needs at least one problem (no local "
                                  "problem has a convection edge)")
        self.names = list(names) if names is not None else [str(i) for i in range(len(self.parts))]
        first = self.parts[0]
        for nm, pb in zip(self.names, self.parts):
            if pb.per_edge:
                raise EstimationError(f"composite cost: part {nm} has per-edge parameters; "
                                      "the parts share one (rbar_v, c_v)")
            for a in _SHARED:
                x, y = getattr(first, a), getattr(pb, a)
                same = (np.allclose(x, y, rtol=1e-12, atol=0) if isinstance(x, np.ndarray)
                        else x == y)
                if not same:
                    raise EstimationError(f"composite cost: part {nm} differs from part "
                                          f"{self.names[0]} in {a} ({y} vs {x}): build every "
                                          "part with the same bounds and alpha")
        for a in _SHARED:
            setattr(self, a, getattr(first, a))
        self.n_res = sum(pb.n_res for pb in self.parts)
        self.free_index = np.zeros(0, dtype=int)     # the parts hold their own initial states
        self.simulator = CompositeSimulator(self)
        self.eta_from_theta = first.eta_from_theta
        self.theta = first.theta
        self.feasible = first.feasible
        self.active_bounds = first.active_bounds
        self.project = first.project

    @property
    def zones(self) -> list:
        return [z for pb in self.parts for z in pb.zones]

    def describe(self) -> str:
        states = [pb.network.n_states for pb in self.parts]
        return (f"J summed over {len(self.parts)} local problems ({min(states)}-{max(states)} "
                f"states each), {self.parts[0].win.K_T} steps each; parameters "
                f"{self.param_names}, alpha = {self.alpha:.4g}")

    def cost(self, rbar_v, c_v) -> float:
        """The summed J [K²] at ``rbar_v`` [K/(W m)], ``c_v`` [J/K]."""
        return self.simulator.cost(self.eta_from_theta(rbar_v, c_v)).J


class CompositeSimulator:
    """Sums the parts' simulators: J, objective, gradient and Gauss–Newton Hessian add up;
    residuals and Jacobians stack."""

    def __init__(self, problem: CompositeCostProblem):
        self.problem = problem
        self.sims = [pb.simulator for pb in problem.parts]

    @property
    def n_sim(self) -> int:
        return sum(s.n_sim for s in self.sims)

    @property
    def description(self) -> str:
        return f"sum of {len(self.sims)} local {self.sims[0].description.split(' (')[0]}"

    def prepare(self, etas):
        return [s.prepare(etas) for s in self.sims]

    def cost_batch(self, etas, prepared=None, objective: bool = False):
        prepared = prepared or [None] * len(self.sims)
        J = np.zeros(len(etas))
        O = np.zeros(len(etas))
        for s, prep in zip(self.sims, prepared):
            j, o = s.cost_batch(etas, prep, objective=True)
            J += j
            O += o
        return (J, O) if objective else J

    def cost(self, eta, grad: bool = False) -> CostEval:
        evs = [s.cost(eta, grad=grad) for s in self.sims]
        out = CostEval(J=float(sum(e.J for e in evs)),
                       objective=float(sum(e.objective for e in evs)),
                       x0=np.concatenate([e.x0 for e in evs]),
                       residuals=np.concatenate([e.residuals.ravel() for e in evs]))
        if grad:
            out.grad = np.sum([e.grad for e in evs], axis=0)
            out.hess = np.sum([e.hess for e in evs], axis=0)
            if all(e.jac is not None for e in evs):
                out.jac = np.vstack([e.jac for e in evs])
        return out
