r"""Sparse dynamics for the MPCs: the continuous network at a fixed flow, its implicit steps,
and the elimination of the fast convection-edge states.

At a fixed supply flow :math:`\dot m` the model is linear,

.. math::

    \dot x = A(\dot m)\,x + B_{T_s}(\dot m)\,T_s + B_T\,T_b + B_Q\,Q,
    \qquad A(\dot m) = A_0 - \mathrm{diag}(k_z \dot m)\ \text{on the zone rows},

with :math:`A_0` as sparse as the network (:meth:`ThermalModel.matrices`). A step of
length :math:`h` with the inputs held is written as *rows* :math:`L x^+ = N x + M u`:

``radau``
    two-stage Radau IIA (:mod:`thermctl._step`) in collocation form: the stage state
    :math:`X_1` at :math:`h/3` and :math:`X_2 = x^+` are both variables,
    :math:`X_i = x + h\sum_j a_{ij}(A X_j + B u)`. Order 3, L-stable, one-hop rows; the
    same step as :func:`thermctl._step.radau_residual`'s Padé rows
    :math:`(I - \tfrac{2h}{3}A + \tfrac{h^2}{6}A^2)x^+ = (I + \tfrac{h}{3}A)x + \dots`,
    whose :math:`A^2` couples two-hop neighbours and squares the rows' conditioning
    (measured: 3× PIQP's time on the 7-zone QP).
``euler``
    implicit Euler: :math:`L = I - hA`, :math:`N = I`, forcing :math:`hB`. Order 1,
    L-stable, one-hop.
``radau-dense``
    the same Radau step solved for :math:`x^+` (:math:`L = I`, :math:`N = D^{-1}(I + \tfrac{h}{3}A)`):
    the optimum of ``radau`` with dense blocks, to measure what density costs.
``zoh``
    the exact discretisation (:func:`thermctl.model.zoh`), dense; what
    ``ThermalModel.to_statespace(op, dt)`` exports.

The implicit forms are scaled row by row (each row divided by its largest entry of
:math:`L`): the same solution, better conditioned constraints.

Singular perturbation of the convection edges: their states have time constants of
seconds, the MPC step is minutes, so :func:`eliminate_fast_edges` holds them quasi-static
(:func:`thermctl.reduce.kron`, a Schur complement). Each convection edge only touches its
two zones, so the result couples the same zone pairs directly: as sparse as before, exact
at steady state, two states fewer per air path, and no time constants of seconds left to
make the implicit rows stiff.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from thermctl.model import zoh

__all__ = ["LinearDynamics", "StepRows", "TRANSCRIPTIONS", "at_flow", "step_rows", "row_scale",
           "eliminate_fast_edges", "casadi_rhs", "network_cp"]

log = logging.getLogger(__name__)

TRANSCRIPTIONS = ("radau", "euler", "radau-dense", "zoh")
"""Step forms of :func:`step_rows`: two sparse (implicit) and two dense (explicit)."""

SPARSE_TRANSCRIPTIONS = ("radau", "euler")


def network_cp(net) -> float:
    """Specific heat of the supply air [J/(kg K)] of a ThermalNetwork or ReducedNetwork."""
    cp = getattr(net, "cp", None)
    return float(cp if cp is not None else net.spec.cp)


@dataclass
class LinearDynamics:
    """Continuous dynamics at a fixed supply flow, all sparse.

    Attributes
    ----------
    A : scipy.sparse.csc_matrix, shape (nx, nx)
        [1/s]
    B_Ts : scipy.sparse.csc_matrix, shape (nx, n_zones)
        Supply temperature [1/s]: ``k_z ṁ_z`` on the zone rows.
    B_T : scipy.sparse.csc_matrix, shape (nx, n_boundary)
        Boundary temperatures [1/s].
    B_Q : scipy.sparse.csc_matrix, shape (nx, n_zones)
        Heat into the zones [K/J]: ``1/C_z`` on the zone rows.
    """

    A: sp.csc_matrix
    B_Ts: sp.csc_matrix
    B_T: sp.csc_matrix
    B_Q: sp.csc_matrix


@dataclass
class StepRows:
    """One held-input step written as rows ``L w − N x − B_Ts Ts − B_T T_b − B_Q Q = 0``.

    ``w`` is ``x⁺``, or for ``radau`` the stage state at ``h/3`` stacked on ``x⁺``.

    Attributes
    ----------
    L : sparse or dense matrix, shape (stages·nx, stages·nx)
    N : sparse or dense matrix, shape (stages·nx, nx)
    B_Ts, B_T, B_Q : sparse or dense matrix
        Forcing of each input group over the step [K per unit input].
    method : str
    """

    L: object
    N: object
    B_Ts: object
    B_T: object
    B_Q: object
    method: str

    @property
    def stages(self) -> int:
        """State vectors per step: 2 for ``radau`` (the stage at h/3, then x⁺), else 1."""
        return self.L.shape[0] // self.N.shape[1]

    @property
    def sparse(self) -> bool:
        return self.method in SPARSE_TRANSCRIPTIONS

    def nnz(self) -> int:
        """Stored entries of the state blocks ``L`` and ``N`` (what the QP's rows carry)."""
        def count(M):
            return M.nnz if sp.issparse(M) else int(np.count_nonzero(M))
        return count(self.L) + count(self.N)


def at_flow(model, ms) -> LinearDynamics:
    """The model's continuous dynamics at supply flows ``ms`` [kg/s] per zone.

    Parameters
    ----------
    model : ThermalModel or thermctl.reduce.ReducedNetwork
    ms : array_like, shape (n_zones,)
        [kg/s]
    """
    net = model.network
    nz, nx = net.n_zones, net.n_states
    A0, Bt = model.matrices()
    cap = np.asarray(model.capacitances(), float)
    kz = network_cp(net) / cap[:nz]
    a_sup = np.zeros(nx)
    a_sup[:nz] = kz * np.asarray(ms, float)
    zr = np.arange(nz)
    A = sp.csc_matrix(A0) - sp.diags(a_sup, format="csc")
    B_Ts = sp.csc_matrix((kz * np.asarray(ms, float), (zr, zr)), shape=(nx, nz))
    B_Q = sp.csc_matrix((1.0 / cap[:nz], (zr, zr)), shape=(nx, nz))
    return LinearDynamics(sp.csc_matrix(A), B_Ts, sp.csc_matrix(Bt), B_Q)


def step_rows(dyn: LinearDynamics, h: float, method: str = "radau") -> StepRows:
    """The step over ``h`` [s] in one of :data:`TRANSCRIPTIONS` (see the module docstring)."""
    if method not in TRANSCRIPTIONS:
        raise ValueError(f"transcription must be one of {TRANSCRIPTIONS}, found {method!r}")
    A = sp.csc_matrix(dyn.A)
    n = A.shape[0]
    I = sp.identity(n, format="csc")
    if method == "zoh":
        Phi, Gam = zoh(A, h)
        return StepRows(np.eye(n), Phi, Gam @ dyn.B_Ts, Gam @ dyn.B_T, Gam @ dyn.B_Q, method)
    if method == "euler":
        L, N, M = I - h * A, I, h * I
    elif method == "radau":
        # collocation form: stage X1 at t + h/3 and X2 = x⁺, X_i = x + h Σ_j a_ij (A X_j + b)
        # (Radau IIA, a = [[5/12, −1/12], [3/4, 1/4]]); eliminating X1 gives the Padé rows
        # below, but those carry A² (two-hop, squared conditioning): these stay one-hop
        a = ((5 / 12, -1 / 12), (3 / 4, 1 / 4))
        L = sp.bmat([[I - h * a[0][0] * A, -h * a[0][1] * A],
                     [-h * a[1][0] * A, I - h * a[1][1] * A]], format="csc")
        N = sp.vstack([I, I], format="csc")
        M = sp.vstack([(h / 3) * I, h * I], format="csc")
    else:
        L = I - (2 * h / 3) * A + (h * h / 6) * (A @ A)
        N = I + (h / 3) * A
        M = h * (I - (h / 6) * A)
    if method == "radau-dense":
        lu = sla.lu_factor(L.toarray())
        solve = lambda X: sla.lu_solve(lu, X.toarray() if sp.issparse(X) else X)  # noqa: E731
        return StepRows(np.eye(n), solve(N), solve(M @ dyn.B_Ts), solve(M @ dyn.B_T),
                        solve(M @ dyn.B_Q), method)
    s = 1.0 / abs(L).max(axis=1).toarray().ravel()       # row scaling: same rows, O(1) entries
    S = sp.diags(s, format="csc")
    return StepRows(sp.csc_matrix(S @ L), sp.csc_matrix(S @ N), sp.csc_matrix(S @ M @ dyn.B_Ts),
                    sp.csc_matrix(S @ M @ dyn.B_T), sp.csc_matrix(S @ M @ dyn.B_Q), method)


def row_scale(dyn: LinearDynamics, h: float, method: str = "radau") -> np.ndarray:
    """``1 / max_j |L_ij|`` of the step rows over ``h`` [s] (``radau``: Padé rows ``L = I −
    (2h/3) A + (h²/6) A²``; ``euler``: ``L = I − h A``): the scaling :func:`step_rows`
    applies, for the economic MPC's symbolic rows."""
    A = sp.csc_matrix(dyn.A)
    I = sp.identity(A.shape[0], format="csc")
    L = I - h * A if method == "euler" else I - (2 * h / 3) * A + (h * h / 6) * (A @ A)
    return 1.0 / abs(L).max(axis=1).toarray().ravel()


def eliminate_fast_edges(model, op, error: bool = True, max_error_states: int = 800,
                         tau: float | None = None):
    """The model with its fast edge states held quasi-static (singular perturbation).

    Parameters
    ----------
    model : ThermalModel
    op : OperatingPoint
        Where the reduction's error is measured (the reduced network holds at every flow).
    tau : float, optional
        Also eliminate every wall edge whose slowest time constant (both ends held) is
        below ``tau`` [s] (:func:`thermctl.reduce.kron`); default: the convection edges
        only. An edge touches two nodes, so either way the result couples only nodes
        the edge joined: no fill-in. On the 49-zone floor (windows 0.20 h, hall walls
        0.31 h, partitions 0.39 h, measured): ``tau=1000`` drops the windows (661 -> 537
        states, step error 1.8 % at 1 h, one QP 3.7 s CPU instead of 4.0);
        ``tau=1500`` also the partitions (349 states, 25 % at 1 h, 2.6 s): not worth it.
    error : bool
        Measure the step-response error against the full model (heat into each zone and
        boundary temperatures to every zone temperature, 1 / 6 / 24 h,
        :class:`thermctl.reduce.Reference`); skipped above ``max_error_states`` states (a
        dense eigen-decomposition of the full model).

    Returns
    -------
    network : thermctl.reduce.ReducedNetwork
        Zone and wall states unchanged; its conductance matrix has the full model's
        sparsity (rounding-level fill-in of the Schur complement removed).
    info : dict
        ``states`` (full, reduced), ``eliminated``, ``time [s]``, ``nnz`` (full and reduced
        ``A``) and ``step error`` (relative, at 1, 6, 24 h) when measured.
    """
    from thermctl.reduce import Reference, kron, linearize

    t0 = time.perf_counter()
    red = kron(model, op, tau=tau)
    rnet = red.network
    K = np.asarray(rnet.K, float)
    scale = np.abs(K).max(axis=1, keepdims=True)
    K[np.abs(K) < 1e-12 * np.maximum(scale, scale.T)] = 0.0
    rnet.K = 0.5 * (K + K.T)
    A_full, _ = model.matrices()
    info = {"states": (model.network.n_states, rnet.n_states),
            "eliminated": len(red.info.get("eliminated", [])),
            "nnz": (int(sp.csc_matrix(A_full).nnz), int(np.count_nonzero(rnet.K))),
            "time [s]": time.perf_counter() - t0}
    if error and model.network.n_states <= max_error_states:
        err = Reference(linearize(model, op)).step_error(red.sys)
        info["step error"] = dict(zip((f"{t / 3600:g} h" for t in err.times),
                                      (float(v) for v in err.rel)))
    log.info("convection edges eliminated: %s", info)
    return rnet, info


def _dm(M) -> ca.DM:
    M = sp.csc_matrix(M)
    return ca.DM(ca.Sparsity(M.shape[0], M.shape[1], M.indptr.tolist(), M.indices.tolist()),
                 M.data)


def casadi_rhs(model) -> ca.Function:
    """``f(x, u) -> xdot`` [K/s] (SX) from the sparse matrices of any model that has
    ``matrices()`` and ``capacitances()``: as sparse as the network, also for a
    :class:`~thermctl.reduce.ReducedNetwork` (whose own ``to_casadi`` uses dense ``K``)."""
    net = model.network
    nz, nx, nu = net.n_zones, net.n_states, net.n_inputs
    A0, Bt = model.matrices()
    cap = np.asarray(model.capacitances(), float)
    kz = ca.DM(network_cp(net) / cap[:nz])
    sl = net.input_slices()
    x, u = ca.SX.sym("x", nx), ca.SX.sym("u", nu)
    ms, Ts, Tb, Q = (u[sl[g].start:sl[g].stop] for g in ("ms", "Ts", "T", "Q"))
    xdot = ca.mtimes(_dm(A0), x) + ca.mtimes(_dm(Bt), Tb)
    zone = ms * kz * (Ts - x[:nz]) + Q / ca.DM(cap[:nz])
    xdot = xdot + ca.vertcat(zone, ca.DM.zeros(nx - nz))
    return ca.Function("f", [x, u], [xdot], ["x", "u"], ["xdot"])
