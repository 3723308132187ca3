r"""Bilinear thermal dynamics of a network: CasADi model, simulation, linearization.

For every state node :math:`i` with capacitance :math:`C_i`,

.. math::

    C_i \dot T_i = \sum_{j \sim i} g_{ij} (T_j - T_i)
                   + [i \text{ zone}]\,\big(\dot m_{s,i} c_p (T_{s,i} - T_i) + Q_i\big),

where the sum runs over the resistive links of the 3R2C chains (:math:`g = 1/R`),
:math:`T_j` may be a boundary temperature (an input), and the supply term makes
the model bilinear. Convection edges have :math:`R_1=R_2=R_3=\bar R_v d` and
:math:`C_1=C_2=C_v`.

The parameter vector of the CasADi functions is per convection edge:
``p = [rbar_v[e] for e in convection edges] + [c_v[e] for e ...]`` (length ``2m``);
:meth:`ThermalModel.expand` maps the paper's shared ``(rbar_v, c_v)`` onto it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import casadi as ca
import networkx as nx
import control as ct
import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ._blas import single_thread_blas
from ._step import radau_casadi_step, radau_stepper
from .errors import ModelError
from .network import ThermalNetwork

__all__ = ["ThermalModel", "ConvectionParameters", "CasadiModel", "OperatingPoint", "zoh", "make_stepper",
           "simulation_method", "SIMULATE_EXACT_STATES", "RBAR_V_PAPER", "C_V_PAPER"]

RBAR_V_PAPER = 3.36e-4
"""Convection resistance per unit distance identified by Goyal et al. [K/(W m)]."""
C_V_PAPER = 1.19e3
"""Convection capacitance identified by Goyal et al. [J/K]."""


SIMULATE_EXACT_STATES = 150
"""Largest model :meth:`ThermalModel.simulate` steps by matrix exponentials with
``method="auto"``; Radau steps (sparse LU) above. Closed-loop supply flows change every step,
and each new flow vector costs one dense exponential: a 49-zone model (659 states) took
about 50 s for 48 h exact and 5 s by Radau, the two within 1e-4 K."""


def simulation_method(n_states: int, method: str = "auto") -> str:
    """The simulator ``method`` stands for: ``auto`` resolved by the state count, any other
    checked and returned as it is.

    Examples
    --------
    >>> simulation_method(659), simulation_method(60), simulation_method(659, "exact")
    ('radau', 'exact', 'exact')
    """
    if method not in ("auto", "exact", "radau", "cvodes"):
        raise ModelError(f"method must be 'auto', 'exact', 'radau' or 'cvodes', found {method!r}")
    if method == "auto":
        return "exact" if n_states <= SIMULATE_EXACT_STATES else "radau"
    return method


def zoh(A, dt: float, B=None):
    r"""Exact zero-order-hold discretisation of :math:`\dot x = A x + b`.

    Uses Van Loan's block exponential
    :math:`\exp\left(\begin{bmatrix}A & I\\0 & 0\end{bmatrix} dt\right)
    = \begin{bmatrix}\Phi & \Gamma\\0 & I\end{bmatrix}`, so that
    :math:`x_{k+1} = \Phi x_k + \Gamma b_k` for any constant :math:`b_k`, also
    when :math:`A` is singular.

    Parameters
    ----------
    A : array_like, shape (n, n)
        State matrix [1/s].
    dt : float
        Step [s].
    B : array_like, shape (n, m), optional
        Input matrix: then ``Γ B`` is returned instead of ``Γ``, from the block exponential
        with ``B`` in place of ``I``, an (n + m)-square matrix instead of 2n (the cube of it
        is what costs: a 49-zone building's state-space export, 659 states and 148 inputs,
        takes a quarter of the time).

    Returns
    -------
    Phi, Gamma : ndarray, shape (n, n)
        ``Gamma`` is ``Γ B``, shape (n, m), when ``B`` is given.
    """
    A = A.toarray() if sp.issparse(A) else np.asarray(A, dtype=float)
    n = A.shape[0]
    if B is not None:
        B = B.toarray() if sp.issparse(B) else np.asarray(B, dtype=float)
        if B.shape[1] >= n:             # the 2n form is the smaller one
            Phi, Gamma = zoh(A, dt)
            return Phi, Gamma @ B
    m = n if B is None else B.shape[1]
    M = np.zeros((n + m, n + m))
    M[:n, :n] = A * dt
    M[:n, n:] = (np.eye(n) if B is None else B) * dt
    with single_thread_blas():
        E = sla.expm(M)
    return E[:n, :n], E[:n, n:]


@dataclass
class CasadiModel:
    """The symbolic model handed to optimisation code.

    Attributes
    ----------
    f : casadi.Function
        ``f(x, u, p) -> xdot`` [K/s].
    F : casadi.Function
        ``F(x, u, p, dt) -> x_next``: one ZOH step with an L-stable 3rd-order
        (Radau IIA) rational approximation of the exponential over ``substeps``
        sub-steps — suitable for the stiff convection edges.
    x, u, p : casadi.SX
        The symbols ``f`` was built from.
    state_names, input_names, param_names : list of str
    p_value : ndarray
        The model's current parameter vector.
    substeps : int
    """

    f: ca.Function
    F: ca.Function
    x: ca.SX
    u: ca.SX
    p: ca.SX
    state_names: list
    input_names: list
    param_names: list
    p_value: np.ndarray
    substeps: int


def _triplet(terms: dict, n: int, m: int) -> ca.SX:
    """Sparse SX matrix from ``{(row, col): [terms to add]}``."""
    if not terms:
        return ca.SX(n, m)
    keys = sorted(terms, key=lambda rc: (rc[1], rc[0]))
    rows = [r for r, _ in keys]
    cols = [c for _, c in keys]
    vals = ca.vertcat(*[sum(terms[k][1:], terms[k][0]) for k in keys])
    return ca.SX.triplet(rows, cols, vals, n, m)


@dataclass(frozen=True)
class ConvectionParameters:
    """The convection parameters of a network's air paths, per edge, with their names.

    The one place parameter names are spelled (``rbar_v[air:a-b]``, ``c_v[air:a-b]``,
    ``tau0[air:a-b]``) and the one conversion between ``(R̄_v, C_v)`` and ``(R̄_v, τ0)``
    with ``τ0 = R̄_v·C_v`` [s/m] (the edge's time constant per metre of air path).

    Attributes
    ----------
    edges : tuple of str
        Air-path names (:func:`thermctl.network.air_path_name`), in the network's order.
    rbar_v : ndarray, shape (m,)
        Convection resistance per unit distance [K/(W m)].
    c_v : ndarray, shape (m,)
        Convection capacitance [J/K].

    Examples
    --------
    >>> cp = ConvectionParameters.from_model(model)            # doctest: +SKIP
    >>> cp.as_dict()["rbar_v[air:r1-r2]"]                      # doctest: +SKIP
    """

    edges: tuple
    rbar_v: np.ndarray
    c_v: np.ndarray

    @staticmethod
    def key(edge: str, kind: str = "rbar_v") -> str:
        """Parameter name of ``kind`` (``rbar_v``, ``c_v`` or ``tau0``) of air path ``edge``."""
        return f"{kind}[{edge}]"

    @staticmethod
    def edge_of(key: str) -> str | None:
        """The air-path name in a parameter name (``None`` for a shared parameter)."""
        return key[key.index("[") + 1:-1] if "[" in key and key.endswith("]") else None

    @staticmethod
    def kind_of(key: str) -> str:
        """The kind a parameter name spells (``rbar_v`` for ``rbar_v`` and ``rbar_v[air:a-b]``;
        the stem of any other name, e.g. ``sigma_q``)."""
        return key.split("[", 1)[0]

    @classmethod
    def is_rbar(cls, key: str, per_edge: bool | None = None) -> bool:
        """Whether ``key`` names an R̄_v: shared or per edge (``per_edge=None``), only per
        edge (``True``) or only the shared one (``False``)."""
        if cls.kind_of(key) != "rbar_v":
            return False
        return per_edge is None or (cls.edge_of(key) is not None) == per_edge

    @classmethod
    def from_tau0(cls, edges, rbar_v, tau0) -> "ConvectionParameters":
        """From ``R̄_v`` [K/(W m)] and ``τ0`` [s/m] (scalars or one per edge)."""
        m = len(edges)
        rb = np.broadcast_to(np.asarray(rbar_v, float), (m,)).copy()
        return cls(tuple(edges), rb, np.broadcast_to(np.asarray(tau0, float), (m,)) / rb)

    @classmethod
    def from_model(cls, model: "ThermalModel") -> "ConvectionParameters":
        """The per-edge values of ``model`` (shared values repeated)."""
        conv = model.network.convection_edges
        p = model.p
        m = len(conv)
        return cls(tuple(e.name for e in conv), p[:m].copy(), p[m:].copy())

    @property
    def tau0(self) -> np.ndarray:
        """``R̄_v·C_v`` per edge [s/m]."""
        return self.rbar_v * self.c_v

    @property
    def names(self) -> list:
        """Parameter names in the model's vector order: every ``rbar_v`` then every ``c_v``."""
        return ([self.key(e) for e in self.edges] + [self.key(e, "c_v") for e in self.edges])

    def as_dict(self, kinds=("rbar_v",)) -> dict:
        """``{name: value}`` of the given kinds (``rbar_v``, ``c_v``, ``tau0``)."""
        vals = {"rbar_v": self.rbar_v, "c_v": self.c_v, "tau0": self.tau0}
        return {self.key(e, k): float(vals[k][i]) for k in kinds
                for i, e in enumerate(self.edges)}

    def to_model(self, network: ThermalNetwork, meta: dict | None = None) -> "ThermalModel":
        """A :class:`ThermalModel` of ``network`` with these values (edges matched by
        name)."""
        order = [self.edges.index(e.name) for e in network.convection_edges]
        return ThermalModel(network, rbar_v=self.rbar_v[order], c_v=self.c_v[order], meta=meta)


class _Symbolic:
    """CasADi expressions of a network, built once per network."""

    def __init__(self, net: ThermalNetwork):
        self.net = net
        nx, nu = net.n_states, net.n_inputs
        conv = net.convection_edges
        m = len(conv)
        d = np.array([e.d for e in conv], dtype=float)
        ends, R, ce = net.links()
        cap_fixed = net.fixed_capacitances()
        cse = net.conv_state_edge()
        x = ca.SX.sym("x", nx)
        u = ca.SX.sym("u", nu)
        p = ca.SX.sym("p", 2 * m)
        rbar, cv = p[:m], p[m:]
        cap = [cap_fixed[i] if cse[i] < 0 else cv[int(cse[i])] for i in range(nx)]
        nb = len(net.boundary)
        sl = net.input_slices()
        # Collect the entries first and build the sparse matrices from triplets: element
        # assignment into an SX matrix is O(nnz) each, far too slow for 1000+ states.
        a_terms, b_terms = {}, {}
        for (i, j), r, k in zip(ends, R, ce):
            g = 1.0 / r if k < 0 else 1.0 / (rbar[int(k)] * d[int(k)])
            for s, t in ((i, j), (j, i)):
                if s >= nx:
                    continue  # boundary nodes have no equation
                a_terms.setdefault((s, s), []).append(-g / cap[s])
                if t < nx:
                    a_terms.setdefault((s, t), []).append(g / cap[s])
                else:
                    b_terms.setdefault((s, t - nx), []).append(g / cap[s])
        A = _triplet(a_terms, nx, nx)
        Bt = _triplet(b_terms, nx, nb)
        nz = net.n_zones
        Cz = cap_fixed[:nz]
        cp = net.spec.cp
        self.kz = cp / Cz  # supply term per unit mass flow: ms·kz·(Ts − T) [K/s per kg/s·K]
        self.inv_cz = 1.0 / Cz
        ms, Ts, Tb, Q = u[sl["ms"]], u[sl["Ts"]], u[sl["T"]], u[sl["Q"]]
        zone_rows = ms * self.kz * (Ts - x[:nz]) + Q * self.inv_cz
        xdot = ca.mtimes(A, x) + ca.mtimes(Bt, Tb) + ca.vertcat(zone_rows, ca.SX(nx - nz, 1))
        self.x, self.u, self.p = x, u, p
        self.f = ca.Function("f", [x, u, p], [xdot], ["x", "u", "p"], ["xdot"])
        self.jacobians = ca.Function("jacobians", [x, u, p],
                                     [ca.jacobian(xdot, x), ca.jacobian(xdot, u)],
                                     ["x", "u", "p"], ["dfdx", "dfdu"])
        self.AB = ca.Function("AB", [p], [A, Bt], ["p"], ["A", "Bt"])
        cap_all = ca.vertcat(*cap)
        self.cap = ca.Function("cap", [p], [cap_all], ["p"], ["cap"])
        self.param_names = ConvectionParameters(tuple(e.name for e in conv), np.zeros(m),
                                                np.zeros(m)).names
        self._F = {}

    def step(self, substeps: int) -> ca.Function:
        """``F(x, u, p, dt)``: ZOH step by the Radau IIA (Padé 1/2) rational of the exponential."""
        if substeps in self._F:
            return self._F[substeps]
        net = self.net
        nx, nz = net.n_states, net.n_zones
        x = ca.MX.sym("x", nx)
        u = ca.MX.sym("u", net.n_inputs)
        p = ca.MX.sym("p", self.p.numel())
        dt = ca.MX.sym("dt")
        A, Bt = self.AB(p)
        sl = net.input_slices()
        ms, Ts, Tb, Q = u[sl["ms"]], u[sl["Ts"]], u[sl["T"]], u[sl["Q"]]
        sel = np.zeros((nx, nz))
        sel[np.arange(nz), np.arange(nz)] = 1.0
        sel = ca.DM(sp.csc_matrix(sel))
        a_sup = ms * self.kz
        A_u = A - ca.mtimes(sel, ca.mtimes(ca.diag(a_sup), sel.T))
        b_u = ca.mtimes(Bt, Tb) + ca.mtimes(sel, a_sup * Ts + Q * self.inv_cz)
        xk = radau_casadi_step(A_u, b_u, x, dt / substeps, substeps)
        F = ca.Function(f"F{substeps}", [x, u, p, dt], [xk], ["x", "u", "p", "dt"], ["x_next"])
        self._F[substeps] = F
        return F


class ThermalModel:
    """A thermal network with parameter values: simulate, linearize, export.

    Parameters
    ----------
    network : ThermalNetwork
    rbar_v : float or array_like
        Convection resistance per unit distance [K/(W m)]; one value shared by all
        convection edges (the paper) or one per edge.
    c_v : float or array_like
        Convection capacitance [J/K]; shared or per edge.
    meta : dict, optional
        Provenance carried into ``model.json`` (scores, data range, metrics...).

    Examples
    --------
    >>> model = ThermalModel(net, rbar_v=3.36e-4, c_v=1.19e3)   # doctest: +SKIP
    >>> sys = model.to_statespace(model.operating_point(ms=0.1, Ts=14, T=5))  # doctest: +SKIP
    """

    def __init__(self, network: ThermalNetwork, rbar_v=RBAR_V_PAPER, c_v=C_V_PAPER,
                 meta: dict | None = None):
        self.network = network
        self.rbar_v = rbar_v
        self.c_v = c_v
        self.meta = {} if meta is None else meta
        self._sym = None

    # ---- parameters --------------------------------------------------------
    def expand(self, rbar_v, c_v) -> np.ndarray:
        """Per-edge parameter vector ``p`` (length ``2m``) from shared or per-edge values."""
        m = len(self.network.convection_edges)
        out = []
        for name, v, unit in (("rbar_v", rbar_v, "[K/(W m)]"), ("c_v", c_v, "[J/K]")):
            v = np.broadcast_to(np.asarray(v, dtype=float), (m,)) if np.ndim(v) == 0 \
                else np.asarray(v, dtype=float)
            if v.shape != (m,):
                raise ModelError(f"{name}: expected a scalar or {m} values (one per convection "
                                 f"edge), found shape {v.shape}")
            if m and (not np.all(np.isfinite(v)) or np.any(v <= 0)):
                raise ModelError(f"{name} must be finite and > 0 {unit}, found {v.tolist()}")
            out.append(v)
        return np.concatenate(out)

    @property
    def p(self) -> np.ndarray:
        return self.expand(self.rbar_v, self.c_v)

    def _p(self, p) -> np.ndarray:
        """The model's parameter vector, or ``p`` checked: shape (2m,), finite, > 0."""
        if p is None:
            return self.p
        p = np.asarray(p, dtype=float)
        names = self.sym.param_names
        if p.shape != (len(names),):
            raise ModelError(f"p: expected {len(names)} values {names}, found shape {p.shape}")
        if not np.all(np.isfinite(p)) or np.any(p <= 0):
            raise ModelError(f"p: every parameter must be finite and > 0, found {p.tolist()} "
                             f"for {names}")
        return p

    @property
    def sym(self) -> _Symbolic:
        if self._sym is None:
            self._sym = _Symbolic(self.network)
        return self._sym

    # ---- numeric matrices --------------------------------------------------
    def matrices(self, p=None):
        """Linear part of the dynamics at parameters ``p``.

        Returns
        -------
        A : scipy.sparse.csc_matrix, shape (n_states, n_states)
            State matrix without the supply term [1/s].
        Bt : scipy.sparse.csc_matrix, shape (n_states, n_boundary)
            Boundary-temperature input matrix [1/s].
        """
        A, Bt = self.sym.AB(self._p(p))
        return sp.csc_matrix(A.sparse()), sp.csc_matrix(Bt.sparse())

    def affine(self, u, p=None, mats=None):
        """State matrix and constant term for a constant input ``u``: ``xdot = A_u x + b_u``."""
        A, Bt = self.matrices(p) if mats is None else mats
        net = self.network
        sl = net.input_slices()
        nz = net.n_zones
        u = np.asarray(u, dtype=float)
        a_sup = u[sl["ms"]] * self.sym.kz
        diag = np.zeros(net.n_states)
        diag[:nz] = a_sup
        A_u = A - sp.diags(diag)
        b_u = Bt @ u[sl["T"]]
        b_u[:nz] += a_sup * u[sl["Ts"]] + u[sl["Q"]] * self.sym.inv_cz
        return sp.csc_matrix(A_u), b_u

    def capacitances(self, p=None) -> np.ndarray:
        """Capacitance of every state [J/K]."""
        return np.asarray(self.sym.cap(self._p(p))).ravel()

    # ---- simulation --------------------------------------------------------
    def simulate(self, U, dt: float, x0, p=None, method: str = "auto", substeps: int | None = None):
        """Simulate with inputs held constant over each step (zero-order hold).

        Parameters
        ----------
        U : array_like, shape (N, n_inputs)
            Input of each interval, in :attr:`ThermalNetwork.input_names` order.
        dt : float
            Step [s].
        x0 : array_like, shape (n_states,)
            Initial state [°C].
        p : array_like, optional
            Per-edge parameter vector (default: the model's).
        method : {"auto", "exact", "radau", "cvodes"}
            ``exact``: matrix exponential, cached per distinct supply-flow vector
            (exact for ZOH inputs, insensitive to stiffness). ``radau``: L-stable
            3rd-order rational step with ``substeps`` sub-steps (sparse for large
            networks). ``cvodes``: CasADi's BDF integrator (an independent reference).
            ``auto``: ``exact`` up to :data:`SIMULATE_EXACT_STATES` states, ``radau`` above
            (:func:`simulation_method`).
        substeps : int, optional
            For ``radau``: default ``ceil(dt / 60 s)``.

        Returns
        -------
        X : ndarray, shape (N + 1, n_states)
        """
        U = np.atleast_2d(np.asarray(U, dtype=float))
        net = self.network
        if U.shape[1] != net.n_inputs:
            raise ModelError(f"U: expected {net.n_inputs} input columns ({net.input_names}), "
                             f"found {U.shape[1]}")
        x0 = np.asarray(x0, dtype=float)
        if x0.shape != (net.n_states,):
            raise ModelError(f"x0: expected shape ({net.n_states},), found {x0.shape}")
        if not dt > 0:
            raise ModelError(f"dt must be > 0 [s], found {dt}")
        p = self._p(p)
        X = np.empty((U.shape[0] + 1, net.n_states))
        X[0] = x0
        method = simulation_method(net.n_states, method)
        if method == "cvodes":
            return self._simulate_cvodes(U, dt, X, p)
        mats = self.matrices(p)
        sl = net.input_slices()
        flows, inverse = np.unique(U[:, sl["ms"]], axis=0, return_inverse=True)
        inverse = inverse.ravel()
        if substeps is None:
            substeps = max(1, math.ceil(dt / 60.0))
        # a stepper (an LU or a matrix exponential) is kept while its flow vector recurs,
        # and dropped after its last use: closed-loop flows rarely repeat, and a 490-zone
        # building's 576 sparse LUs of a 48-h window, all kept, took 5.6 GB
        last = np.zeros(len(flows), dtype=int)
        np.maximum.at(last, inverse, np.arange(len(inverse)))
        steppers = {}
        with single_thread_blas():
            for k in range(U.shape[0]):
                j = inverse[k]
                A_u, b = self.affine(U[k], mats=mats)
                if j not in steppers:
                    steppers[j] = make_stepper(A_u, dt, method, substeps)
                X[k + 1] = steppers[j](X[k], b)
                if last[j] == k:
                    del steppers[j]
        return X

    def _simulate_cvodes(self, U, dt, X, p):
        sym = self.sym
        dae = {"x": sym.x, "p": ca.vertcat(sym.u, sym.p), "ode": sym.f(sym.x, sym.u, sym.p)}
        integ = ca.integrator("I", "cvodes", dae, 0.0, dt,
                              {"abstol": 1e-10, "reltol": 1e-10, "max_num_steps": 100000})
        for k in range(U.shape[0]):
            X[k + 1] = np.asarray(integ(x0=X[k], p=np.concatenate([U[k], p]))["xf"]).ravel()
        return X

    def initial_state(self, T_zones, T_boundary) -> np.ndarray:
        """Initial state from data, as in the paper (IV-A).

        Measured zones at their measurement; unmeasured zones (NaN) at the mean of
        their measured zone neighbours (of all measured zones if they have none);
        every edge state at the mean of its two end nodes.

        Parameters
        ----------
        T_zones : array_like, shape (n_zones,)
            [°C], NaN where unmeasured.
        T_boundary : array_like, shape (n_boundary,)
            [°C].
        """
        net = self.network
        Tz = np.array(T_zones, dtype=float)
        Tb = np.asarray(T_boundary, dtype=float)
        if Tz.shape != (net.n_zones,) or Tb.shape != (len(net.boundary),):
            raise ModelError(f"initial_state: expected {net.n_zones} zone and "
                             f"{len(net.boundary)} boundary temperatures, found {Tz.shape}, {Tb.shape}")
        known = ~np.isnan(Tz)
        if not known.any():
            raise ModelError("initial_state: no zone temperature is known")
        zi = {z: i for i, z in enumerate(net.zones)}
        filled = Tz.copy()
        for i in np.flatnonzero(~known):
            nb = [zi[n] for n in net.neighbours(net.zones[i]) if n in zi and known[zi[n]]]
            filled[i] = Tz[nb].mean() if nb else Tz[known].mean()
        node_T = dict(zip(net.zones, filled))
        node_T.update(zip(net.boundary, Tb))
        x = list(filled)
        for e in net.edges:
            mid = 0.5 * (node_T[e.a] + node_T[e.b])
            x += [mid, mid]
        return np.array(x)

    def steady_state(self, u, p=None) -> np.ndarray:
        """Equilibrium state for a constant input ``u`` [°C]."""
        net = self.network
        u = np.asarray(u, dtype=float)
        # A floating part of the network (no boundary node, no supply air) makes A_u singular;
        # LU does not reliably flag that numerically, so check the structure first.
        fed = {z for z, m in zip(net.zones, u[net.input_slices()["ms"]]) if m > 0}
        for comp in nx.connected_components(net.graph):
            if not (comp & set(net.boundary)) and not (comp & fed):
                raise ModelError(f"no unique steady state: zones {sorted(comp)} have no path to a "
                                 "boundary node and no supply air at this operating point")
        A_u, b = self.affine(u, p)
        x = spla.splu(sp.csc_matrix(A_u)).solve(-b)
        if not np.all(np.isfinite(x)):
            raise ModelError("no unique steady state: the linear system is singular")
        return x

    # ---- exports -----------------------------------------------------------
    def operating_point(self, x=None, **inputs) -> "OperatingPoint":
        """An operating point from input values (see `ThermalNetwork.input_vector`).

        Parameters
        ----------
        x : array_like, optional
            State [°C]; default: the steady state for these inputs.
        **inputs : float or mapping
            ``ms`` supply flow per zone [kg/s], ``Ts`` supply temperature per zone [°C],
            ``T`` boundary temperatures [°C], ``Q`` heat per zone [W]: one value for every
            node, or a mapping by node name. In a mapping the key ``"*"`` gives the value
            of every node not named, e.g. ``T={"*": 21.0, "outside": -5.0}`` (all
            boundaries at 21 °C but the outside at −5 °C). A mapping for ``T`` must cover
            every boundary node, by name or through ``"*"``.

        Examples
        --------
        >>> op = model.operating_point(ms={"r240": 0.05}, Ts=14.0,
        ...                            T={"*": 21.0, "outside": -5.0})   # doctest: +SKIP
        """
        net = self.network
        for name in ("ms", "Ts", "T", "Q"):
            val = inputs.get(name)
            if not isinstance(val, Mapping):
                continue
            nodes = net.boundary if name == "T" else net.zones
            unknown = sorted(set(val) - set(nodes) - {"*"})
            if unknown:
                raise ModelError(f"{name}: unknown node(s) {unknown}; expected one of {list(nodes)} "
                                 "or '*' for all others")
            if "*" in val:
                inputs[name] = {n: val.get(n, val["*"]) for n in nodes}
            elif name == "T":
                # a silent default boundary temperature would move the operating point
                # without anyone noticing, so every boundary node must be given
                missing = [n for n in nodes if n not in val]
                if missing:
                    raise ModelError(f"T: no temperature for boundary node(s) {missing}; give "
                                     f"them, or one for all others with T={{'*': 21.0, ...}} "
                                     f"(command line: --op T=21 --op T[{missing[0]}]=...)")
        u = net.input_vector(**inputs)
        x = self.steady_state(u) if x is None else np.asarray(x, dtype=float)
        return OperatingPoint(x=x, u=u)

    def jacobians(self, op: "OperatingPoint", p=None):
        """Exact CasADi Jacobians ``(df/dx, df/du)`` at the operating point."""
        A, B = self.sym.jacobians(op.x, op.u, self._p(p))
        return np.asarray(ca.densify(A)), np.asarray(ca.densify(B))

    def to_statespace(self, op: "OperatingPoint", dt: float | None = None, name: str | None = None):
        """Linearize at ``op`` and return a named ``control.StateSpace``.

        The linear model is in deviation variables around ``op``: states ``T[z]``,
        ``x[e,1]``, ``x[e,2]``; inputs ``ms[z]``, ``Ts[z]``, ``T[b]``, ``Q[z]``;
        outputs ``T[z]``. Continuous unless ``dt`` [s] is given, then ZOH-discretised
        exactly (matrix exponential).

        Parameters
        ----------
        op : OperatingPoint
            From :meth:`operating_point`.
        dt : float, optional
            Sample time [s].
        """
        net = self.network
        A, B = self.jacobians(op)
        C = np.zeros((net.n_zones, net.n_states))
        C[np.arange(net.n_zones), np.arange(net.n_zones)] = 1.0
        D = np.zeros((net.n_zones, net.n_inputs))
        if dt is not None:
            if not dt > 0:
                raise ModelError(f"dt must be > 0 [s], found {dt}")
            Phi, Gamma = zoh(A, dt)
            A, B = Phi, Gamma @ B
        return ct.ss(A, B, C, D, dt=0 if dt is None else dt, states=net.state_names,
                     inputs=net.input_names, outputs=net.output_names,
                     name=name or net.spec.name)

    def to_casadi(self, substeps: int = 5) -> CasadiModel:
        """The symbolic model: ``f(x, u, p)`` and a stiff-stable discrete step ``F(x, u, p, dt)``.

        Parameters
        ----------
        substeps : int
            Sub-steps of the rational step per call of ``F``.
        """
        sym = self.sym
        net = self.network
        return CasadiModel(sym.f, sym.step(substeps), sym.x, sym.u, sym.p, net.state_names,
                           net.input_names, sym.param_names, self.p, substeps)


@dataclass
class OperatingPoint:
    """State and input around which a model is linearized.

    Attributes
    ----------
    x : ndarray, shape (n_states,)
        [°C]
    u : ndarray, shape (n_inputs,)
        Inputs in :attr:`ThermalNetwork.input_names` order.
    """

    x: np.ndarray
    u: np.ndarray = field(default=None)


def make_stepper(A_u, dt: float, method: str = "exact", substeps: int = 1):
    """A function ``step(x, b) -> x_next`` for ``xdot = A_u x + b`` with ``b`` held over ``dt``.

    Parameters
    ----------
    A_u : sparse or dense matrix, shape (n, n)
        State matrix at the current supply flow [1/s] (see :meth:`ThermalModel.affine`).
    dt : float
        Step [s].
    method : {"exact", "radau"}
        ``exact``: matrix exponential (dense, O(n³) once per call of this function).
        ``radau``: L-stable 3rd-order rational step over ``substeps`` sub-steps; sparse
        LU above 400 states, so it scales to large buildings.
    substeps : int
        Sub-steps for ``radau``.
    """
    if method == "exact":
        Phi, Gamma = zoh(A_u, dt)
        return lambda x, b: Phi @ x + Gamma @ b
    if method != "radau":
        raise ModelError(f"method must be 'exact' or 'radau', found {method!r}")
    return radau_stepper(A_u, dt, substeps)
