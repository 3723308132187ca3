r"""A reduced thermal network that keeps the zone temperatures as states.

Structure-preserving, Kron and lumped reductions all give a model of the form

.. math::

    \mathcal{C}_r \dot x_r = -K_r x_r - c_p E\,\mathrm{diag}(\dot m_s) E^T x_r
        + G_r T_b + E\,\big(c_p\,\mathrm{diag}(\dot m_s) T_s + Q\big),

with :math:`x_r = [T_z; a]`, :math:`\mathcal{C}_r` diagonal positive [J/K],
:math:`K_r` symmetric positive semi-definite [W/K] and :math:`E` selecting the zone
rows. It is bilinear in the supply flow exactly as the full model is, so it holds at
every operating point, not only at the one it was designed for.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import casadi as ca
import control as ct
import numpy as np
import scipy.sparse as sp

from .._step import radau_casadi_step
from ..errors import ModelError
from ..model import OperatingPoint, make_stepper, zoh
from ..network import ThermalNetwork

__all__ = ["ReducedNetwork"]


@dataclass
class ReducedNetwork:
    """A bilinear RC-type model whose first ``n_zones`` states are the zone temperatures.

    Attributes
    ----------
    state_names : list of str
        ``T[z]`` for the zones, then the kept edge states (``x[e,k]``) or modes (``a[k]``).
    zones, boundary : list of str
        Node names, in the full model's order.
    cap : ndarray, shape (r,)
        Capacitance of every state [J/K] (a mode's is its modal capacitance).
    K : ndarray, shape (r, r)
        Symmetric conductance matrix without the supply term [W/K].
    G : ndarray, shape (r, n_boundary)
        Conductance to the boundary nodes [W/K].
    cp : float
        Specific heat of the supply air [J/(kg K)].
    name : str
    lift_x, lift_b : ndarray or None, shapes (n_full, r), (n_full, n_boundary)
        Full state from the reduced one, ``x = lift_x @ x_r + lift_b @ T_b`` (quasi-static
        eliminated states).
    restrict : ndarray or None, shape (r, n_full)
        Reduced state from a full one (capacitance-weighted projection).
    full_state_names : list of str
    measured : list of str, optional
        Measured zones (default: all).

    It also answers the parts of the :class:`~thermctl.model.ThermalModel` interface that
    controllers and estimators use (``network``, ``matrices``, ``capacitances``,
    ``affine``, ``initial_state``, ``steady_state``, ``operating_point``,
    ``to_statespace``, ``simulate``), so it can stand in for the full model there.
    """

    state_names: list
    zones: list
    boundary: list
    cap: np.ndarray
    K: np.ndarray
    G: np.ndarray
    cp: float
    name: str = "reduced"
    lift_x: np.ndarray | None = None
    lift_b: np.ndarray | None = None
    restrict: np.ndarray | None = None
    full_state_names: list = field(default_factory=list)
    measured: list | None = None

    def __post_init__(self):
        r = len(self.state_names)
        for what, arr, shape in (("cap", self.cap, (r,)), ("K", self.K, (r, r)),
                                 ("G", self.G, (r, len(self.boundary)))):
            if np.shape(arr) != shape:
                raise ModelError(f"ReducedNetwork.{what}: expected shape {shape}, found {np.shape(arr)}")
        if np.any(~(np.asarray(self.cap) > 0)):
            raise ModelError("ReducedNetwork.cap: every capacitance must be > 0 [J/K]")

    # ---- sizes and names (same conventions as ThermalNetwork) ---------------
    @property
    def n_states(self) -> int:
        return len(self.state_names)

    @property
    def n_zones(self) -> int:
        return len(self.zones)

    # the same naming conventions, from the one place that defines them (they read only
    # `zones` and `boundary`)
    n_inputs = ThermalNetwork.n_inputs
    input_names = ThermalNetwork.input_names
    output_names = ThermalNetwork.output_names

    @property
    def network(self) -> "ReducedNetwork":
        """Itself: the sizes and names a ThermalModel keeps on its network."""
        return self

    @property
    def measured_zones(self) -> list[str]:
        return list(self.zones) if self.measured is None else list(self.measured)

    def input_slices(self) -> dict[str, slice]:
        return ThermalNetwork.input_slices(self)

    def input_vector(self, ms=0.0, Ts=20.0, T=10.0, Q=0.0) -> np.ndarray:
        """Input vector from scalars or dicts (see :meth:`ThermalNetwork.input_vector`)."""
        return ThermalNetwork.input_vector(self, ms=ms, Ts=Ts, T=T, Q=Q)

    # ---- dynamics ----------------------------------------------------------
    def capacitances(self, p=None) -> np.ndarray:
        """Capacitance of every state [J/K] (``p`` is accepted and ignored)."""
        return np.array(self.cap, dtype=float)

    def matrices(self, p=None):
        """``(A, Bt)`` without the supply term, sparse, like :meth:`ThermalModel.matrices`."""
        return (sp.csc_matrix(-self.K / self.cap[:, None]),
                sp.csc_matrix(self.G / self.cap[:, None]))

    def initial_state(self, T_zones, T_boundary) -> np.ndarray:
        """Zones at the given temperatures (NaN: mean of the known ones), the other states at
        their steady state for those zone and boundary temperatures [°C]."""
        Tz = np.array(T_zones, dtype=float)
        Tb = np.asarray(T_boundary, dtype=float)
        nz = self.n_zones
        if Tz.shape != (nz,) or Tb.shape != (len(self.boundary),):
            raise ModelError(f"initial_state: expected {nz} zone and {len(self.boundary)} boundary "
                             f"temperatures, found {Tz.shape}, {Tb.shape}")
        known = ~np.isnan(Tz)
        if not known.any():
            raise ModelError("initial_state: no zone temperature is known")
        Tz[~known] = Tz[known].mean()
        if self.n_states == nz:
            return Tz
        K, G = self.K, self.G
        a = np.linalg.solve(K[nz:, nz:], G[nz:] @ Tb - K[nz:, :nz] @ Tz)
        return np.concatenate([Tz, a])

    def affine(self, u, p=None, mats=None):
        """``xdot = A_u x + b_u`` for a constant input ``u`` (dense; ``p``, ``mats`` ignored)."""
        u = self._check_u(u)
        sl = self.input_slices()
        nz = self.n_zones
        ms = u[sl["ms"]]
        Kms = self.K.copy()
        Kms[np.arange(nz), np.arange(nz)] += self.cp * ms
        rhs = self.G @ u[sl["T"]]
        rhs[:nz] += self.cp * ms * u[sl["Ts"]] + u[sl["Q"]]
        return -Kms / self.cap[:, None], rhs / self.cap

    def steady_state(self, u) -> np.ndarray:
        """Equilibrium state for a constant input ``u`` [°C]."""
        A_u, b = self.affine(u)
        try:
            x = np.linalg.solve(A_u, -b)
        except np.linalg.LinAlgError:
            x = np.full(len(b), np.nan)
        if not np.all(np.isfinite(x)):
            raise ModelError("no unique steady state: the reduced network has no path to a "
                             "boundary node or to supply air at this operating point")
        return x

    def operating_point(self, x=None, **inputs) -> OperatingPoint:
        """Operating point from input values; ``x`` defaults to the steady state."""
        u = self.input_vector(**inputs)
        x = self.steady_state(u) if x is None else np.asarray(x, dtype=float)
        return OperatingPoint(x=x, u=u)

    def to_statespace(self, op: OperatingPoint, dt: float | None = None, name: str | None = None):
        """Linearize at ``op`` (reduced state) and return a named ``control.StateSpace``.

        Deviation variables, like :meth:`ThermalModel.to_statespace`; continuous unless
        ``dt`` [s] is given (exact ZOH).
        """
        u = self._check_u(op.u)
        x = np.asarray(op.x, dtype=float)
        if x.shape != (self.n_states,):
            raise ModelError(f"op.x: expected {self.n_states} reduced states, found shape {x.shape}")
        sl = self.input_slices()
        nz, r = self.n_zones, self.n_states
        A, _ = self.affine(u)
        B = np.zeros((r, self.n_inputs))
        zi = np.arange(nz)
        cz = self.cap[:nz]
        B[zi, sl["ms"].start + zi] = self.cp * (u[sl["Ts"]] - x[:nz]) / cz
        B[zi, sl["Ts"].start + zi] = self.cp * u[sl["ms"]] / cz
        B[:, sl["T"]] = self.G / self.cap[:, None]
        B[zi, sl["Q"].start + zi] = 1.0 / cz
        C = np.zeros((nz, r))
        C[zi, zi] = 1.0
        D = np.zeros((nz, self.n_inputs))
        if dt is not None:
            if not dt > 0:
                raise ModelError(f"dt must be > 0 [s], found {dt}")
            Phi, Gamma = zoh(A, dt)
            A, B = Phi, Gamma @ B
        return ct.ss(A, B, C, D, dt=0 if dt is None else dt, states=self.state_names,
                     inputs=self.input_names, outputs=self.output_names, name=name or self.name)

    def simulate(self, U, dt: float, x0, method: str = "exact", substeps: int | None = None):
        """Simulate with inputs held over each step; see :meth:`ThermalModel.simulate`.

        Parameters
        ----------
        U : array_like, shape (N, n_inputs)
        dt : float
            Step [s].
        x0 : array_like, shape (n_states,)
            Initial reduced state [°C].
        method : {"exact", "radau"}
        substeps : int, optional
            For ``radau``; default ``ceil(dt / 60 s)``.

        Returns
        -------
        X : ndarray, shape (N + 1, n_states)
        """
        U = np.atleast_2d(np.asarray(U, dtype=float))
        if U.shape[1] != self.n_inputs:
            raise ModelError(f"U: expected {self.n_inputs} input columns, found {U.shape[1]}")
        if not dt > 0:
            raise ModelError(f"dt must be > 0 [s], found {dt}")
        x0 = np.asarray(x0, dtype=float)
        if x0.shape != (self.n_states,):
            raise ModelError(f"x0: expected shape ({self.n_states},), found {x0.shape}")
        substeps = substeps or max(1, math.ceil(dt / 60.0))
        sl = self.input_slices()
        flows, inverse = np.unique(U[:, sl["ms"]], axis=0, return_inverse=True)
        steppers = {}
        X = np.empty((U.shape[0] + 1, self.n_states))
        X[0] = x0
        for k, j in enumerate(inverse.ravel()):
            A_u, b = self.affine(U[k])
            if j not in steppers:
                steppers[j] = make_stepper(A_u, dt, method, substeps)
            X[k + 1] = steppers[j](X[k], b)
        return X

    def to_casadi(self, substeps: int = 5):
        """CasADi functions ``f(x, u) -> xdot`` and ``F(x, u, dt) -> x_next``.

        ``F`` is the L-stable Radau IIA (Padé 1/2) step of :meth:`ThermalModel.to_casadi`
        over ``substeps`` sub-steps; it is exact at steady state.

        Returns
        -------
        f, F : casadi.Function
        """
        r, nz = self.n_states, self.n_zones
        sl = self.input_slices()
        x = ca.MX.sym("x", r)
        u = ca.MX.sym("u", self.n_inputs)
        dt = ca.MX.sym("dt")
        inv_c = ca.DM(1.0 / self.cap)
        A0 = ca.DM(-self.K / self.cap[:, None])
        Bt = ca.DM(self.G / self.cap[:, None])
        sel = np.zeros((r, nz))
        sel[np.arange(nz), np.arange(nz)] = 1.0
        sel = ca.DM(sel)
        ms, Ts, Tb, Q = u[sl["ms"]], u[sl["Ts"]], u[sl["T"]], u[sl["Q"]]
        a_sup = self.cp * ms * inv_c[:nz]
        A_u = A0 - ca.mtimes(sel, ca.mtimes(ca.diag(a_sup), sel.T))
        b_u = ca.mtimes(Bt, Tb) + ca.mtimes(sel, a_sup * Ts + Q * inv_c[:nz])
        f = ca.Function("f", [x, u], [ca.mtimes(A_u, x) + b_u], ["x", "u"], ["xdot"])
        xk = radau_casadi_step(A_u, b_u, x, dt / substeps, substeps)
        F = ca.Function(f"F{substeps}", [x, u, dt], [xk], ["x", "u", "dt"], ["x_next"])
        return f, F

    # ---- mapping to and from the full state -------------------------------
    def from_full_state(self, x_full) -> np.ndarray:
        """Reduced state of a full state (zone temperatures copied, modes projected) [°C]."""
        if self.restrict is None:
            raise ModelError("this reduced network stores no map from the full state")
        return self.restrict @ np.asarray(x_full, dtype=float)

    def to_full_state(self, x_r, T_boundary) -> np.ndarray:
        """Full state implied by a reduced one and the boundary temperatures [°C]."""
        if self.lift_x is None:
            raise ModelError("this reduced network stores no map to the full state")
        return self.lift_x @ np.asarray(x_r, dtype=float) + self.lift_b @ np.asarray(T_boundary, dtype=float)

    def _check_u(self, u):
        u = np.asarray(u, dtype=float)
        if u.shape != (self.n_inputs,):
            raise ModelError(f"u: expected {self.n_inputs} inputs ({self.input_names[:4]} ...), "
                             f"found shape {u.shape}")
        return u


def network_matrices(model, p=None):
    """Capacitances [J/K], sparse ``K`` at zero flow [W/K] and dense ``G`` [W/K] of a ThermalModel.

    ``C ẋ = -K x + G T_b`` plus the zone supply and heat terms.
    """
    cap = model.capacitances(p)
    A0, Bt = model.matrices(p)
    K = -(sp.diags(cap) @ A0)
    K = sp.csr_matrix(0.5 * (K + K.T))  # symmetric up to rounding by construction (g_ij = g_ji)
    G = cap[:, None] * Bt.toarray()
    return cap, K, G


def full_network(model) -> ReducedNetwork:
    """The full model as a (not reduced) :class:`ReducedNetwork`: same states, dense matrices."""
    net = model.network
    cap, K, G = network_matrices(model)
    return ReducedNetwork(list(net.state_names), list(net.zones), list(net.boundary), cap, K.toarray(), G,
                          net.spec.cp, net.spec.name)


def linearize(model, op, dt=None):
    """``model.to_statespace(op, dt)`` from the dense network matrices.

    Same result as the CasADi Jacobian (tested to rounding), without building the
    symbolic Jacobian, which dominates for thousands of states.
    """
    return full_network(model).to_statespace(op, dt=dt, name=model.network.spec.name)
