r"""Multiple shooting through the problem's simulator (the default NLP).

The window's ``K`` data steps are cut into shooting intervals of ``M`` steps (``M = 1``:
a node at every sample). Decision variables ``w = [eta, delta, S_1, …, S_{N-1}]``: the
scaled log-parameters, the free initial deviation (``initial_state="estimate"``) and the
state at every interior shooting node. Continuity constraints

.. math::

    S_{i+1} - \Psi_i(S_i, \eta) = 0, \qquad S_0 = x_{0,\mathrm{ref}} + P\delta,

where :math:`\Psi_i` runs the problem's simulator over the ``M`` steps of interval ``i``
— by default the exact zero-order-hold step of :mod:`.sim`, the grid's own simulator, so
the NLP's J at a solution *is* the grid's J: no discretisation bias, however stiff the
convection edges (with ``simulator="radau"`` it is the sparse Radau step of
:mod:`.radau`). Observations at a node are the node variable itself; those inside an
interval are simulated from its node. The constraint Jacobian is exact (state and parameter sensitivities, closed form); the
Hessian is the generalised Gauss–Newton one (residual Jacobians, no constraint
curvature), whose reduced Hessian equals the Gauss–Newton Hessian of single shooting:
IPOPT then converges like Gauss–Newton, fast for small residuals. The bound on ``tau0``
is the same linear constraint in log space as everywhere.

``M`` trades the KKT system's size (``n·K/M`` node variables, factorised by MUMPS)
against the sensitivities carried per interval (``n`` extra columns): short intervals
make the problem better conditioned (a bad parameter guess cannot blow a long
simulation up), long ones make it cheaper. The default is one hour.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..._blas import single_thread_blas
from ...errors import EstimationError
from .nlp import _RMS_SCALE, _ipopt_result, _ipopt_solver, _run_ipopt

__all__ = ["MultipleShootingNLP", "DEFAULT_INTERVAL"]

DEFAULT_INTERVAL = 3600.0
"""Default length of a shooting interval [s] (rounded to whole data steps)."""


class _Pattern:
    """A fixed sparsity from coordinate lists; values are summed into CCS order."""

    def __init__(self, n_rows, n_cols, rows, cols):
        rows = np.concatenate([np.zeros(0)] + list(rows)).astype(np.int64)
        cols = np.concatenate([np.zeros(0)] + list(cols)).astype(np.int64)
        lin = cols * n_rows + rows
        uniq, self.inv = np.unique(lin, return_inverse=True)
        self.nnz = len(uniq)
        r, c = uniq % n_rows, uniq // n_rows
        colind = np.searchsorted(c, np.arange(n_cols + 1))
        self.sparsity = ca.Sparsity(n_rows, n_cols, colind.tolist(), r.tolist())

    def values(self, parts):
        return np.bincount(self.inv, weights=np.concatenate(parts), minlength=self.nnz)


class _BufferCallback(ca.Callback):
    """A CasADi function computed in numpy, outputs written straight into CasADi's buffers
    (converting 10⁵ Jacobian nonzeros to a DM costs more than computing them)."""

    def __init__(self, name, sp_in, sp_out, fn, jacobian=None):
        ca.Callback.__init__(self)
        self.sp_in, self.sp_out, self.fn, self.jacobian = sp_in, sp_out, fn, jacobian
        self.construct(name, {})

    def get_n_in(self):
        return len(self.sp_in)

    def get_n_out(self):
        return len(self.sp_out)

    def get_sparsity_in(self, i):
        return self.sp_in[i]

    def get_sparsity_out(self, i):
        return self.sp_out[i]

    def has_eval_buffer(self):
        return True

    def eval_buffer(self, arg, res):
        ins = [np.frombuffer(a, dtype=np.float64).copy() if a is not None else None for a in arg]
        outs = []
        for r in res:
            v = None if r is None else np.frombuffer(r, dtype=np.float64)
            outs.append(v if v is not None and v.size else None)
        self.fn(ins, outs)
        return 0

    def has_jacobian(self):
        return self.jacobian is not None

    def get_jacobian(self, name, inames, onames, opts):
        self._jac = self.jacobian(name)
        return self._jac


class MultipleShootingNLP:
    """Multiple shooting with the problem's simulator between nodes (see the module docstring).

    Parameters
    ----------
    problem : CostProblem
    interval : float, optional
        Shooting interval [s], rounded to whole data steps (default 1 h; ``dt`` gives a
        node at every sample).
    ipopt_options : dict, optional
        Merged over :data:`~.nlp.IPOPT_DEFAULTS`.
    progress : callable, optional
        ``progress("ipopt", iteration, max_iter)``.

    Attributes
    ----------
    nlp : dict
        ``{"x", "f", "g"}`` (``f`` and the continuity part of ``g`` are callbacks).
    lbx, ubx, lbg, ubg : ndarray
    solver : casadi.Function
    M : int
        Data steps per shooting interval.
    nodes : ndarray of int
        Sample index (from the simulation start) of each interval start.
    n_variables, n_constraints : int
    discretisation : str
    """

    def __init__(self, problem, interval: float | None = None, ipopt_options=None, progress=None):
        self.problem = pb = problem
        self.sim = sim = pb.simulator
        n, ne, nf = sim.n, pb.n_eta, pb.n_free
        K = len(sim.inverse)
        M = int(round((DEFAULT_INTERVAL if interval is None else interval) / pb.dt))
        if M < 1:
            raise EstimationError(f"interval must be at least one data step ({pb.dt:g} s), "
                                  f"found {interval}")
        self.M = M = min(M, K)
        self.nodes = np.arange(0, K, M)
        NI = len(self.nodes)
        self.NI, self.K, self.n = NI, K, n
        ends = np.append(self.nodes[1:], K)
        self.n_nodes = NI - 1
        self.n_variables = ne + nf + n * self.n_nodes
        self.n_cont = n * self.n_nodes
        self.n_constraints = self.n_cont + pb.tau_matrix.shape[0]
        self.f_scale = pb.n_res * _RMS_SCALE ** 2
        # observations: at a node (variable) or inside an interval (simulated)
        self.node_obs = []       # (w index, y)
        self.interior = [dict() for _ in range(NI)]   # interval -> {sample: row in its list}
        self.interior_y = [[] for _ in range(NI)]     # per interval: list of (zone cols mask, y)
        node_of = {int(k): i for i, k in enumerate(self.nodes)}
        for r, k in enumerate(pb.obs_index):
            k = int(k)
            if k in node_of and node_of[k] >= 1:
                i = node_of[k]
                for cz, zi in enumerate(pb.zone_index):
                    if pb.mask[r, cz]:
                        self.node_obs.append((self._node_var(i) + zi, pb.Y_obs[r, cz]))
            else:
                i = int(np.searchsorted(self.nodes, k, side="left")) - 1
                self.interior[i][k] = len(self.interior_y[i])
                self.interior_y[i].append((pb.mask[r], np.where(pb.mask[r], pb.Y_obs[r], 0.0)))
        self.node_idx = np.array([a for a, _ in self.node_obs], dtype=int)
        self.node_y = np.array([b for _, b in self.node_obs])
        self._ends = ends
        self._build_patterns()
        self._key = None
        wsym = ca.MX.sym("w", self.n_variables)
        dense = ca.Sparsity.dense
        sp_w, sp_p = dense(self.n_variables, 1), dense(0, 1)
        self._cbs = {}

        def jac_f(name):
            return _BufferCallback(name, [sp_w, dense(1, 1)], [dense(1, self.n_variables)],
                                   lambda i, o: self._out(o, 0, self._eval(i[0])["grad"]))

        def jac_c(name):
            return _BufferCallback(name, [sp_w, dense(self.n_cont, 1)],
                                   [self.cont_pattern.sparsity],
                                   lambda i, o: self._out(o, 0, self._jac_values(i[0], False)))

        cb = self._cbs
        cb["f"] = _BufferCallback("J_ms", [sp_w], [dense(1, 1)],
                                  lambda i, o: self._out(o, 0, self._eval(i[0])["f"]), jac_f)
        cb["c"] = _BufferCallback("continuity", [sp_w], [dense(self.n_cont, 1)],
                                  lambda i, o: self._out(o, 0, self._eval(i[0])["res"]), jac_c)
        cb["grad_f"] = _BufferCallback(
            "grad_f", [sp_w, sp_p], [dense(1, 1), sp_w],
            lambda i, o: (self._out(o, 0, self._eval(i[0])["f"]),
                          self._out(o, 1, self._eval(i[0])["grad"])))
        cb["jac_g"] = _BufferCallback(
            "jac_g", [sp_w, sp_p], [dense(self.n_constraints, 1), self.jac_pattern.sparsity],
            lambda i, o: (self._out(o, 0, self._g(i[0])),
                          self._out(o, 1, self._jac_values(i[0], True))))
        cb["hess"] = _BufferCallback(
            "hess_ggn", [sp_w, sp_p, dense(1, 1), dense(self.n_constraints, 1)],
            [self.hess_pattern.sparsity],
            lambda i, o: self._out(o, 0, i[2][0] * self._hess_values(i[0])))
        g = ca.vertcat(cb["c"](wsym), ca.mtimes(ca.DM(pb.tau_matrix), wsym[:ne]))
        self.nlp = {"x": wsym, "f": cb["f"](wsym), "g": g}
        inf = np.inf
        self.lbx = np.concatenate([pb.eta_lb, np.full(nf + self.n_cont, -inf)])
        self.ubx = np.concatenate([pb.eta_ub, np.full(nf + self.n_cont, inf)])
        self.lbg = np.concatenate([np.zeros(self.n_cont), pb.tau_lb])
        self.ubg = np.concatenate([np.zeros(self.n_cont), pb.tau_ub])
        self.solver, self._cb = _ipopt_solver(
            "multiple_shooting", self.nlp, self.n_variables, self.n_constraints, ipopt_options,
            progress, grad_f=cb["grad_f"], jac_g=cb["jac_g"], hess_lag=cb["hess"])
        self.discretisation = (f"{sim.description}; {NI} shooting intervals of {M} steps, "
                               "Gauss–Newton Hessian")

    # ---- layout ------------------------------------------------------------------
    def _node_var(self, i):
        """w index of the first state of node ``i >= 1``."""
        pb = self.problem
        return pb.n_eta + pb.n_free + (i - 1) * self.n

    def _start_vars(self, i):
        """w indices the state at the start of interval ``i`` depends on (linearly)."""
        pb = self.problem
        if i == 0:
            return pb.n_eta + np.arange(pb.n_free)
        return self._node_var(i) + np.arange(self.n)

    def _build_patterns(self):
        pb = self.problem
        n, ne, NI = self.n, pb.n_eta, self.NI
        eta_idx = np.arange(ne)
        # Jacobian of the continuity rows (+ tau rows)
        rows, cols = [], []
        for i in range(NI - 1):
            r0 = i * n
            sv = self._start_vars(i)
            blk = np.arange(r0, r0 + n)
            rows += [blk, np.repeat(blk, ne), np.repeat(blk, len(sv))]
            cols += [self._node_var(i + 1) + np.arange(n), np.tile(eta_idx, n), np.tile(sv, n)]
        self.cont_pattern = _Pattern(self.n_cont, self.n_variables, rows, cols)
        tr, tc = np.nonzero(pb.tau_matrix)
        self._tau_vals = pb.tau_matrix[tr, tc]
        self.jac_pattern = _Pattern(self.n_constraints, self.n_variables,
                                    rows + [self.n_cont + tr], cols + [tc])
        # Gauss-Newton Hessian (upper triangle): dense [eta, start vars] block per interval
        # with interior observations, node observations on the diagonal, delta's weight
        rows, cols = [], []
        self._hblocks = []
        for i in range(NI):
            if not self.interior_y[i]:
                continue
            v = np.concatenate([eta_idx, self._start_vars(i)])
            R, C = np.meshgrid(v, v, indexing="ij")
            keep = R <= C
            rows.append(R[keep])
            cols.append(C[keep])
            self._hblocks.append((i, keep))
        diag = np.concatenate([eta_idx, self.node_idx, ne + np.arange(pb.n_free)])
        rows.append(diag)
        cols.append(diag)
        self.hess_pattern = _Pattern(self.n_variables, self.n_variables, rows, cols)

    # ---- evaluation ------------------------------------------------------------------
    @staticmethod
    def _out(outs, k, value):
        if outs[k] is not None:
            outs[k][:] = value

    def _eval(self, w):
        """Everything at ``w`` (cached): residuals, objective, gradient, blocks."""
        key = w.tobytes()
        if key == self._key:
            return self._cache
        pb, sim = self.problem, self.sim
        n, ne, nf = self.n, pb.n_eta, pb.n_free
        eta = w[:ne]
        if not np.all(np.isfinite(w)):
            raise EstimationError("non-finite iterate in the multiple-shooting NLP")
        with single_thread_blas():
            fac = sim.factors(eta, derivs=True)
            res = np.empty((self.NI - 1, n))
            d_eta = np.empty((self.NI - 1, n, ne))
            d_start = []
            grad = np.zeros(self.n_variables)
            f = 0.0
            blocks = []
            for i in range(self.NI):
                if i == 0:
                    x = pb.start_state(w[ne:ne + nf])
                    X = np.zeros((n, 1 + ne + nf))
                    X[pb.free_index, 1 + ne + np.arange(nf)] = 1.0
                else:
                    x = w[self._node_var(i):self._node_var(i) + n]
                    X = np.zeros((n, 1 + ne + n))
                    X[:, 1 + ne:] = np.eye(n)
                X[:, 0] = x
                rec = self.interior[i]
                out = np.empty((len(rec), len(pb.zone_index), X.shape[1]))
                X = sim.propagate(fac, X, int(self.nodes[i]), int(self._ends[i]), rec, out)
                if i < self.NI - 1:
                    nxt = w[self._node_var(i + 1):self._node_var(i + 1) + n]
                    res[i] = nxt - X[:, 0]
                    d_eta[i] = -X[:, 1:1 + ne]
                    d_start.append(-X[:, 1 + ne:])
                if rec:
                    m = np.array([mk for mk, _ in self.interior_y[i]])
                    y = np.array([yk for _, yk in self.interior_y[i]])
                    r = (out[:, :, 0] - y)[m]
                    Jr = out[:, :, 1:][m]                      # (rows, ne + start vars)
                    f += float(r @ r)
                    v = np.concatenate([np.arange(ne), self._start_vars(i)])
                    np.add.at(grad, v, 2.0 * Jr.T @ r)
                    blocks.append(2.0 * Jr.T @ Jr)
        rn = w[self.node_idx] - self.node_y
        f += float(rn @ rn)
        np.add.at(grad, self.node_idx, 2.0 * rn)
        delta = w[ne:ne + nf]
        f += pb.x0_weight * float(delta @ delta)
        grad[ne:ne + nf] += 2.0 * pb.x0_weight * delta
        if not np.isfinite(f):
            raise EstimationError(f"J is not finite at {dict(zip(pb.param_names, pb.theta(eta)))}")
        self._key = key
        self._cache = {"res": res.ravel(), "d_eta": d_eta, "d_start": d_start,
                       "f": f / self.f_scale, "J": f - pb.x0_weight * float(delta @ delta),
                       "grad": grad / self.f_scale, "blocks": blocks}
        return self._cache

    def _g(self, w):
        return np.concatenate([self._eval(w)["res"],
                               self.problem.tau_matrix @ w[:self.problem.n_eta]])

    def _jac_values(self, w, with_tau):
        ev = self._eval(w)
        parts = []
        for i in range(self.NI - 1):
            parts += [np.ones(self.n), ev["d_eta"][i].ravel(), ev["d_start"][i].ravel()]
        if with_tau:
            parts.append(self._tau_vals)
            return self.jac_pattern.values(parts)
        return self.cont_pattern.values(parts)

    def _hess_values(self, w):
        ev = self._eval(w)
        pb = self.problem
        parts = [B[keep] for B, (_, keep) in zip(ev["blocks"], self._hblocks)]
        parts.append(np.zeros(pb.n_eta))
        parts.append(np.full(len(self.node_idx), 2.0))
        parts.append(np.full(pb.n_free, 2.0 * pb.x0_weight))
        return self.hess_pattern.values(parts) / self.f_scale

    # ---- use -------------------------------------------------------------------
    def initial_guess(self, eta, delta=None) -> np.ndarray:
        """Decision vector at ``eta``: node states from the exact simulation."""
        pb = self.problem
        eta = np.asarray(eta, dtype=float)
        delta = np.zeros(pb.n_free) if delta is None else np.asarray(delta, dtype=float)
        x0 = pb.start_state(delta)
        X = self.sim.trajectory(eta, x0)
        return np.concatenate([eta, delta, X[self.nodes[1:]].ravel()])

    def unpack(self, w):
        """``(eta, delta, S)`` from a decision vector; ``S`` shape (n_nodes, n_states)."""
        pb = self.problem
        w = np.asarray(w, dtype=float).ravel()
        ne, nf = pb.n_eta, pb.n_free
        return w[:ne], w[ne:ne + nf], w[ne + nf:].reshape(self.n_nodes, self.n)

    def solve(self, w0, lbx=None, ubx=None) -> dict:
        """Run IPOPT from ``w0`` (keys as :meth:`~.nlp.CasadiMultipleShootingNLP.solve`)."""
        sol, st = _run_ipopt(self.solver, self._cb, w0, self.lbx if lbx is None else lbx,
                             self.ubx if ubx is None else ubx, self.lbg, self.ubg)
        w = np.asarray(sol["x"]).ravel()
        if not np.all(np.isfinite(w)):
            raise EstimationError("IPOPT returned non-finite decision variables "
                                  f"(status {st['return_status']})")
        eta, delta, _ = self.unpack(w)
        return _ipopt_result(sol, st, self.f_scale, w, eta, delta, J=self._eval(w)["J"],
                             lbg=self.lbg, ubg=self.ubg)
