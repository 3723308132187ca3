r"""Exact zero-order-hold simulation of the cost window, with parameter sensitivities.

The state matrix at a fixed supply flow is :math:`A_u = -C^{-1} K_u` with :math:`C`
the diagonal capacitance matrix and :math:`K_u` the symmetric conductance matrix
(supply air adds to its zone diagonal), so :math:`S = C^{1/2} A_u C^{-1/2}` is
symmetric. One eigendecomposition :math:`S = W \Lambda W^T` gives the exact step

.. math::

    x_{k+1} = V \big(e^{\Lambda\Delta} V^{-1} x_k + \varphi(\Lambda) V^{-1} b_k\big),
    \quad V = C^{-1/2} W,\; V^{-1} = W^T C^{1/2},\;
    \varphi(\lambda) = (e^{\lambda\Delta} - 1)/\lambda,

exact for inputs held over the step and unconditionally stable, however stiff the
convection edges are (their modes simply give :math:`e^{\lambda\Delta} = 0`). It is
cheaper than the matrix exponential of the ``2n`` Van Loan block and differentiates in
closed form (Daleckii–Krein): for a perturbation :math:`E` of :math:`A_u`,
:math:`\partial f(A_u)[E] = V\,(F \circ V^{-1} E V)\,V^{-1}` with :math:`F` the
divided differences of :math:`f` on the eigenvalues. The factorisation is cached per
distinct supply-flow vector, as the supply flow is the only input that changes
:math:`A_u`.

Heat inputs ``b_k`` (boundary temperatures through walls, supply air, gains) do not
depend on the convection parameters: convection edges join zones only.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ..._blas import single_thread_blas
from ...errors import EstimationError

__all__ = ["Simulator", "ExactSimulator", "CostEval"]

_CACHE_BYTES = 256 * 2**20   # pattern cache budget per simulation
_TAYLOR = 1e-3               # |lambda·dt| below which divided differences use a series


@dataclass
class CostEval:
    """J and what comes with it at one parameter point.

    Attributes
    ----------
    J : float
        The paper's cost [K²] (without the initial-state penalty).
    objective : float
        ``J + x0_weight·Σδ²`` [K²]: what the estimators minimise.
    x0 : ndarray, shape (n_states,)
        Initial state used [°C] (estimated if the problem frees it).
    residuals : ndarray, shape (K_T, n_cost_zones)
        ``T̂ − T`` [K], 0 where the measurement is missing.
    grad : ndarray, shape (n_eta,) or None
        Gradient of the objective in the scaled log-parameters [K²].
    hess : ndarray, shape (n_eta, n_eta) or None
        Gauss–Newton Hessian of the objective (initial states projected out) [K²].
    jac : ndarray, shape (n_res, n_eta) or None
        Jacobian of the residual vector (masked entries only) [K].
    """

    J: float
    objective: float
    x0: np.ndarray
    residuals: np.ndarray
    grad: np.ndarray | None = None
    hess: np.ndarray | None = None
    jac: np.ndarray | None = None


def _phi1(z):
    """``expm1(z)/z`` with its limit 1 at 0."""
    z = np.asarray(z, dtype=float)
    small = np.abs(z) < 1e-8
    zs = np.where(small, 1.0, z)
    return np.where(small, 1.0 + 0.5 * z, np.expm1(zs) / zs)


def _divided_differences(lam, dt):
    """Divided differences of ``exp(λ dt)`` and ``φ(λ) = (exp(λ dt) − 1)/λ`` on ``lam``.

    Both written so that nothing overflows (λ ≤ 0 up to round-off, but the fast modes
    have |λ dt| ~ 1e3) and nothing cancels catastrophically.
    """
    la, lb = lam[:, None], lam[None, :]
    hi, lo = np.maximum(la, lb), np.minimum(la, lb)
    F_exp = dt * np.exp(hi * dt) * _phi1(-(hi - lo) * dt)
    big = np.where(np.abs(la) >= np.abs(lb), la, lb)
    small = np.where(np.abs(la) >= np.abs(lb), lb, la)
    phi_small = dt * _phi1(small * dt)
    bigs = np.where(np.abs(big) * dt < _TAYLOR, 1.0, big)
    F_phi = (F_exp - phi_small) / bigs
    taylor = np.abs(big) * dt < _TAYLOR
    if taylor.any():
        a, b = la * dt, lb * dt
        ser = dt * (0.5 + (a + b) / 6 + (a * a + a * b + b * b) / 24
                    + (a ** 3 + a * a * b + a * b * b + b ** 3) / 120)
        F_phi = np.where(taylor, ser, F_phi)
    return F_exp, F_phi


class Simulator:
    """What every simulator of a :class:`~.problem.CostProblem` window shares.

    Subclasses provide :meth:`factors` (the per-parameter, per-flow-pattern pieces) and
    :meth:`propagate` (advance a state and its sensitivity columns); J, its gradient,
    the Gauss–Newton Hessian and the variable projection of free initial states are
    written once, here.

    Parameters
    ----------
    problem : CostProblem
    """

    description = ""

    def __init__(self, problem):
        self.problem = problem
        model = problem.model
        net = problem.network
        self.n = net.n_states
        self.dt = problem.dt
        U = problem.U_sim
        sl = net.input_slices()
        nz = net.n_zones
        p_ref = problem.p(np.zeros(problem.n_eta))
        _, Bt = model.matrices(p_ref)
        _, Bt_2 = model.matrices(2.0 * p_ref)
        # an air path to a boundary node (a measured neighbour outside a local problem)
        # puts its resistances into the input matrix: the forcing then depends on eta
        self.b_varies = bool(abs(Bt - Bt_2).max() > 0)
        self._UT = U[:, sl["T"]]
        b = np.zeros((len(U), self.n))
        a_sup = U[:, sl["ms"]] * model.sym.kz
        b[:, :nz] += a_sup * U[:, sl["Ts"]] + U[:, sl["Q"]] * model.sym.inv_cz
        if self.b_varies:
            self._b0 = b
            p_sym = ca.SX.sym("p", 2 * problem.m)
            B_sym = model.sym.AB(p_sym)[1]
            self._dB = ca.Function("dB", [p_sym], [ca.jacobian(ca.vec(B_sym), p_sym)])
            self.b = None
        else:
            self.b = b + np.asarray(Bt @ self._UT.T).T   # (N, n) constant term of each step [K/s]
        flows, inverse, counts = np.unique(U[:, sl["ms"]], axis=0, return_inverse=True,
                                           return_counts=True)
        self.inverse = inverse.ravel()
        self.counts = counts
        self.n_patterns = len(flows)
        self.supply = np.zeros((len(flows), self.n))
        self.supply[:, :nz] = flows * model.sym.kz   # supply conductance / C_z per pattern [1/s]
        # dA/dp (sparse, column-major vec of A) for the sensitivities
        p = ca.SX.sym("p", 2 * problem.m)
        A_sym, _ = model.sym.AB(p)
        self._dA = ca.Function("dA", [p], [ca.jacobian(ca.vec(A_sym), p)])
        self.n_sim = 0
        self._factors = None
        self.obs_steps = problem.obs_index
        self.zone_index = problem.zone_index

    def forcing(self, eta) -> np.ndarray:
        """The constant term of each step, shape (N, n) [K/s]."""
        if not self.b_varies:
            return self.b
        _, Bt = self.problem.model.matrices(self.problem.p(eta))
        return self._b0 + np.asarray(Bt @ self._UT.T).T

    def dforcing(self, eta) -> np.ndarray | None:
        """``d forcing / d eta_i``, shape (n_eta, N, n) [K/s], or None when constant."""
        if not self.b_varies:
            return None
        pb = self.problem
        nT = self._UT.shape[1]
        J = sp.csc_matrix(self._dB(pb.p(eta)).sparse())        # (n·nT, 2m)
        D = np.asarray(J @ pb.dp_deta(eta))                      # (n·nT, n_eta)
        return np.stack([self._UT @ D[:, i].reshape(self.n, nT, order="F").T
                         for i in range(pb.n_eta)])

    def _dA_sparse(self, eta):
        """``dA/deta_i`` as sparse CSR matrices (list of n_eta)."""
        pb = self.problem
        J = sp.csc_matrix(self._dA(pb.p(eta)).sparse())       # (n², 2m)
        D = sp.csc_matrix(J @ sp.csc_matrix(pb.dp_deta(eta)))  # (n², n_eta)
        out = []
        for i in range(pb.n_eta):
            col = D[:, i].tocoo()
            out.append(sp.csr_matrix((col.data, (col.row % self.n, col.row // self.n)),
                                     shape=(self.n, self.n)))
        return out

    def factors(self, eta, derivs: bool = False):
        """The per-flow-pattern pieces at ``eta`` (cached for the last ``eta``)."""
        key = (np.asarray(eta, dtype=float).tobytes(), derivs)
        if self._factors is None or self._factors[0] != key:
            self._factors = (key, self._make_factors(np.asarray(eta, dtype=float), derivs))
        return self._factors[1]

    def _make_factors(self, eta, derivs):
        raise NotImplementedError

    def propagate(self, fac, X, k0: int, k1: int, record=None, out=None):
        """Advance the columns of ``X`` from sample ``k0`` to ``k1`` (see subclasses)."""
        raise NotImplementedError

    def prepare(self, etas):
        """Per-point data for :meth:`cost_batch` (none for the generic loop)."""
        return None

    def cost_batch(self, etas, prepared=None, objective: bool = False):
        """J at each row of ``etas`` (a loop over :meth:`cost`); with ``objective`` also
        ``J + x0_weight·Σδ²``, what the NLPs minimise."""
        evs = [self.cost(e) for e in np.atleast_2d(np.asarray(etas, dtype=float))]
        J = np.array([ev.J for ev in evs])
        return (J, np.array([ev.objective for ev in evs])) if objective else J

    def trajectory(self, eta, x0=None) -> np.ndarray:
        """All states at every simulated sample, shape (n_steps + 1, n_states) [°C]."""
        pb = self.problem
        x = pb.x0_ref if x0 is None else np.asarray(x0, dtype=float)
        fac = self.factors(eta, False)
        X = np.empty((len(self.inverse) + 1, self.n))
        X[0] = x
        col = x[:, None].copy()
        with single_thread_blas():
            for k in range(len(self.inverse)):
                col = self.propagate(fac, col, k, k + 1)
                X[k + 1] = col[:, 0]
        return X

    def run(self, eta, x0, n_sens_eta: bool = False, sens_x0: bool = False):
        """Simulate at ``eta`` from ``x0`` and return the cost-zone outputs.

        Returns
        -------
        Yhat : ndarray, shape (K_T, n_cost_zones)
        dY_deta : ndarray, shape (K_T, n_cost_zones, n_eta) or None
        dY_dx0 : ndarray, shape (K_T, n_cost_zones, n_free) or None
        """
        pb = self.problem
        n = self.n
        fac = self.factors(eta, n_sens_eta)
        ne = fac.ne
        nf = pb.n_free if sens_x0 else 0
        X = np.zeros((n, 1 + ne + nf))
        X[:, 0] = x0
        if nf:
            X[pb.free_index, 1 + ne + np.arange(nf)] = 1.0
        out = np.empty((len(self.obs_steps), len(self.zone_index), X.shape[1]))
        record = {int(k): r for r, k in enumerate(self.obs_steps)}
        self.n_sim += 1
        with single_thread_blas():
            self.propagate(fac, X, 0, len(self.inverse), record, out)
        Yhat = out[:, :, 0]
        dY = out[:, :, 1:1 + ne] if ne else None
        dX0 = out[:, :, 1 + ne:] if nf else None
        return Yhat, dY, dX0

    def cost(self, eta, grad: bool = False) -> CostEval:
        """The objective at ``eta`` (scaled log-parameters), optionally with derivatives.

        For a problem with free initial states the initial state is the minimiser
        (variable projection): a linear least-squares problem for each ``eta``. The
        gradient then follows from the envelope theorem, and the Gauss–Newton Hessian
        is the Schur complement that projects out the initial-state directions.
        """
        with single_thread_blas():
            return self._cost(eta, grad)

    def _cost(self, eta, grad):
        pb = self.problem
        eta = np.asarray(eta, dtype=float)
        mask = pb.mask
        Y = np.where(mask, pb.Y_obs, 0.0)
        x0 = pb.x0_ref.copy()
        delta = np.zeros(0)
        H = None
        if pb.n_free:
            Yhat0, _, dX0 = self.run(eta, x0, sens_x0=True)
            H = dX0[mask]                                   # (n_res, n_free)
            e0 = (Yhat0 - Y)[mask]
            delta = _ridge_lstsq(H, -e0, pb.x0_weight)
            x0[pb.free_index] += delta
        if grad or not pb.n_free:
            Yhat, dY, _ = self.run(eta, x0, n_sens_eta=grad)
        else:   # the output is linear in the initial state: no second simulation
            Yhat = Yhat0.copy()
            Yhat[mask] += H @ delta
        r = np.where(mask, Yhat - Y, 0.0)
        with np.errstate(over="ignore"):    # an overflow is reported below, by name
            J = float(np.sum(r * r))
        obj = J + pb.x0_weight * float(delta @ delta)
        if not np.isfinite(J):
            raise EstimationError(f"J is not finite at {dict(zip(pb.param_names, pb.theta(eta)))}: "
                                  "the simulation blew up or the data contain inf")
        ev = CostEval(J, obj, x0, r)
        if grad:
            Jr = dY[mask]                                   # (n_res, n_eta)
            ev.jac = Jr
            ev.grad = 2.0 * Jr.T @ r[mask]
            Hgn = Jr.T @ Jr
            if H is not None and H.size:
                M = H.T @ H + pb.x0_weight * np.eye(H.shape[1])
                HJ = H.T @ Jr
                Hgn = Hgn - HJ.T @ np.linalg.lstsq(M, HJ, rcond=None)[0]
            ev.hess = 2.0 * 0.5 * (Hgn + Hgn.T)
        return ev

    # ---- many points, no derivatives ------------------------------------------

class ExactSimulator(Simulator):
    """Exact ZOH simulator of a :class:`~.problem.CostProblem` window.

    Parameters
    ----------
    problem : CostProblem

    Notes
    -----
    Use :meth:`cost` for one parameter point (optionally with the gradient and the
    Gauss–Newton Hessian) and :meth:`cost_batch` for many (the grid): it vectorises
    over the points. Linear algebra runs single-threaded (``threadpoolctl``): the
    matrices are small and BLAS threads only fight each other; parallelism belongs
    to the caller (:func:`~.grid.grid_search` runs chunks on a thread pool).
    Dense: O(n³) per flow pattern, so for hundreds of states with a supply flow that
    changes every step use :class:`~.radau.RadauSimulator`.
    """

    @property
    def description(self):
        return f"exact ZOH (eigendecomposition, {self.n_patterns} flow patterns)"

    # ---- per-parameter pieces ------------------------------------------------
    def _scaled(self, p):
        """``c = sqrt(C)`` and the symmetric ``S0 = C^{1/2} A C^{-1/2}`` at ``p``."""
        model = self.problem.model
        A = model.matrices(p)[0].toarray()
        cap = model.capacitances(p)
        c = np.sqrt(cap)
        S0 = (c[:, None] * A) / c[None, :]
        asym = np.abs(S0 - S0.T).max()
        if asym > 1e-9 * max(np.abs(S0).max(), 1e-300):
            raise EstimationError(f"internal: scaled state matrix not symmetric ({asym:.2e})")
        return c, 0.5 * (S0 + S0.T)

    def _dA_deta(self, eta):
        """``dA/deta_i`` as dense (n, n) matrices, shape (n_eta, n, n)."""
        pb = self.problem
        J = sp.csc_matrix(self._dA(pb.p(eta)).sparse())       # (n², 2m)
        D = np.asarray(J @ pb.dp_deta(eta))                    # (n², n_eta)
        return np.stack([D[:, i].reshape(self.n, self.n, order="F") for i in range(pb.n_eta)])

    def _make_factors(self, eta, derivs):
        return Factors(self, eta, derivs)

    def propagate(self, fac: "Factors", X, k0: int, k1: int, record=None, out=None):
        """Advance the columns of ``X`` from step ``k0`` to ``k1``.

        ``X[:, 0]`` is the state [°C]; with ``fac.ne`` parameter columns next (their
        sensitivities, Daleckii–Krein), the remaining columns are sensitivities to the
        initial state (they obey the homogeneous equation).

        Parameters
        ----------
        fac : Factors
        X : ndarray, shape (n, n_cols)
            Modified copy returned.
        k0, k1 : int
            Steps ``k0 .. k1-1`` are taken (state after step ``k`` is sample ``k + 1``).
        record : dict, optional
            ``{sample: row}``: store ``X[zone_index]`` at these samples in ``out[row]``.
        out : ndarray, shape (rows, n_cost_zones, n_cols), optional

        Returns
        -------
        ndarray
            ``X`` at sample ``k1``.
        """
        c, ne = fac.c, fac.ne
        for k in range(k0, k1):
            W, e, ph, Et, F = fac.get(self.inverse[k])
            Z = W.T @ (c[:, None] * X)
            bt = W.T @ (c * fac.b[k])
            new = e[:, None] * Z
            new[:, 0] += ph * bt
            if ne:
                G = F[0] * Z[:, 0][None, :] + F[1] * bt[None, :]
                new[:, 1:1 + ne] += np.einsum("pij,ij->ip", Et, G)
                if fac.db is not None:     # the forcing's own derivative, held like b
                    new[:, 1:1 + ne] += ph[:, None] * (W.T @ (c[:, None] * fac.db[:, k].T))
            X = (W @ new) / c[:, None]
            if record is not None and k + 1 in record:
                out[record[k + 1]] = X[self.zone_index]
        return X

    def prepare(self, etas):
        """The parameter-dependent matrices of each row of ``etas``, for :meth:`cost_batch`.

        Separate so that a thread pool can run :meth:`cost_batch` on chunks while the
        (not thread-safe) CasADi evaluations stay in the calling thread.
        """
        pb = self.problem
        etas = np.atleast_2d(np.asarray(etas, dtype=float))
        cs, S0s = zip(*(self._scaled(pb.p(eta)) for eta in etas))
        self.n_sim += len(etas)   # counted here: cost_batch may run on worker threads
        bs = np.stack([self.forcing(eta) for eta in etas], axis=1) if self.b_varies else None
        return np.stack(cs), np.stack(S0s), bs

    def cost_batch(self, etas, prepared=None, objective: bool = False):
        """J at each row of ``etas`` (shape (G, n_eta)), vectorised over the points.

        Parameters
        ----------
        etas : array_like, shape (G, n_eta)
        prepared : tuple, optional
            ``prepare(etas)``, if already computed.
        objective : bool
            Also return ``J + x0_weight·Σδ²``.

        Returns
        -------
        J : ndarray, shape (G,)
            [K²]; for free initial states at the ridge estimate of them.
        obj : ndarray, shape (G,)
            ``J + x0_weight·Σδ²`` [K²] (only with ``objective``): what the NLPs minimise,
            so what a grid must rank by to give them a start they cannot end above.
        """
        pb = self.problem
        # (G, n), (G, n, n), (N, G, n) or None
        c, S0, bs = self.prepare(etas) if prepared is None else prepared
        G, n, dt = c.shape[0], self.n, self.dt
        nf = pb.n_free
        X = np.broadcast_to(pb.x0_ref, (G, n)).copy()
        Sx = None
        if nf:
            Sx = np.zeros((G, n, nf))
            Sx[:, pb.free_index, np.arange(nf)] = 1.0
        K = len(self.obs_steps)
        nzc = len(self.zone_index)
        out = np.empty((G, K, nzc))
        outS = np.empty((G, K, nzc, nf)) if nf else None
        first = self.obs_steps[0]
        budget = _CACHE_BYTES // max(1, G * n * n * 8)
        cache = {}
        diag = np.arange(n)
        with single_thread_blas():
            for k in range(len(self.inverse)):
                j = self.inverse[k]
                item = cache.get(j)
                if item is None:
                    S = S0.copy()
                    S[:, diag, diag] -= self.supply[j]
                    lam, W = np.linalg.eigh(S)
                    item = (W, np.exp(lam * dt), dt * _phi1(lam * dt))
                    if self.counts[j] > 1 and len(cache) < budget:
                        cache[j] = item
                W, e, ph = item
                Wt = W.transpose(0, 2, 1)
                z = np.matmul(Wt, (c * X)[:, :, None])[:, :, 0]
                bk = self.b[k] if bs is None else bs[k]
                bt = np.matmul(Wt, (c * bk)[:, :, None])[:, :, 0]
                X = np.matmul(W, (e * z + ph * bt)[:, :, None])[:, :, 0] / c
                if nf:
                    Z = np.matmul(Wt, c[:, :, None] * Sx)
                    Sx = np.matmul(W, e[:, :, None] * Z) / c[:, :, None]
                if k + 1 >= first:
                    out[:, k + 1 - first] = X[:, self.zone_index]
                    if nf:
                        outS[:, k + 1 - first] = Sx[:, self.zone_index]
        mask = pb.mask
        Y = np.where(mask, pb.Y_obs, 0.0)
        J = np.empty(G)
        obj = np.empty(G)
        for g in range(G):
            e0 = (out[g] - Y)[mask]
            pen = 0.0
            if nf:
                H = outS[g][mask]
                d = _ridge_lstsq(H, -e0, pb.x0_weight)
                e0 = e0 + H @ d
                pen = pb.x0_weight * float(d @ d)
            with np.errstate(over="ignore", invalid="ignore"):   # checked by the caller
                J[g] = float(e0 @ e0)
            obj[g] = J[g] + pen
        return (J, obj) if objective else J

    def trajectory(self, eta, x0=None) -> np.ndarray:
        """All states at every simulated sample, shape (n_steps + 1, n_states) [°C]."""
        pb = self.problem
        x = pb.x0_ref if x0 is None else np.asarray(x0, dtype=float)
        c, S0 = self._scaled(pb.p(eta))
        b = self.forcing(eta)
        X = np.empty((len(self.inverse) + 1, self.n))
        X[0] = x
        cache = {}
        with single_thread_blas():
            for k in range(len(self.inverse)):
                j = self.inverse[k]
                if j not in cache:
                    lam, W = np.linalg.eigh(S0 - np.diag(self.supply[j]))
                    cache[j] = (W, np.exp(lam * self.dt), self.dt * _phi1(lam * self.dt))
                W, e, ph = cache[j]
                z = W.T @ (c * X[k])
                X[k + 1] = (W @ (e * z + ph * (W.T @ (c * b[k])))) / c
                if self.counts[j] == 1:
                    del cache[j]
        return X


def _ridge_lstsq(H, rhs, w):
    """``argmin ‖H d − rhs‖² + w‖d‖²`` (minimum norm when ``w = 0``)."""
    if H.shape[1] == 0:
        return np.zeros(0)
    if w > 0:
        k = H.shape[1]
        Ha = np.vstack([H, np.sqrt(w) * np.eye(k)])
        ra = np.concatenate([rhs, np.zeros(k)])
        return np.linalg.lstsq(Ha, ra, rcond=None)[0]
    return np.linalg.lstsq(H, rhs, rcond=1e-12)[0]


class Factors:
    """Eigendecompositions of the flow patterns' state matrices at one ``eta``.

    Attributes
    ----------
    c : ndarray, shape (n,)
        ``sqrt(C)`` [sqrt(J/K)].
    ne : int
        Number of parameter derivatives carried (0 or ``n_eta``).
    """

    def __init__(self, sim: ExactSimulator, eta, derivs: bool):
        self.sim = sim
        pb = sim.problem
        self.c, self.S0 = sim._scaled(pb.p(eta))
        self.ne = pb.n_eta if derivs else 0
        self.b = sim.forcing(eta)
        self.db = sim.dforcing(eta) if self.ne else None
        if self.ne:
            c = self.c
            self.Es = sim._dA_deta(eta) * (c[None, :, None] / c[None, None, :])  # C^½ E C^-½
        n = sim.n
        self.budget = _CACHE_BYTES // max(1, (3 + self.ne) * n * n * 8)
        self.cache = {}

    def get(self, j):
        """``(W, exp(λ dt), φ(λ), Ẽ, (F_exp, F_φ))`` of flow pattern ``j``."""
        item = self.cache.get(j)
        if item is not None:
            return item
        sim, dt = self.sim, self.sim.dt
        lam, W = np.linalg.eigh(self.S0 - np.diag(sim.supply[j]))
        e, ph = np.exp(lam * dt), dt * _phi1(lam * dt)
        Et = F = None
        if self.ne:
            Et = (W.T @ self.Es) @ W
            F = _divided_differences(lam, dt)
        item = (W, e, ph, Et, F)
        if len(self.cache) < self.budget:
            self.cache[j] = item
        return item
