r"""Two more NLPs for J: a pure CasADi multiple-shooting NLP, and single shooting.

(The default multiple-shooting NLP, steps from the problem's simulator, is in
:mod:`.shooting`.)

**Pure CasADi multiple shooting** (:class:`CasadiMultipleShootingNLP`, method
``"casadi_radau"``). Decision variables: the scaled log-parameters ``eta`` (copied to
every sub-step with consensus constraints, which keeps the KKT matrix banded in time),
the free initial deviation ``delta`` (``initial_state="estimate"``) and the state after
every sub-step. Each data step of length ``dt`` is cut into ``s`` sub-steps of
``h = dt/s``, and consecutive states are tied by the implicit form of the model's own
L-stable Radau IIA step (:func:`thermctl._step.radau_residual`; its explicit form is
:meth:`thermctl.model.CasadiModel.F`), Padé (1,2) of the exponential:

.. math::

    \Big(I - \tfrac{2h}{3} A_u + \tfrac{h^2}{6} A_u^2\Big) x_{j+1}
    = \Big(I + \tfrac{h}{3} A_u\Big) x_j + h\Big(b_u - \tfrac{h}{6} A_u b_u\Big).

Written as equality constraints it needs no symbolic linear solve: the left side is
three sparse products with :math:`A_u(\eta, u)`, so the constraint Jacobian stays as
sparse as the network. L-stability matters: the convection edges have time constants of
seconds and ``h`` is a minute. The bound on ``tau0`` is the linear constraint
``log rbar_v + log c_v ∈ [log t_min/alpha, log t_max/alpha]``. The Hessian is CasADi's
exact one. Every piece is a symbolic CasADi expression (``nlp["x"]``, ``nlp["f"]``,
``nlp["g"]``): inspect it or hand it to another solver. It is the slowest of the three
(a node per sub-step) and carries the Radau step's small bias.

**Single shooting** (:class:`SingleShootingNLP`, the fast path). Decision variables:
``eta`` only. J, its exact gradient and a Gauss–Newton Hessian come from the problem's
simulator with closed-form sensitivities (:mod:`.sim`); free initial states are
eliminated by variable projection. IPOPT solves the same bounds and the same linear
constraint.
"""

from __future__ import annotations

import logging
import math

import casadi as ca
import numpy as np

from ..._step import radau_residual
from ...errors import EstimationError
from ...model import make_stepper

__all__ = ["CasadiMultipleShootingNLP", "SingleShootingNLP", "IPOPT_DEFAULTS", "radau_substeps"]

log = logging.getLogger(__name__)

IPOPT_DEFAULTS = {
    "print_level": 0,
    "sb": "yes",
    "tol": 1e-9,
    "acceptable_tol": 1e-6,
    "acceptable_iter": 10,
    "max_iter": 500,
}
"""IPOPT options used unless overridden (quiet; MUMPS is single-threaded, so deterministic)."""

_RMS_SCALE = 0.1   # [K]: the objective is J / (n_res · 0.1²), O(1) for a good fit


def default_substeps(dt: float) -> int:
    """Sub-steps per data step: one per minute (``ceil(dt / 60 s)``)."""
    return max(1, math.ceil(dt / 60.0))


def _ipopt_solver(name, nlp, n_variables, n_constraints, ipopt_options=None, progress=None,
                  **functions):
    """IPOPT on ``nlp`` with ``ipopt_options`` merged over :data:`IPOPT_DEFAULTS`.

    ``functions`` are further ``nlpsol`` options (``grad_f``, ``jac_g``, ``hess_lag``
    callbacks). Returns ``(solver, callback)``; ``callback`` reports ``progress`` once per
    iteration (None without ``progress``) and must stay referenced as long as ``solver``.
    """
    ipopt = {**IPOPT_DEFAULTS, **(ipopt_options or {})}
    opts = {"ipopt": ipopt, "print_time": False, **functions}
    cb = None
    if progress:
        cb = _IterationCallback(n_variables, n_constraints, progress, ipopt["max_iter"])
        opts["iteration_callback"] = cb
    return ca.nlpsol(name, "ipopt", nlp, opts), cb


def _run_ipopt(solver, cb, x0, lbx, ubx, lbg, ubg):
    """``(sol, stats)`` of one IPOPT run (the progress count restarts from 0)."""
    if cb is not None:
        cb.k = 0
    sol = solver(x0=x0, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
    return sol, solver.stats()


def _ipopt_result(sol, stats, f_scale, w, eta, delta, J=None, lbg=None, ubg=None) -> dict:
    """The dict every NLP's ``solve`` returns (keys: :meth:`CasadiMultipleShootingNLP.solve`).

    ``J`` defaults to the objective ``f`` [K²]; without ``lbg``/``ubg`` the constraint
    violation is reported as 0.
    """
    f = float(sol["f"]) * f_scale
    viol = 0.0
    if lbg is not None:
        g = np.asarray(sol["g"]).ravel()
        viol = float(np.max(np.maximum(lbg - g, g - ubg), initial=0.0))
    return {"w": w, "eta": eta, "delta": delta, "f": f, "J": f if J is None else J,
            "status": stats["return_status"], "success": bool(stats["success"]),
            "iterations": int(stats["iter_count"]), "max_violation": viol}


class _IterationCallback(ca.Callback):
    """Calls ``progress("ipopt", iteration, max_iter)`` once per IPOPT iteration."""

    def __init__(self, nx, ng, progress, max_iter):
        ca.Callback.__init__(self)
        self.nx, self.ng, self.progress, self.max_iter = nx, ng, progress, max_iter
        self.k = 0
        self.construct("iteration_callback", {})

    def get_n_in(self):
        return ca.nlpsol_n_out()

    def get_n_out(self):
        return 1

    def get_name_in(self, i):
        return ca.nlpsol_out(i)

    def get_name_out(self, i):
        return "ret"

    def get_sparsity_in(self, i):
        name = ca.nlpsol_out(i)
        n = {"x": self.nx, "lam_x": self.nx, "g": self.ng, "lam_g": self.ng, "f": 1}.get(name, 0)
        return ca.Sparsity.dense(n, 1)

    def eval(self, arg):
        self.k += 1
        self.progress("ipopt", self.k, self.max_iter)
        return [0]


def radau_substeps(problem, eta, x0, substeps: int) -> np.ndarray:
    """States after every Radau IIA sub-step, shape (n_steps·substeps, n_states) [°C].

    The same formula as the multiple-shooting constraints (used for its initial guess).
    """
    sim = problem.simulator
    model = problem.model
    p = problem.p(eta)
    mats = model.matrices(p)
    h = problem.dt / substeps
    U = problem.U_sim
    out = np.empty((len(U) * substeps, problem.network.n_states))
    steppers = {}
    b = sim.forcing(eta)
    x = np.asarray(x0, dtype=float)
    for k in range(len(U)):
        j = sim.inverse[k]
        if j not in steppers:
            A_u, _ = model.affine(U[k], mats=mats)
            steppers[j] = make_stepper(A_u, h, "radau", 1)
        for i in range(substeps):
            x = steppers[j](x, b[k])
            out[k * substeps + i] = x
    return out


class CasadiMultipleShootingNLP:
    """The multiple-shooting NLP of a :class:`~.problem.CostProblem` (public, inspectable).

    Parameters
    ----------
    problem : CostProblem
    substeps : int, optional
        Radau sub-steps per data step (default one per minute, ``ceil(dt/60)``).
    ipopt_options : dict, optional
        Merged over :data:`IPOPT_DEFAULTS`.
    progress : callable, optional
        ``progress("ipopt", iteration, max_iter)``.

    Attributes
    ----------
    nlp : dict
        ``{"x", "f", "g"}`` CasADi SX expressions: give it to any ``ca.nlpsol``.
    lbx, ubx, lbg, ubg : ndarray
        Bounds (``g`` = continuity residuals [K], then the tau constraints).
    solver : casadi.Function
        IPOPT on :attr:`nlp`.
    n_variables, n_constraints : int
    f_scale : float
        ``f = J_objective / f_scale`` [K²].
    discretisation : str

    Examples
    --------
    >>> ms = CasadiMultipleShootingNLP(problem)               # doctest: +SKIP
    >>> sol = ms.solve(ms.initial_guess(eta0))                 # doctest: +SKIP
    """

    def __init__(self, problem, substeps: int | None = None, ipopt_options=None, progress=None,
                 symbolic: str = "MX"):
        SYM = {"MX": ca.MX, "SX": ca.SX}[symbolic]
        self.problem = pb = problem
        s = default_substeps(pb.dt) if substeps is None else int(substeps)
        if s < 1:
            raise EstimationError(f"substeps must be >= 1, found {substeps}")
        self.substeps = s
        self.h = h = pb.dt / s
        net = pb.network
        n, ne, nf = net.n_states, pb.n_eta, pb.n_free
        n_steps = len(pb.U_sim)
        self.T = T = n_steps * s
        step = self._step_function(h)
        eta = SYM.sym("eta", ne)
        delta = SYM.sym("delta", nf)
        X = SYM.sym("X", n, T)
        # eta is copied to every sub-step (E[:, t]) with consensus constraints: each
        # continuity block then touches its own copy only, and the KKT matrix stays banded
        # in time instead of having dense parameter rows (a much cheaper factorisation)
        E = SYM.sym("E", ne, T - 1)
        Eall = ca.horzcat(eta, E)
        P = np.zeros((n, nf))
        P[pb.free_index, np.arange(nf)] = 1.0
        x_start = ca.DM(pb.x0_ref) + (ca.mtimes(ca.DM(P), delta) if nf else 0)
        Xprev = ca.horzcat(x_start, X[:, :T - 1])
        Umat = ca.DM(np.repeat(pb.U_sim, s, axis=0).T)
        res = step.map(T)(Xprev, X, Umat, Eall)
        g_cons = ca.vec(Eall[:, 1:] - Eall[:, :T - 1])
        g_tau = ca.mtimes(ca.DM(pb.tau_matrix), eta)
        cols = list(pb.obs_index * s - 1)
        Xo = X[list(pb.zone_index), cols]                                  # (n_zones, K_T)
        Y = np.where(pb.mask, pb.Y_obs, 0.0).T
        r = (Xo - ca.DM(Y)) * ca.DM(pb.mask.T.astype(float))
        J = ca.sumsqr(r)
        obj = J + (pb.x0_weight * ca.sumsqr(delta) if nf else 0)
        self.f_scale = pb.n_res * _RMS_SCALE ** 2
        w = ca.vertcat(eta, delta, ca.vec(X), ca.vec(E))
        self.nlp = {"x": w, "f": obj / self.f_scale, "g": ca.vertcat(ca.vec(res), g_cons, g_tau)}
        self.J_fun = ca.Function("J", [w], [J])
        self.n_variables = int(w.numel())
        self.n_constraints = int(self.nlp["g"].numel())
        inf = np.inf
        n_free_vars = nf + n * T + ne * (T - 1)
        self.lbx = np.concatenate([pb.eta_lb, np.full(n_free_vars, -inf)])
        self.ubx = np.concatenate([pb.eta_ub, np.full(n_free_vars, inf)])
        n_eq = n * T + ne * (T - 1)
        self.lbg = np.concatenate([np.zeros(n_eq), pb.tau_lb])
        self.ubg = np.concatenate([np.zeros(n_eq), pb.tau_ub])
        self.solver, self._cb = _ipopt_solver("multiple_shooting", self.nlp, self.n_variables,
                                              self.n_constraints, ipopt_options, progress)
        self.discretisation = f"Radau IIA implicit, {s} sub-steps of {h:g} s per data step"

    def _step_function(self, h):
        """``G(x, x_next, u, eta) -> residual`` of one implicit Radau IIA sub-step [K]."""
        pb = self.problem
        net = pb.network
        sym = pb.model.sym
        n, nz = net.n_states, net.n_zones
        x = ca.SX.sym("x", n)
        xn = ca.SX.sym("x_next", n)
        u = ca.SX.sym("u", net.n_inputs)
        eta = ca.SX.sym("eta", pb.n_eta)
        p = ca.mtimes(ca.DM(pb.p_map), ca.DM(pb.theta_ref) * ca.exp(eta))
        A, Bt = sym.AB(p)
        sl = net.input_slices()
        ms, Ts, Tb, Q = u[sl["ms"]], u[sl["Ts"]], u[sl["T"]], u[sl["Q"]]
        a_sup = ms * ca.DM(sym.kz)

        def Au(v):
            out = ca.mtimes(A, v)
            return ca.vertcat(out[:nz] - a_sup * v[:nz], out[nz:])

        b = ca.mtimes(Bt, Tb) + ca.vertcat(a_sup * Ts + Q * ca.DM(sym.inv_cz), ca.SX(n - nz, 1))
        res = radau_residual(Au, x, xn, b, h)
        return ca.Function("radau_residual", [x, xn, u, eta], [res],
                           ["x", "x_next", "u", "eta"], ["residual"])

    def initial_guess(self, eta, delta=None) -> np.ndarray:
        """Decision vector for ``eta`` (and initial deviation ``delta``): the simulated states."""
        pb = self.problem
        eta = np.asarray(eta, dtype=float)
        delta = np.zeros(pb.n_free) if delta is None else np.asarray(delta, dtype=float)
        x0 = pb.start_state(delta)
        Xs = radau_substeps(pb, eta, x0, self.substeps)
        # vec(X) is column-major, i.e. the rows of Xs one after the other
        return np.concatenate([eta, delta, Xs.ravel(), np.tile(eta, self.T - 1)])

    def unpack(self, w):
        """``(eta, delta, X)`` from a decision vector; ``X`` shape (T, n_states)."""
        pb = self.problem
        w = np.asarray(w, dtype=float).ravel()
        ne, nf, n = pb.n_eta, pb.n_free, pb.network.n_states
        return w[:ne], w[ne:ne + nf], w[ne + nf:ne + nf + n * self.T].reshape(self.T, n)

    def solve(self, w0, lbx=None, ubx=None) -> dict:
        """Run IPOPT from ``w0``.

        Returns
        -------
        dict
            ``w``, ``eta``, ``delta``, ``f`` (objective [K²]), ``J`` (the discretised J [K²]),
            ``status``, ``success``, ``iterations``, ``max_violation`` [K].
        """
        sol, st = _run_ipopt(self.solver, self._cb, w0, self.lbx if lbx is None else lbx,
                             self.ubx if ubx is None else ubx, self.lbg, self.ubg)
        w = np.asarray(sol["x"]).ravel()
        eta, delta, _ = self.unpack(w)
        return _ipopt_result(sol, st, self.f_scale, w, eta, delta, J=float(self.J_fun(w)),
                             lbg=self.lbg, ubg=self.ubg)


# ---------------------------------------------------------------------------- single shooting
class _Evaluator:
    """Caches the exact simulator's objective, gradient and GN Hessian per ``eta``."""

    def __init__(self, problem, f_scale):
        self.sim = problem.simulator
        self.f_scale = f_scale
        self._plain = {}
        self._full = {}

    def value(self, eta):
        key = eta.tobytes()
        if key in self._full:
            return self._full[key].objective / self.f_scale
        if key not in self._plain:
            if len(self._plain) > 32:
                self._plain.clear()
            self._plain[key] = self.sim.cost(eta).objective
        return self._plain[key] / self.f_scale

    def full(self, eta):
        key = eta.tobytes()
        if key not in self._full:
            if len(self._full) > 8:
                self._full.clear()
            self._full[key] = self.sim.cost(eta, grad=True)
        return self._full[key]


class _CB(ca.Callback):
    """Objective (with its Jacobian), (objective, gradient) or the GN Hessian of the Lagrangian."""

    def __init__(self, name, kind, ev, ne):
        ca.Callback.__init__(self)
        self.kind, self.ev, self.ne = kind, ev, ne
        self.construct(name, {})

    def get_n_in(self):
        return {"f": 1, "jac": 2, "grad": 2, "hess": 4}[self.kind]

    def get_n_out(self):
        return 2 if self.kind == "grad" else 1

    def get_sparsity_in(self, i):
        if i == 0:
            return ca.Sparsity.dense(self.ne, 1)
        if self.kind == "grad" and i == 1:
            return ca.Sparsity.dense(0, 1)         # p
        if self.kind == "hess" and i == 1:
            return ca.Sparsity.dense(0, 1)
        if self.kind == "hess" and i == 3:
            return ca.Sparsity.dense(self.ev.ng, 1)
        return ca.Sparsity.dense(1, 1)

    def get_sparsity_out(self, i):
        if self.kind == "hess":
            return ca.Sparsity.upper(self.ne)
        if self.kind == "jac":
            return ca.Sparsity.dense(1, self.ne)
        if self.kind == "grad" and i == 1:
            return ca.Sparsity.dense(self.ne, 1)
        return ca.Sparsity.dense(1, 1)

    def eval(self, arg):
        eta = np.asarray(arg[0], dtype=float).ravel()
        ev = self.ev
        if self.kind == "f":
            return [ev.value(eta)]
        full = ev.full(eta)
        if self.kind == "jac":
            return [ca.DM(full.grad[None, :] / ev.f_scale)]
        if self.kind == "grad":
            return [full.objective / ev.f_scale, ca.DM(full.grad / ev.f_scale)]
        H = float(arg[2]) * full.hess / ev.f_scale
        return [ca.triu(ca.DM(H))]

    def has_jacobian(self):
        return self.kind == "f"

    def get_jacobian(self, name, inames, onames, opts):
        self._jac = _CB(name, "jac", self.ev, self.ne)
        return self._jac


class SingleShootingNLP:
    """Single shooting over the log-parameters with the exact ZOH simulator (the fast path).

    Parameters
    ----------
    problem : CostProblem
    ipopt_options : dict, optional
        Merged over :data:`IPOPT_DEFAULTS`.
    progress : callable, optional
        ``progress("ipopt", iteration, max_iter)``.

    Attributes
    ----------
    solver : casadi.Function
        IPOPT with callbacks for J, its exact gradient and a Gauss–Newton Hessian.
    discretisation : str
    """

    def __init__(self, problem, ipopt_options=None, progress=None):
        self.problem = pb = problem
        ne = pb.n_eta
        self.f_scale = pb.n_res * _RMS_SCALE ** 2
        self.ev = ev = _Evaluator(pb, self.f_scale)
        ev.ng = pb.tau_matrix.shape[0]
        self._cbs = [_CB("J", "f", ev, ne), _CB("grad_J", "grad", ev, ne),
                     _CB("hess_J", "hess", ev, ne)]
        x = ca.MX.sym("eta", ne)
        self.nlp = {"x": x, "f": self._cbs[0](x), "g": ca.mtimes(ca.DM(pb.tau_matrix), x)}
        self.solver, self._cb = _ipopt_solver("single_shooting", self.nlp, ne, ev.ng,
                                              ipopt_options, progress,
                                              grad_f=self._cbs[1], hess_lag=self._cbs[2])
        self.n_variables = ne
        self.n_constraints = ev.ng
        self.discretisation = pb.simulator.description

    def solve(self, eta0, lbx=None, ubx=None) -> dict:
        """Run IPOPT from ``eta0`` (see :meth:`CasadiMultipleShootingNLP.solve` for the keys)."""
        pb = self.problem
        eta0 = np.asarray(eta0, dtype=float)
        sol, st = _run_ipopt(self.solver, self._cb, eta0, pb.eta_lb if lbx is None else lbx,
                             pb.eta_ub if ubx is None else ubx, pb.tau_lb, pb.tau_ub)
        eta = np.asarray(sol["x"]).ravel()
        return _ipopt_result(sol, st, self.f_scale, eta, eta, None)
