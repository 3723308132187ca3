r"""A plant that is not the identification model: walls resolved by finite volumes.

The default plant (:class:`~thermctl.testbed.plant.Plant`) *is* the model thermctl
identifies: 3R2C walls, stepped by the model core's own Radau scheme. Data from it test
the estimators, not the model class. :class:`FDPlant` simulates the same building as real
walls behave:

* **every wall is surface films and a slab of many nodes.** A spec wall of area ``A``
  gets the surface resistances of ISO 6946 (:data:`R_SI` = 0.13 m² K/W towards a zone or
  indoor node, :data:`R_SE` = 0.04 towards outdoors; scaled down to at most 60 % of the
  wall's resistance), without capacity. The rest of its 3R2C element
  ``R = (R1, R2, R3)``, ``C = (C1, C2)`` is read as two homogeneous layers, layer 1 with
  capacity :math:`C_1` and resistance in proportion :math:`R_1 + R_2/2`, layer 2 with
  :math:`C_2` and :math:`R_2/2 + R_3`, each cut into ``nodes`` finite volumes (a node at
  each cell centre, half a cell's resistance from each face). For the homogeneous-slab
  split of :func:`thermctl.rc.homogeneous_split` and for the 25/50/25 % split alike the
  core is one homogeneous slab. The series resistance is the wall's, so steady heat flows
  are exact; the 3R2C element matches the first mode of a film-less slab (homogeneous
  split) or none (25/50/25), and a real wall's surface responds otherwise;
* **its own matrices**, assembled here from the spec's R and C, the zone capacitances and
  the true convection edges (the paper's 3R2C air paths, ``R̄_v d`` three times and
  ``C_v`` twice) — not :meth:`ThermalModel.matrices`;
* **its own integrator**: Alexander's 3-stage, order-3, L-stable SDIRK method on
  sub-steps of at most ``max_substep`` seconds, one sparse LU of
  :math:`I - \gamma h A_u` per supply flow — not :mod:`thermctl._step` or
  :func:`thermctl.model.make_stepper`. The tests check it against
  :func:`scipy.integrate.solve_ivp` (Radau, tight tolerances).

The interface is :class:`Plant`'s, so the baseline controller, an MPC or
:func:`run_closed_loop` drive it the same way; its state is the finite-volume state
(zones first, in spec order).
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import ModelError
from ..model import ThermalModel
from ..spec import is_outdoor
from .disturbances import Disturbances
from .plant import Plant

__all__ = ["FDPlant", "fd_matrices", "FD_NODES", "MAX_SUBSTEP", "R_SI", "R_SE"]

FD_NODES = 10
"""Finite volumes per wall layer (two layers per wall) [-]."""

R_SI, R_SE = 0.13, 0.04
"""Surface resistances [m² K/W] inside (zones, indoor neighbours) and outside (ISO 6946)."""

FILM_MAX = 0.6
"""Films take at most this share of a wall's resistance [-] (light partitions)."""

MAX_SUBSTEP = 15.0
"""Longest SDIRK sub-step [s]: the convection edges' time constants are seconds."""

# Alexander (1977), SDIRK3: L-stable, stiffly accurate, order 3.
_G = 0.43586652150845899942
_A21 = (1.0 - _G) / 2.0
_B1 = -(6.0 * _G**2 - 16.0 * _G + 1.0) / 4.0
_B2 = (6.0 * _G**2 - 20.0 * _G + 5.0) / 4.0


def _films(w):
    """Surface resistances [K/W] at ends ``a`` and ``b`` of spec wall ``w`` (0 without area)."""
    if not w.area:
        return 0.0, 0.0
    ra, rb = ((R_SE if is_outdoor(n) else R_SI) / w.area for n in (w.a, w.b))
    scale = min(1.0, FILM_MAX * sum(w.R) / (ra + rb))
    return ra * scale, rb * scale


def fd_matrices(model: ThermalModel, nodes: int = FD_NODES):
    """State matrix, boundary input matrix and capacitances of the finite-volume building.

    Parameters
    ----------
    model : ThermalModel
        Its network gives zones, walls (3R2C, read as two layers) and convection edges;
        its parameters give each convection edge's ``R̄_v`` and ``C_v``.
    nodes : int
        Finite volumes per wall layer (>= 1).

    Returns
    -------
    A : scipy.sparse.csr_matrix, shape (n, n)
        Without the supply term [1/s]. States: zones (spec order), then every wall's
        ``2 nodes`` cells (spec order, from end ``a`` to ``b``), then two states per
        convection edge.
    B : scipy.sparse.csr_matrix, shape (n, n_boundary)
        Boundary temperatures → ``dx/dt`` [1/s].
    C : ndarray, shape (n,)
        Capacitance of every state [J/K].
    surfaces : list of (int, int, float, int, int, float)
        Per wall: (node of end ``a``, its surface cell, conductance [W/K], node of end
        ``b``, its surface cell, conductance); nodes ``>= n`` are boundary nodes
        ``n + j``.
    """
    if int(nodes) != nodes or nodes < 1:
        raise ModelError(f"fd_matrices: nodes must be an integer >= 1, found {nodes!r}")
    nodes = int(nodes)
    net = model.network
    nz = net.n_zones
    cap = list(net.fixed_capacitances()[:nz])
    walls = net.conduction_edges
    conv = net.convection_edges
    n = nz + 2 * nodes * len(walls) + 2 * len(conv)
    index = {z: i for i, z in enumerate(net.zones)}
    index.update({b: n + j for j, b in enumerate(net.boundary)})
    links = []      # (i, j, conductance)
    surfaces = []
    k = nz
    if len(walls) != len(net.spec.walls):
        raise ModelError("fd_matrices: the network's conduction edges are not the spec's walls")
    for w, sw in zip(walls, net.spec.walls):
        (R1, R2, R3), (C1, C2) = w.R, w.C
        fa, fb = _films(sw)
        core = (sum(w.R) - fa - fb) / sum(w.R)
        layers = ((core * (R1 + R2 / 2.0), C1), (core * (R2 / 2.0 + R3), C2))
        cells = list(range(k, k + 2 * nodes))
        res = []        # resistance from the previous node to each cell centre, then to b
        prev_half = fa
        for R, C in layers:
            for _ in range(nodes):
                res.append(prev_half + R / (2 * nodes))
                prev_half = R / (2 * nodes)
                cap.append(C / nodes)
        res.append(prev_half + fb)
        chain = [index[w.a]] + cells + [index[w.b]]
        for (i, j), r in zip(zip(chain, chain[1:]), res):
            links.append((i, j, 1.0 / r))
        surfaces.append((index[w.a], cells[0], 1.0 / res[0], index[w.b], cells[-1], 1.0 / res[-1]))
        k += 2 * nodes
    m = len(conv)
    p = model.p
    for q, e in enumerate(conv):
        R, C = p[q] * e.d, p[m + q]
        s1, s2 = k, k + 1
        links += [(index[e.a], s1, 1.0 / R), (s1, s2, 1.0 / R), (s2, index[e.b], 1.0 / R)]
        cap += [C, C]
        k += 2
    C = np.array(cap, dtype=float)
    rows, cols, vals = [], [], []
    brow, bcol, bval = [], [], []
    for i, j, g in links:
        for u, v in ((i, j), (j, i)):
            if u >= n:
                continue
            rows.append(u)
            cols.append(u)
            vals.append(-g / C[u])
            if v >= n:
                brow.append(u)
                bcol.append(v - n)
                bval.append(g / C[u])
            else:
                rows.append(u)
                cols.append(v)
                vals.append(g / C[u])
    A = sp.csr_matrix((vals, (rows, cols)), shape=(n, n))
    B = sp.csr_matrix((bval, (brow, bcol)), shape=(n, len(net.boundary)))
    return A, B, C, surfaces


class FDPlant(Plant):
    """The building with finite-volume walls and its own stiff integrator.

    Parameters
    ----------
    model : ThermalModel
        The true 3R2C description: zones, walls (read as layered slabs), true convection
        edges and their ``R̄_v``, ``C_v``. Only its network and parameters are used.
    disturbances : Disturbances
    x0 : array_like, shape (n_states,), optional
        Initial finite-volume state [°C]; default: steady state of the first step with
        the supply off.
    nodes : int
        Finite volumes per wall layer (:data:`FD_NODES`).
    max_substep : float
        Longest integration sub-step [s] (:data:`MAX_SUBSTEP`).
    sensor_sd, sensor_bias, seed, sensed
        As :class:`Plant`.

    Examples
    --------
    >>> tb = generate(days=2, plant="fd")           # doctest: +SKIP
    >>> tb.plant().n_states                         # doctest: +SKIP
    853
    """

    def __init__(self, model: ThermalModel, disturbances: Disturbances, x0=None,
                 nodes: int = FD_NODES, max_substep: float = MAX_SUBSTEP, sensor_sd: float = 0.0,
                 sensor_bias=None, seed=None, *, sensed=None):
        if not (math.isfinite(max_substep) and max_substep > 0):
            raise ModelError(f"FDPlant: max_substep must be > 0 [s], found {max_substep!r}")
        self.nodes = int(nodes)
        self.max_substep = float(max_substep)
        super().__init__(model, disturbances, x0, None, sensor_sd, sensor_bias, seed,
                         sensed=sensed)

    def _build(self):
        net = self.network
        nz = net.n_zones
        self.A, self.B, self.C, self.surfaces = fd_matrices(self.model, self.nodes)
        self.n_states = self.A.shape[0]
        self.substeps = max(1, math.ceil(self.dt / self.max_substep - 1e-9))
        self.h = self.dt / self.substeps
        self._kz = net.spec.cp / self.C[:nz]
        self._inv_cz = 1.0 / self.C[:nz]
        self._factors = {}
        self.method = "sdirk3"

    def _rhs(self, ms, Ts, k):
        """(a, b): supply coefficient per zone [1/s] and the constant term [K/s] of step k."""
        nz = self.network.n_zones
        d = self.disturbances
        a = np.asarray(ms, float) * self._kz
        b = self.B @ d.T_boundary[k]
        b[:nz] += a * Ts + d.gains[k] * self._inv_cz
        return a, b

    def _A_u(self, a):
        pad = np.zeros(self.n_states)
        pad[: len(a)] = a
        return (self.A - sp.diags(pad)).tocsr()

    def _solver(self, a):
        key = a.tobytes()
        hit = self._factors.get(key)
        if hit is None:
            if len(self._factors) > 8:
                self._factors.clear()
            A_u = self._A_u(a)
            M = sp.identity(self.n_states, format="csc") - (_G * self.h) * A_u.tocsc()
            hit = (A_u, spla.splu(M).solve)
            self._factors[key] = hit
        return hit

    def _advance(self, ms, Ts, k):
        a, b = self._rhs(ms, Ts, k)
        A_u, solve = self._solver(a)
        h = self.h
        x = self.x
        for _ in range(self.substeps):
            k1 = solve(A_u @ x + b)
            k2 = solve(A_u @ (x + (h * _A21) * k1) + b)
            k3 = solve(A_u @ (x + h * (_B1 * k1 + _B2 * k2)) + b)
            x = x + h * (_B1 * k1 + _B2 * k2 + _G * k3)
        return x

    def steady_state(self, u) -> np.ndarray:
        """Steady finite-volume state [°C] for the constant input vector ``u``."""
        net = self.network
        nz, nb = net.n_zones, len(net.boundary)
        ms, Ts = u[:nz], u[nz:2 * nz]
        Tb, Q = u[2 * nz:2 * nz + nb], u[2 * nz + nb:]
        a = ms * self._kz
        b = self.B @ Tb
        b[:nz] += a * Ts + Q * self._inv_cz
        return spla.spsolve(self._A_u(a).tocsc(), -b)

    def rhs(self, x, ms, Ts, k=None) -> np.ndarray:
        """``dx/dt`` [K/s] at state ``x`` with supply ``ms``, ``Ts`` and step ``k``'s disturbances."""
        a, b = self._rhs(ms, Ts, self.k if k is None else k)
        return self._A_u(a) @ x + b

    def step_responses(self, ms, horizons_h=(1.0, 6.0, 24.0), power: float = 100.0) -> np.ndarray:
        r"""Zone temperature rises after a heat step into each zone, supply held at ``ms``.

        :math:`G(t) = A_u^{-1}(e^{A_u t} - I) B_Q P`, exactly: with the capacitances
        :math:`C`, :math:`S = C^{1/2} A_u C^{-1/2}` is symmetric (a network of
        conductances), so :math:`S = V \Lambda V^T` and
        :math:`G(t) = C^{-1/2} V \,\mathrm{diag}((e^{\lambda t} - 1)/\lambda)\, V^T C^{1/2} B_Q P`.

        Parameters
        ----------
        ms : array_like, shape (n_zones,)
            Supply flow held during the step [kg/s].
        horizons_h : sequence of float
            Times after the step [h].
        power : float
            Step size [W].

        Returns
        -------
        ndarray, shape (len(horizons_h), n_zones, n_zones)
            ``G[h, j, i]``: rise of zone ``j`` [K] at horizon ``h`` after ``power`` W is
            switched on in zone ``i``.
        """
        nz = self.network.n_zones
        A_u = self._A_u(np.asarray(ms, float) * self._kz).toarray()
        s = np.sqrt(self.C)
        S = (s[:, None] * A_u) / s[None, :]
        lam, V = np.linalg.eigh(0.5 * (S + S.T))
        # B_Q P in the symmetric basis: power / C_z on zone z, times C_z^(1/2)
        W = V[:nz].T * (power / s[:nz])[None, :]            # V^T C^(1/2) B_Q P, (n, nz)
        out = np.empty((len(horizons_h), nz, nz))
        for h, t in enumerate(horizons_h):
            f = np.expm1(lam * 3600.0 * t) / lam
            out[h] = (V[:nz] * f[None, :]) @ W / s[:nz, None]
        return out

    def wall_heat_flows(self, x=None) -> np.ndarray:
        """Heat flow from each wall's surfaces into its end nodes [W], shape (n_walls, 2).

        Column 0 flows into end ``a``, column 1 into end ``b`` (spec wall order);
        boundary ends included.
        """
        x = self.x if x is None else np.asarray(x, float)
        n = self.n_states
        Tb = self.disturbances.T_boundary[min(self.k, self.n_steps - 1)]

        def temp(i):
            return x[i] if i < n else Tb[i - n]

        return np.array([[g_a * (x[ca] - temp(ia)), g_b * (x[cb] - temp(ib))]
                         for ia, ca, g_a, ib, cb, g_b in self.surfaces])
