r"""The stochastic grey-box model of a thermal network and its CasADi criteria.

State: the network's states ``x`` (zone air, 3R2C edge states) plus, per measured zone,
an unmeasured heat gain :math:`\phi_z` [kW] that follows a random walk
(:math:`d\phi_z = \sigma_\phi\,d\beta`, the offset-free disturbance model of MPC):

.. math::

    C_z\,dT_z = \Big(\sum g (T_j - T_z) + q_z + Q_z + \textstyle\sum_s a_{z,s} I_s
               + \sum_b \beta_{z,b}\,\varphi_b(t) + \phi_z\Big) dt + \sigma_q\,d\beta_z,
    \qquad y_k = T_{z,k} + v_k,\; v_k \sim N(0, \sigma_v^2).

``q_z = \dot m_s c_p (T_s - \bar T_z)`` is the supply heat. The network is bilinear
(``ms·T``); closed-loop flows change every step, so an exact per-step discretisation
would cost an n×n exponential per step *and per parameter value*. Instead the supply
heat is computed from the *measured* zone temperature (mean of the two samples that
bracket the step, ``supply_temperature="midpoint"``): the model becomes linear
time-invariant, and its exact discretisation and stationary Kalman filter are computed
once per parameter value (see :mod:`.kalman`). The error is the sensor error times
``ms·cp`` (0.02 K · 0.3 kg/s · 1 kJ/(kg K) ≈ 6 W), far below the gains it competes with.
An unmeasured zone keeps the bilinear term at its mean flow in ``A``; the deviation
from it is applied to the mean measured temperature (exact when it has no supply air).

Which samples count (``LikelihoodOptions.fit_rows``): by default only those after 3 h with
no supply air anywhere — in closed loop the logged supply depends on readings the log
does not hold, which biases the likelihood (see :class:`.LikelihoodOptions`).

Parameters (:mod:`.params`): R̄_v (shared or per edge), τ0 = R̄_v·C_v (its bounds are the
paper's :math:`t_{min}/\alpha \le \tau_0 \le t_{max}/\alpha`), noise intensities σ_v, σ_q,
σ_φ, solar apertures on measured ``solar:`` columns, and coefficients of a time-of-day
basis of the gains (occupied/unoccupied levels or Fourier terms); with
``internal_mass`` a capacity factor f_z >= 1 per measured zone (``C_z → f_z·C_z``: every
term of the zone's equation, noise included, is divided by f_z); with ``wall_factors`` a
UA factor per wall class (:func:`thermctl.spec.wall_class`: every conductance of those walls times f,
``R → R/f``; their capacities kept).
"""

from __future__ import annotations

import copy
import dataclasses
import logging
import math
import threading
from types import SimpleNamespace

import casadi as ca
import numpy as np
import scipy.sparse as sp
from scipy.stats import gmean

from ..._parallel import thread_map
from ...errors import DataError, EstimationError
from ...model import RBAR_V_PAPER, ConvectionParameters, ThermalModel
from ...network import ThermalNetwork
from ...spec import WALL_CLASSES, is_outdoor, wall_class
from . import kalman
from ._dense import BufferedFunction, dense_mtimes
from ..data import EstimationData
from ..bounds import RBAR_BOUNDS, T_MAX, T_MIN
from .options import LikelihoodOptions
from .params import Param, ParamLayout

__all__ = ["LikelihoodOptions", "LikelihoodProblem", "T_MIN", "T_MAX", "RBAR_BOUNDS",
           "WALL_CLASSES", "wall_class"]

log = logging.getLogger(__name__)

_KW = 1e-3                      # gains and heat inputs are in kW inside: states O(0.1–1)

class LikelihoodProblem:
    """Likelihood and k-step criterion of a network model on data, as CasADi functions.

    The decision vector ``eta`` is described by :attr:`layout`. Everything that depends on
    the parameters is one CasADi MX graph (discretisation, stationary Riccati solution,
    initial states, filter recursion), so the gradient and the Hessian are exact.

    Parameters
    ----------
    network : ThermalNetwork
        The structure (conduction and convection edges).
    data : EstimationData
    options : LikelihoodOptions, optional
    rbar_v : float or array_like
        Start value of R̄_v [K/(W m)] (shared or per edge).
    c_v : float or None
        Start value of C_v [J/K]; default: τ0 at the geometric mean of its bounds.
    init : dict, optional
        Start values by parameter name (natural units), e.g. from a previous fit.

    Attributes
    ----------
    layout : ParamLayout
    n_obs : int
        Scalar observations in the likelihood.
    n_restarts : int
        k-step restarts.
    """

    def __init__(self, network: ThermalNetwork, data: EstimationData, options: LikelihoodOptions | None = None,
                 *, rbar_v=RBAR_V_PAPER, c_v=None, init: dict | None = None):
        self.options = opt = options or LikelihoodOptions()
        opt.check()
        data.check(network)
        self.network = network
        self.data = data
        self.model = ThermalModel(network)
        self.sym = self.model.sym
        net = network
        self.zones = list(net.zones)
        self.nz, self.nb = net.n_zones, len(net.boundary)
        self.n_net = net.n_states
        self.meas = [self.zones.index(z) for z in data.zones]
        self.ny = len(self.meas)
        if self.ny == 0:
            raise DataError("no measured zone temperature in the data")
        self.n_d = self.ny if opt.disturbance == "random_walk" else 0
        self.n_e = self.ny if opt.measurement == "ar1" else 0
        self.bnoise = self._boundary_noise_nodes()
        self.n_b = len(self.bnoise)
        self.n_g = self.ny if opt.fast_gain else 0
        self.n_c = int(opt.common_gain)
        self.n = self.n_net + self.n_d + self.n_e + self.n_b + self.n_g + self.n_c
        self.nw = self.nz + self.nb
        self.edges = net.convection_edges
        self.alpha = float(opt.alpha if opt.alpha is not None else net.spec.alpha())
        self.tau_bounds = (opt.t_min / self.alpha, opt.t_max / self.alpha)
        self.cap_z = 1.0 / np.asarray(self.sym.inv_cz, dtype=float)
        self.wall_classes = self._wall_classes()
        self._prepare_inputs()
        self._make_layout(rbar_v, c_v, init or {})
        self._make_chunks()
        self._setup_graphs()

    # ------------------------------------------------------------------ data → arrays
    def _prepare_inputs(self):
        d, net, opt = self.data, self.network, self.options
        sl = net.input_slices()
        U, Y = d.U, d.Y
        N = len(d)
        cp = net.spec.cp
        ms, Ts, Tb, Q = U[:, sl["ms"]], U[:, sl["Ts"]], U[:, sl["T"]], U[:, sl["Q"]]
        Tbar = Y.copy()
        if opt.supply_temperature == "midpoint" and N > 1:
            nxt = np.vstack([Y[1:], Y[-1:]])
            Tbar = np.where(np.isfinite(nxt), 0.5 * (Y + nxt), Y)
        if self.ny:
            # the mean of the finite readings per row, NaN where none is (a gap, or a
            # resample's dropped days): np.nanmean would warn on every such row, and a
            # warnings filter around it is not thread-safe (problems are built in threads)
            ok = np.isfinite(Tbar)
            cnt = ok.sum(axis=1)
            Tref = np.where(cnt > 0, np.where(ok, Tbar, 0.0).sum(axis=1) / np.maximum(cnt, 1),
                            np.nan)
        else:
            Tref = np.full(N, 20.0)
        heat = Q.copy()
        # for k-step predictions the supply heat uses the *predicted* temperature:
        # heat(T̂) = heat(T̄) − ms·cp·(T̂ − T̄) (explicit over a step; C_z/(ms cp) ≫ dt)
        self.sup_gain = np.zeros((N, self.ny))      # ms·cp [kW/K] of measured zones
        self.Tbar = np.nan_to_num(Tbar)
        self.d_sup = np.zeros(self.n_net)
        valid = d.valid() & np.isfinite(Tbar).all(axis=1)
        for i, z in enumerate(self.zones):
            if i in self.meas:
                j = self.meas.index(i)
                heat[:, i] += ms[:, i] * cp * (Ts[:, i] - Tbar[:, j])
                self.sup_gain[:, j] = ms[:, i] * cp * _KW
            else:
                mbar = float(np.mean(ms[valid, i])) if valid.any() else 0.0
                self.d_sup[i] = mbar * self.sym.kz[i]
                heat[:, i] += ms[:, i] * cp * Ts[:, i] - (ms[:, i] - mbar) * cp * Tref
        self.W0 = np.vstack([heat.T * _KW, Tb.T])                         # (nw, N)
        # loop_gain: the measured zones with supply air (measured index), and the rows in
        # which any of them has it on (their loops act there)
        self.loop_zones = []
        self.on_rows = np.zeros(N, dtype=bool)
        if opt.loop_gain:
            self.loop_zones = [j for j, i in enumerate(self.meas) if np.any(ms[valid, i] > 1e-9)]
            if self.loop_zones:
                cols = [self.meas[j] for j in self.loop_zones]
                self.on_rows = np.any(ms[:, cols] > 1e-9, axis=1)
            else:
                log.info("loop_gain: no measured zone has supply air; no loop term")
        self.fit_rows = self._fit_rows(ms)
        self.valid = valid & np.isfinite(self.W0).all(axis=0)
        # deterministic basis rows: solar columns, then time-of-day functions
        rows, names = [], []
        self.solar_zones = self._solar_zones()
        self.solar_zones_idx = [self.zones.index(z) for z in self.solar_zones]
        for s, name in enumerate(d.solar_names):
            rows.append(d.solar[:, s])
            names.append(("solar", name))
        self.basis_zones = [self.solar_zones_idx] * len(rows)
        for name, row, zones in self._time_basis(N):
            rows.append(row)
            names.append(("time", name))
            self.basis_zones.append(zones)
        self.basis_rows = names
        self.Bas = np.vstack(rows) if rows else np.zeros((0, N))
        self.Y = Y

    def _wall_classes(self) -> list[str]:
        """Class of every conduction edge, in network order (:func:`wall_class`).

        A network may override classes with an attribute ``wall_classes`` =
        ``{edge name: class}`` (a local problem whose neighbour zones are boundary nodes
        keeps their partitions as ``partition``).
        """
        over = getattr(self.network, "wall_classes", None) or {}
        bad = {k: v for k, v in over.items() if v not in WALL_CLASSES}
        if bad:
            raise EstimationError(f"wall_classes: unknown class(es) {bad}; classes are "
                                  f"{WALL_CLASSES}")
        zones = set(self.zones)
        return [over.get(e.name) or wall_class(e.a, e.b, zones)
                for e in self.network.conduction_edges]

    def _wall_matrices(self, cls: str):
        """``(A_k, Bt_k)``: the part of the network's ``A`` and ``Bt`` that the walls of
        class ``cls`` contribute at the spec's resistances (numeric, sparse)."""
        net = self.network
        nx, nz = self.n_net, self.nz
        cap = net.fixed_capacitances()
        index = {z: i for i, z in enumerate(self.zones)}
        index.update({b: nx + j for j, b in enumerate(net.boundary)})
        A = sp.lil_matrix((nx, nx))
        Bt = sp.lil_matrix((nx, self.nb))
        wall = iter(self.wall_classes)
        for k, e in enumerate(net.edges):
            if e.kind != "conduction":
                continue
            if next(wall) != cls:
                continue
            s1, s2 = nz + 2 * k, nz + 2 * k + 1
            for (i, j), r in zip(((index[e.a], s1), (s1, s2), (s2, index[e.b])), e.R):
                g = 1.0 / r
                for s, t in ((i, j), (j, i)):
                    if s >= nx:
                        continue           # boundary nodes have no equation
                    A[s, s] -= g / cap[s]
                    if t < nx:
                        A[s, t] += g / cap[s]
                    else:
                        Bt[s, t - nx] += g / cap[s]
        return A.tocsc(), Bt.tocsc()

    def _boundary_noise_nodes(self):
        rule = self.options.boundary_noise
        bnd = list(self.network.boundary)
        if rule is None or rule is False:
            return []
        if rule == "all":
            return list(range(len(bnd)))
        if rule == "outdoor":
            return [j for j, b in enumerate(bnd) if is_outdoor(b)]
        bad = [b for b in rule if b not in bnd]
        if bad:
            raise EstimationError(f"boundary_noise: {bad} are not boundary nodes ({bnd})")
        return [bnd.index(b) for b in rule]

    def _fit_rows(self, ms):
        """Rows whose innovations enter the likelihood (see ``LikelihoodOptions.fit_rows``)."""
        rule = self.options.fit_rows
        N = len(ms)
        if isinstance(rule, str):
            if rule not in ("all", "supply_off", "auto"):
                raise EstimationError(f"fit_rows must be 'auto', 'all', 'supply_off' or a boolean "
                                      f"array, found {rule!r}")
            if rule == "all":
                self.fit_rule = "all"
                return np.ones(N, dtype=bool)
            off = np.all(ms <= 1e-9, axis=1)
            # y_k is predicted through the input of row k-1; count it once the supply has
            # been off for `holdoff` (the filter first forgets the closed loop)
            h = 1 + int(round(self.options.holdoff / self.data.dt))
            run = np.zeros(N, dtype=int)
            for k in range(1, N):
                run[k] = run[k - 1] + 1 if off[k - 1] else 0
            out = run >= h
            if rule == "auto" and out.sum() < max(0.15 * N, 86400.0 / self.data.dt):
                log.info("fit_rows='auto': only %d of %d samples follow %g h without supply air; "
                         "using all samples", int(out.sum()), N, self.options.holdoff / 3600)
                self.fit_rule = "all"
                return np.ones(N, dtype=bool)
            self.fit_rule = "supply_off"
            return out
        out = np.asarray(rule, dtype=bool)
        if out.shape != (N,):
            raise EstimationError(f"fit_rows: expected {N} booleans (one per row), found shape "
                                  f"{out.shape}")
        self.fit_rule = "given"
        return out

    def _solar_zones(self):
        sol = self.options.solar
        if not self.data.solar_names or sol is False or sol is None:
            return []
        if sol is True or sol == "auto":
            return list(self.zones)
        bad = [z for z in sol if z not in self.zones]
        if bad:
            raise EstimationError(f"solar: zone(s) {bad} are not zones of the network")
        return list(sol)

    def _time_basis(self, N):
        """Deterministic gain rows: ``(name, row, zone indices)``."""
        opt = self.options
        unmeas = [i for i in range(self.nz) if i not in self.meas] if opt.unmeasured_gain else []
        # with random-walk gains a constant input anywhere is observationally equivalent
        # to shifted gains (the filter starts at the matching steady state): no constant
        const_zones = list(self.meas) + unmeas if opt.disturbance == "none" else []
        out = []
        if const_zones:
            out.append(("const", np.ones(N), const_zones))
        if opt.basis is None:
            return out
        t = self.data.time
        if t is None:
            raise DataError(f"basis={opt.basis!r} needs time stamps; the data has none")
        hour = np.asarray(t.hour + t.minute / 60.0 + t.second / 3600.0, dtype=float)
        zones = list(self.meas) + unmeas
        if opt.basis == "levels":
            h0, h1 = opt.occupied_hours
            occ = (hour >= h0) & (hour < h1)
            if opt.weekdays_only:
                occ &= np.asarray(t.day_of_week < 5)
            out.append(("occupied", occ.astype(float), zones))
        else:
            for k in range(1, opt.harmonics + 1):
                out.append((f"cos{k}", np.cos(2 * np.pi * k * hour / 24.0), zones))
                out.append((f"sin{k}", np.sin(2 * np.pi * k * hour / 24.0), zones))
        return out

    # ------------------------------------------------------------------ parameters
    def _make_layout(self, rbar_v, c_v, init):
        opt, lay = self.options, ParamLayout()
        m = len(self.edges)
        lo_r, hi_r = opt.rbar_bounds
        lo_t, hi_t = self.tau_bounds
        self.i_rbar, self.i_tau = [], None
        if m:
            rb = np.broadcast_to(np.asarray(rbar_v, dtype=float), (m,))
            if opt.per_edge:
                for e, r in zip(self.edges, rb):
                    self.i_rbar.append(lay.add(Param(ConvectionParameters.key(e.name), "rbar_v", True,
                                                     float(np.clip(r, lo_r, hi_r)), lo_r, hi_r)))
            else:
                r0 = float(gmean(rb))
                self.i_rbar = [lay.add(Param("rbar_v", "rbar_v", True, float(np.clip(r0, lo_r, hi_r)),
                                             lo_r, hi_r))] * m
            t0 = math.sqrt(lo_t * hi_t) if c_v is None else float(gmean(rb)) * c_v
            self.i_tau = lay.add(Param("tau0", "tau0", True, float(np.clip(t0, lo_t, hi_t)), lo_t, hi_t))
        shared = opt.noise == "shared"
        mz = [self.zones[i] for i in self.meas]
        cz_med = float(np.median(self.cap_z))
        sq0 = 0.02 * cz_med / math.sqrt(self.data.dt)    # ≈ 0.02 K of white wander per step
        if shared:
            self.i_sv = [lay.add(Param("sigma_v", "sigma_v", True, 0.02, 1e-4, 2.0))] * self.ny
            self.i_sq = [lay.add(Param("sigma_q", "sigma_q", True, sq0, 1e-1, 1e7))] * self.nz
        else:
            self.i_sv = [lay.add(Param(f"sigma_v[{z}]", "sigma_v", True, 0.02, 1e-4, 2.0)) for z in mz]
            self.i_sq = [lay.add(Param(f"sigma_q[{z}]", "sigma_q", True, sq0, 1e-1, 1e7))
                         for z in self.zones]
        self.i_sphi = []
        if self.n_d:
            s0 = 100.0 / 60.0    # 100 W per hour
            if shared:
                self.i_sphi = [lay.add(Param("sigma_phi", "sigma_phi", True, s0, 1e-3, 1e3))] * self.ny
            else:
                self.i_sphi = [lay.add(Param(f"sigma_phi[{z}]", "sigma_phi", True, s0, 1e-3, 1e3))
                               for z in mz]
        self.i_occ = None       # occupied-hours ratio of the gains' noise intensity
        if opt.gain_schedule is not None:
            self.i_occ = lay.add(Param("occ_ratio", "occ_ratio", True, 2.0, 1e-2, 1e3))
        # loop gain per measured zone with supply air [W/K]; its lower bound is no loop at
        # all for a zone (0.01 W/K against walls and air paths of 10-100 W/K)
        self.i_loop = [lay.add(Param(f"loop_gain[{self.zones[self.meas[j]]}]", "loop_gain", True,
                                     10.0, 1e-2, 1e4)) for j in self.loop_zones]
        if self.n_b:
            self.i_sigb = lay.add(Param("sigma_b", "sigma_b", True, 0.2, 1e-3, 5.0))
            self.i_taub = lay.add(Param("tau_b", "tau_b", True, 3600.0, 300.0, 86400.0))
        if self.n_e:
            self.i_sige = lay.add(Param("sigma_e", "sigma_e", True, 0.015, 1e-4, 1.0))
            self.i_taue = lay.add(Param("tau_e", "tau_e", True, 1800.0, 60.0, 86400.0))
        if self.n_g:
            self.i_sigg = lay.add(Param("sigma_g", "sigma_g", True, 50.0, 1.0, 5e3))
            self.i_taug = lay.add(Param("tau_g", "tau_g", True, 1800.0, 600.0, 6 * 3600.0))
        self.i_load = []        # (zone j, gain k, parameter index) of loading[z,ck]
        if self.n_c:
            self.i_tauc = lay.add(Param("tau_c", "tau_c", True, 3600.0, 600.0, 2 * 86400.0))
            for k in range(self.n_c):
                # the gains share τ_c and unit variance, so the likelihood sees the loadings
                # only through λλᵀ: any rotation of λ's columns fits alike. Gain k has no
                # loading on the first k measured zones (a lower-triangular λ, the usual
                # factor-analysis choice), which leaves one λ per λλᵀ up to signs.
                # Start values not 0: λ = 0 is a stationary point the optimiser would not
                # leave; alternating signs keep a second gain off the first one's direction.
                for j, z in enumerate(mz):
                    if j < k:
                        continue
                    l0 = 50.0 if k == 0 else 50.0 * (-1.0) ** j
                    self.i_load.append((j, k, lay.add(Param(f"loading[{z},c{k + 1}]", "loading",
                                                            False, l0, -5e3, 5e3, 100.0))))
        self.i_cf = []          # capacity factor per measured zone (internal_mass)
        if opt.internal_mass:
            lo_f, hi_f = opt.cap_factor_bounds
            # start at 2, not on the bound 1: L-BFGS-B starting on a bound with a small
            # gradient there may never leave it
            f0 = float(np.clip(2.0, lo_f, hi_f))
            self.i_cf = [lay.add(Param(f"cap_factor[{z}]", "cap_factor", True, f0, lo_f, hi_f))
                         for z in mz]
        self.i_ua, self.ua_classes, self.ua_mats = [], [], []    # UA factor per wall class
        if opt.wall_factors:
            lo_u, hi_u = opt.ua_factor_bounds
            for cls in WALL_CLASSES:
                if cls in self.wall_classes:
                    self.ua_classes.append(cls)
                    self.i_ua.append(lay.add(Param(f"ua_factor[{cls}]", "ua_factor", True,
                                                   1.0, lo_u, hi_u)))
                    self.ua_mats.append(self._wall_matrices(cls))
            if not self.i_ua:
                log.info("wall_factors: the network has no wall; no UA factor")
        self.i_nu = None        # degrees of freedom of t innovations, when fitted
        if opt.innovations == "student" and opt.nu == "fit":
            lo_n, hi_n = opt.nu_bounds
            self.i_nu = lay.add(Param("nu", "nu", True, float(np.clip(5.0, lo_n, hi_n)),
                                      lo_n, hi_n))
        # linear parameters: entries of Theta (nz × n_basis)
        self.lin = []          # (param index, zone index, basis row)
        for b, (kind, name) in enumerate(self.basis_rows):
            if kind == "solar":
                for z in self.solar_zones:
                    i = lay.add(Param(f"aperture[{z},{name}]", "aperture", False, 0.5, 0.0, 50.0, 1.0))
                    self.lin.append((i, self.zones.index(z), b))
            else:
                for zi in self.basis_zones[b]:
                    z = self.zones[zi]
                    i = lay.add(Param(f"gain[{z},{name}]", "gain", False, 0.0, -5e3, 5e3, 100.0))
                    self.lin.append((i, zi, b))
        for name, v in init.items():
            if name in lay.names:
                p = lay.params[lay.index(name)]
                p.init = float(np.clip(v, p.lower, p.upper))
        self.layout = lay

    def _occupied_rows(self) -> np.ndarray:
        """Rows in the options' ``occupied_hours`` (every day), for ``gain_schedule``."""
        t = self.data.time
        if t is None:
            raise DataError("gain_schedule='occupied' needs time stamps; the data has none")
        hour = np.asarray(t.hour + t.minute / 60.0 + t.second / 3600.0, dtype=float)
        h0, h1 = self.options.occupied_hours
        return (hour >= h0) & (hour < h1) if h0 <= h1 else (hour >= h0) | (hour < h1)

    # ------------------------------------------------------------------ chunk layout
    def _make_chunks(self):
        opt, dt = self.options, self.data.dt
        ok = np.r_[False, self.valid, False].astype(np.int8)
        e = np.flatnonzero(np.diff(ok))
        self.burn = int(round(opt.burn_in / dt))
        segs = [(int(a), int(b)) for a, b in zip(e[::2], e[1::2]) if b - a > self.burn + 1]
        dropped = sum(1 for a, b in zip(e[::2], e[1::2]) if b - a <= self.burn + 1)
        if dropped:
            log.info("%d data segment(s) no longer than the burn-in (%g h) left out", dropped,
                     opt.burn_in / 3600)
        if not segs:
            raise DataError(f"no gap-free stretch of data longer than the burn-in "
                            f"({opt.burn_in / 3600:g} h); {int(self.valid.sum())} valid rows")
        self.segments = segs
        n_tot = sum(b - a for a, b in segs)
        L = 2 ** int(round(math.log2(max(math.sqrt(n_tot), 4.0))))
        L = int(min(max(L, 8), 256))
        if opt.gain_schedule is not None or self.i_loop:
            # about an hour of rows: a chunk whose regime changes is chained step by step,
            # so short chunks keep most of them in one regime (twin house, 10-min data:
            # 120 ms an evaluation with 8 rows, 149 ms with 64)
            L = min(L, max(4, 2 ** int(round(math.log2(max(3600.0 / dt, 1.0))))))
        self.L = L
        chunk_seg, chunk_off = [], []
        for s, (a, b) in enumerate(segs):
            for o in range(0, b - a, L):
                chunk_seg.append(s)
                chunk_off.append(o)
        M = len(chunk_seg)
        self.M = M
        self.restart = [s if o == 0 else -1 for s, o in zip(chunk_seg, chunk_off)]
        tmap = np.full(L * M, -1, dtype=int)       # data row of each layout column
        first = np.zeros(L * M, dtype=int)
        for c, (s, o) in enumerate(zip(chunk_seg, chunk_off)):
            a, b = segs[s]
            for j in range(L):
                t = a + o + j
                if t < b:
                    tmap[j * M + c] = t
                    first[j * M + c] = a
        self.tmap = tmap
        live = tmap >= 0
        # regime (0, or 1 in occupied hours) of every row and layout column
        self.row_regime = np.zeros(len(self.valid), dtype=int)
        self.regime = None
        if opt.gain_schedule is not None or self.i_loop:
            # regime 1: occupied hours (gain schedule), or the supply on (loop gain)
            self.row_regime = (self._occupied_rows() if opt.gain_schedule is not None
                               else self.on_rows).astype(int)
            self.regime = np.where(live, self.row_regime[np.maximum(tmap, 0)], 0)
        use = np.zeros(L * M, dtype=bool)
        use[live] = self.fit_rows[tmap[live]]
        self.mask = (live & use & (tmap - first >= self.burn)).astype(float)
        self.n_cols = int(self.mask.sum())
        self.n_obs = self.n_cols * self.ny
        self.pos = {int(t): k for k, t in enumerate(tmap) if t >= 0}

        def lay(A):
            out = np.zeros((A.shape[0], L * M))
            out[:, live] = A[:, tmap[live]]
            return out

        self.W0_lay = lay(self.W0)
        self.B_lay = lay(self.Bas)
        self.Y_lay = lay(np.nan_to_num(self.Y.T))
        # k-step restarts
        H = max(1, int(round(opt.horizon / dt)))
        stride = max(1, int(round((opt.stride or opt.horizon) / dt)))
        self.H = H
        ok_rows = self.fit_rows
        starts = [t for a, b in segs for t in range(a + self.burn, b - H, stride)
                  if ok_rows[t + 1:t + H + 1].all()]
        self.n_restarts = len(starts)
        self.kstarts = np.array(starts, dtype=int)
        # steady initial state windows: the first day of every segment
        day = max(1, int(round(86400.0 / dt)))
        self.seg_means = []
        for a, b in segs:
            w = slice(a, min(b, a + day))
            self.seg_means.append((self.Y[w].mean(axis=0), self.W0[:, w].mean(axis=1),
                                   self.Bas[:, w].mean(axis=1), self.Y[a], self.W0[:, a]))

    # ------------------------------------------------------------------ the graph
    def _theta_net(self, eta):
        """Network parameter vector p (MX) from eta."""
        m = len(self.edges)
        if not m:
            return ca.MX(0, 1)
        lr = ca.vertcat(*[eta[i] for i in self.i_rbar])
        rb = ca.exp(lr)
        cv = ca.exp(eta[self.i_tau] - lr)
        return ca.vertcat(rb, cv)

    def _inv_factor(self, eta):
        """``1/f`` per network state (MX column): 1 except the measured zones' capacity
        factors (``internal_mass``); ``None`` without them."""
        if not self.i_cf:
            return None
        P = np.zeros((self.n_net, self.ny))
        P[self.meas, np.arange(self.ny)] = 1.0
        rest = np.ones(self.n_net)
        rest[self.meas] = 0.0
        inv_f = ca.exp(-ca.vertcat(*[eta[i] for i in self.i_cf]))
        return ca.mtimes(ca.DM(P), inv_f) + ca.DM(rest)

    def zone_capacitances(self, eta) -> np.ndarray:
        """Capacitance of every zone at ``eta`` [J/K] (the spec's, times the fitted factor)."""
        cap = self.cap_z.copy()
        if self.i_cf:
            cap[self.meas] *= np.exp(np.asarray(eta, float)[self.i_cf])
        return cap

    def _continuous(self, eta):
        n, n_net, nz = self.n, self.n_net, self.nz
        A, Bt = self.sym.AB(self._theta_net(eta))
        for i, (Ak, Bk) in zip(self.i_ua, self.ua_mats):
            # the class's walls enter A and Bt linearly in their conductances: f·G_k is
            # the spec's part plus (f − 1)·G_k (exactly the spec's at f = 1)
            g = ca.exp(eta[i]) - 1.0
            A = A + g * ca.DM(Ak)
            Bt = Bt + g * ca.DM(Bk)
        A = A - ca.DM(sp.diags(self.d_sup).tocsc())
        inv_cz_kw = np.asarray(self.sym.inv_cz, dtype=float) / _KW     # kW → K/s
        Sq = np.zeros((n_net, nz))
        Sq[np.arange(nz), np.arange(nz)] = inv_cz_kw
        B = ca.horzcat(ca.DM(Sq), Bt)
        s = self._inv_factor(eta)
        if s is not None:
            # every term of a zone's equation is divided by its capacitance: a factor f_z
            # scales the zone's row of A, B (heat, walls, boundaries) and of its gain and
            # heat-noise inputs by 1/f_z
            Sd = ca.diag(s)
            A, B, Bt = ca.mtimes(Sd, A), ca.mtimes(Sd, B), ca.mtimes(Sd, Bt)

        def to_zones(n_y):
            """(n_y, measured zones): a heat [kW] into each measured zone's temperature,
            divided by its capacitance (times its factor)."""
            P = np.zeros((n_y, self.ny))
            P[self.meas, np.arange(self.ny)] = inv_cz_kw[self.meas]
            P = ca.DM(P)
            if s is None:
                return P
            return ca.mtimes(ca.diag(ca.vertcat(s, ca.DM.ones(n_y - n_net))), P)

        def first_order(A, B, E, tau, q):
            """``A``, ``B`` with ``E.shape[1]`` first-order states appended: ``−x/τ`` each,
            feeding the states before through ``E``, noise intensity ``q`` each."""
            k = E.shape[1]
            diag.append(ca.repmat(q, k, 1))
            A = ca.blockcat([[A, E], [ca.MX(k, A.shape[0]), -ca.MX.eye(k) / tau]])
            return A, ca.vertcat(B, ca.MX(k, self.nw))

        n_x = n_net + self.n_d          # states before the sensor-error block
        if self.n_d:
            A = ca.vertcat(ca.horzcat(A, to_zones(n_net)), ca.MX(self.n_d, n_x))
            B = ca.vertcat(B, ca.MX(self.n_d, self.nw))
        sq = ca.vertcat(*[ca.exp(eta[i]) for i in self.i_sq]) * ca.DM(np.asarray(self.sym.inv_cz, float))
        if s is not None:
            sq = sq * s[:nz]
        diag = [sq ** 2, ca.MX(n_net - nz, 1)]
        if self.n_d:
            diag.append((ca.vertcat(*[ca.exp(eta[i]) for i in self.i_sphi]) * _KW) ** 2)
        if self.n_e:
            tau_e = ca.exp(eta[self.i_taue])
            sig_e = ca.exp(eta[self.i_sige])
            A, B = first_order(A, B, ca.MX(n_x, self.n_e), tau_e, 2 * sig_e ** 2 / tau_e)
        if self.n_b:
            # boundary temperature error b: the walls see T_b + b (sensor placement, sun
            # on the facade, gusts): a disturbance common to every zone on that boundary
            tau_b = ca.exp(eta[self.i_taub])
            sig_b = ca.exp(eta[self.i_sigb])
            Eb = ca.vertcat(Bt[:, self.bnoise], ca.MX(A.shape[0] - n_net, self.n_b))
            A, B = first_order(A, B, Eb, tau_b, 2 * sig_b ** 2 / tau_b)
        if self.n_g:
            # fast gain g (kW) per measured zone: dg = −g/τ_g dt + √(2/τ_g)·σ_g dW, heating
            # its zone like the random walk does
            tau_g = ca.exp(eta[self.i_taug])
            sig_g = ca.exp(eta[self.i_sigg]) * _KW
            A, B = first_order(A, B, to_zones(A.shape[0]), tau_g, 2 * sig_g ** 2 / tau_g)
        if self.n_c:
            # common gains c_k (unit variance): dc = −c/τ_c dt + √(2/τ_c) dW, heating
            # measured zone z by loading[z,ck]·c_k (kW inside)
            tau_c = ca.exp(eta[self.i_tauc])
            scale = self.layout.params[self.i_load[0][2]].scale * _KW
            Sel = np.zeros((self.ny * self.n_c, len(self.i_load)))
            for col, (j, k, _) in enumerate(self.i_load):
                Sel[j + self.ny * k, col] = scale
            vals = ca.vertcat(*[eta[i] for _, _, i in self.i_load])
            lam = ca.reshape(ca.mtimes(ca.DM(Sel), vals), self.ny, self.n_c)
            A, B = first_order(A, B, ca.mtimes(to_zones(A.shape[0]), lam), tau_c, 2.0 / tau_c)
        Sig = ca.diag(ca.vertcat(*diag))
        R = ca.diag(ca.vertcat(*[ca.exp(2 * eta[i]) for i in self.i_sv]))
        return A, B, Sig, R

    def _theta_basis(self, eta):
        nb_rows = self.Bas.shape[0]
        if not self.lin:
            return ca.MX(self.nz, nb_rows)
        S = np.zeros((self.nz * nb_rows, len(self.lin)))
        vals = []
        for k, (i, zi, b) in enumerate(self.lin):
            S[zi + self.nz * b, k] = self.layout.params[i].scale
            vals.append(eta[i])
        return ca.reshape(ca.mtimes(ca.DM(S), ca.vertcat(*vals)), self.nz, nb_rows)

    def _initial_states(self, A, B, ThB, eta):
        n_net, meas = self.n_net, self.meas
        rest = [i for i in range(n_net) if i not in meas]
        Anet = A[:n_net, :n_net]
        Bnet = B[:n_net, :]
        cols = []
        for s, (a, b) in enumerate(self.segments):
            ybar, w0bar, bbar, y_a, w_a = self.seg_means[s]
            if self.options.initial_state == "paper":
                Tz = np.full(self.nz, np.nan)
                Tz[meas] = y_a
                x = self.model.initial_state(Tz, w_a[self.nz:])
                extra = self.n_d + self.n_e + self.n_b + self.n_g + self.n_c
                cols.append(ca.DM(np.r_[x, np.zeros(extra)]))
                continue
            wbar = ca.DM(w0bar) + ca.vertcat(_KW * ca.mtimes(ThB, ca.DM(bbar)), ca.DM.zeros(self.nb))
            bvec = ca.mtimes(Bnet, wbar)
            rhs = ca.mtimes(Anet[rest, meas], ca.DM(ybar)) + bvec[rest]
            xr = -ca.solve(Anet[rest, rest], rhs)
            PK = np.zeros((n_net, self.ny))
            PK[meas, np.arange(self.ny)] = 1.0
            PR = np.zeros((n_net, len(rest)))
            PR[rest, np.arange(len(rest))] = 1.0
            x0 = ca.mtimes(ca.DM(PK), ca.DM(y_a)) + ca.mtimes(ca.DM(PR), xr)
            if self.n_d:
                imb = ca.mtimes(Anet[meas, meas], ca.DM(ybar)) + ca.mtimes(Anet[meas, rest], xr) \
                    + bvec[meas]
                cap = ca.DM(self.cap_z[meas])
                if self.i_cf:      # A's zone rows are divided by f: the imbalance in W is C·f·imb
                    cap = cap * ca.exp(ca.vertcat(*[eta[i] for i in self.i_cf]))
                phi = -imb * cap * _KW
                x0 = ca.vertcat(x0, phi)
            rest_n = self.n_e + self.n_b + self.n_g + self.n_c
            if rest_n:
                x0 = ca.vertcat(x0, ca.DM.zeros(rest_n))
            cols.append(x0)
        return ca.horzcat(*cols)

    def _norm_bound(self):
        """Upper bound of ‖A‖₁·dt over the parameter box (fastest corner: smallest R̄_v, τ0)."""
        m = len(self.edges)
        if m:
            r = self.options.rbar_bounds[0]
            p = np.r_[np.full(m, r), np.full(m, self.tau_bounds[0] / r)]
        else:
            p = np.zeros(0)
        A, _ = self.sym.AB(p)
        A = np.asarray(ca.densify(A)) - np.diag(self.d_sup)
        for j, i in zip(self.loop_zones, self.i_loop):      # every loop at its largest gain
            z = self.meas[j]
            A[z, z] -= self.layout.params[i].upper * float(self.sym.inv_cz[z])
        if self.i_ua:      # every class at its largest conductance
            hi = self.options.ua_factor_bounds[1]
            A = A + sum((hi - 1.0) * Ak.toarray() for Ak, _ in self.ua_mats)
        return 1.1 * np.abs(A).sum(axis=0).max() * self.data.dt

    def _setup_graphs(self):
        """The criteria's CasADi graphs, one per number of squarings (made on first use; the
        start's at once, so that a problem that cannot be built fails where it is made).

        The discretisation's squarings were once set by the parameter box's fastest corner
        (every R̄_v at its lower bound: ‖A‖₁·dt ≈ 5e4 on the twin house N2, 18 squarings),
        where the fits never go: at the fitted values ‖A‖₁·dt is 427 (11 squarings), and a
        gradient took 50.6 ms with 18 squarings against 44.9 ms with 11 (the value 2e-8 apart
        of 45 248, the fewer squarings the closer to exact). Each evaluation now takes the
        graph of the squarings its own ``eta`` needs (:meth:`squarings_at`): the value at an
        ``eta`` does not depend on what was evaluated before, so threads and serial runs
        give the same numbers.
        """
        self.box_squarings = kalman.n_squarings(self._norm_bound())
        C = self.zone_pick
        if self.n_e:
            C[np.arange(self.ny), self.n_net + self.n_d + np.arange(self.ny)] = 1.0
        self.C = C
        eta = ca.MX.sym("eta", len(self.layout))
        A = self._continuous(eta)[0]
        norm = ca.mmax(ca.sum1(ca.fabs(A)))
        if self.i_loop:
            norm = ca.fmax(norm, ca.mmax(ca.sum1(ca.fabs(self._loop_A(A, eta)[0]))))
        # the same 10 % above the 1-norm as the box bound (:meth:`_norm_bound`)
        self._norm_fn = ca.Function("norm_dt", [eta], [1.1 * self.data.dt * norm])
        self._graphs = {}
        self._graphs_lock = threading.Lock()
        self._graph(self.layout.eta0())

    def squarings_at(self, eta) -> int:
        """Halvings of the step that bring ``‖A(eta)‖₁·dt`` (plus 10 %) below 1/4, at most
        the box's (:attr:`box_squarings`)."""
        nd = float(self._norm_fn(np.asarray(eta, float)))
        if not np.isfinite(nd):
            return self.box_squarings
        return min(self.box_squarings, kalman.n_squarings(nd))

    def _graph(self, eta=None):
        """The graph for ``eta`` (:meth:`squarings_at`); ``None``: the box's, valid over the
        whole parameter box (for a solver that cannot switch graphs, IPOPT)."""
        s = self.box_squarings if eta is None else self.squarings_at(eta)
        g = self._graphs.get(s)
        if g is None:
            with self._graphs_lock:
                g = self._graphs.get(s)
                if g is None:
                    g = self._graphs[s] = self._make_graph(s)
        return g

    @property
    def _eta(self):
        return self._graph().eta

    @property
    def _nll(self):
        return self._graph().nll

    @property
    def _kstep(self):
        return self._kstep_of(self._graph())

    def _make_graph(self, squarings: int) -> SimpleNamespace:
        g = SimpleNamespace(squarings=squarings)
        npar = len(self.layout)
        eta = ca.MX.sym("eta", npar)
        A, B, Sig, R = self._continuous(eta)
        two = self.regime is not None          # two regimes: gain schedule or loop gain
        sched = self.i_occ is not None
        loop = bool(self.i_loop)
        Phi, Gam, Qd = kalman.discretize(A, B, Sig, self.data.dt, squarings)
        if loop:
            Phi1, Gam1, GamY, Qd1 = self._loop_discretized(A, B, Sig, eta, squarings)
        if sched:
            # in occupied hours the random-walk gains' increments over a step have
            # ratio × their variance σ_φ²·dt: the excess enters the gain states at the
            # sample (a discrete-time term). Its effect on the temperatures within the
            # step is left out: discretising it with Van Loan like Σ costs three n×n
            # products per Taylor stage and squaring (twin house: 30 % of an evaluation)
            gsel = np.zeros(self.n)
            gsel[self.n_net:self.n_net + self.n_d] = self.data.dt
            Qd_occ = Qd + (ca.exp(eta[self.i_occ]) - 1.0) * ca.diag(ca.diag(Sig) * ca.DM(gsel))
        C = ca.DM(self.C)
        g.dare = None
        if self.options.riccati == "implicit":
            # kept with the graph: the CasADi graph only holds a reference to the callback
            g.dare = kalman.DareCallback(f"dare_{id(self):x}_{squarings}", self.C)
        P, S, Kf, change = kalman.stationary_filter(Phi, C, Qd, R, self.options.sda_iterations,
                                                    g.dare)
        ThB = self._theta_basis(eta)
        X0 = self._initial_states(A, B, ThB, eta)
        PhiK = ca.mtimes(Phi, Kf)
        F = Phi - ca.mtimes(PhiK, C)
        ThB_full = ca.vertcat(ThB, ca.MX(self.nb, ThB.shape[1]))
        W = ca.DM(self.W0_lay) + _KW * ca.mtimes(ThB_full, ca.DM(self.B_lay))
        occ_extra = []
        if two:
            # a second stationary filter, for the occupied hours (gain schedule: the same
            # dynamics, more gain noise) or the supply on (loop gain: the loops' dynamics and
            # the held readings as inputs); each row steps on its regime's matrices and gain,
            # each column's innovation is scored with its regime's S
            if sched:
                Phi1, Qd1 = Phi, Qd_occ
            P1, S1, Kf1, _ = kalman.stationary_filter(Phi1, C, Qd1, R,
                                                      self.options.sda_iterations, g.dare)
            PhiK1 = ca.mtimes(Phi1, Kf1)
            cols1 = self.regime.astype(float)
            GZ = dense_mtimes(PhiK, ca.DM(self.Y_lay * (1.0 - cols1))) \
                + dense_mtimes(PhiK1, ca.DM(self.Y_lay * cols1))
            if sched:
                GZ = GZ + dense_mtimes(Gam, W)
                occ_extra = [P1, S1, Kf1, Qd_occ]
            else:
                on_w = ca.DM(np.tile(cols1, (self.nw, 1)))
                GZ = GZ + dense_mtimes(Gam, W * (1.0 - on_w)) + dense_mtimes(Gam1, W * on_w) \
                    + dense_mtimes(GamY, ca.DM(self.Y_lay * cols1))
                occ_extra = [P1, S1, Kf1, Qd1, Phi1, Gam1, GamY]
            F = ca.horzcat(F, Phi1 - ca.mtimes(PhiK1, C))
            X = kalman.chunked_recursion(F, GZ, X0, self.restart, self.L, self.regime)
        else:
            GZ = dense_mtimes(Gam, W) + dense_mtimes(PhiK, ca.DM(self.Y_lay))
            X = kalman.chunked_recursion(F, GZ, X0, self.restart, self.L)
        E = ca.DM(self.Y_lay) - ca.mtimes(C, X)
        Em = E * ca.DM(np.tile(self.mask, (self.ny, 1)))
        if two:
            E0 = Em * ca.DM(np.tile(1.0 - cols1, (self.ny, 1)))
            E1 = Em * ca.DM(np.tile(cols1, (self.ny, 1)))
            quad_cols = ca.sum1(E0 * ca.solve(S, E0)) + ca.sum1(E1 * ca.solve(S1, E1))
            m1 = self.mask * cols1
            # log det S per counted column, of its own regime
            ldet_row = ca.DM(self.mask - m1).T * ca.log(ca.det(S)) + ca.DM(m1).T * ca.log(ca.det(S1))
            ldet_sum = float((self.mask - m1).sum()) * ca.log(ca.det(S)) \
                + float(m1.sum()) * ca.log(ca.det(S1))
        else:
            quad_cols = ca.sum1(Em * ca.solve(S, Em))                         # (1, L·M)
            ldet_row = ca.DM(self.mask).T * ca.log(ca.det(S))
            ldet_sum = self.n_cols * ca.log(ca.det(S))
        mask_row = ca.DM(self.mask).T
        if self.options.innovations == "student":
            # multivariate t, scale S: a masked column has e = 0 and adds log(1) = 0
            p = self.ny
            if self.i_nu is None:
                nu = float(self.options.nu)
                const = 2.0 * (math.lgamma(nu / 2) - math.lgamma((nu + p) / 2)) \
                    + p * math.log(nu * math.pi)
            else:
                nu = ca.exp(eta[self.i_nu])
                const = 2.0 * (_lgamma(nu / 2) - _lgamma((nu + p) / 2)) + p * ca.log(nu * math.pi)
            quad_cols = (nu + p) * ca.log1p(quad_cols / nu)
        else:
            const = self.ny * kalman.LOG2PI
        quad = ca.sum2(quad_cols)
        nll = 0.5 * (quad + ldet_sum + self.n_cols * const)
        g.col_terms = 0.5 * (quad_cols + ldet_row + mask_row * const)
        g.eta = eta
        g.nll = nll
        g.nll_buf = BufferedFunction(ca.Function("nll", [eta], [nll], ["eta"], ["nll"]))
        g.nll_grad_buf = BufferedFunction(ca.Function(
            "nll_grad", [eta], [nll, ca.densify(ca.gradient(nll, eta))],
            ["eta"], ["nll", "grad"]))
        g.matrices_fn = ca.Function(
            "matrices", [eta], [A, B, Sig, R, Phi, Gam, Qd, P, S, Kf, X0, ThB, change] + occ_extra,
            ["eta"], ["A", "B", "Sigma", "R", "Phi", "Gamma", "Qd", "P", "S", "Kf", "X0",
                      "Theta", "change"]
            + (["P_occ", "S_occ", "Kf_occ", "Qd_occ"] if sched else [])
            + (["P_on", "S_on", "Kf_on", "Qd_on", "Phi_on", "Gamma_on", "Gamma_y"] if loop else []))
        g.cache = {}
        g.kstep_parts = (X, E, (Kf, Kf1) if two else Kf, Phi, Gam, C, ThB_full,
                         (Phi1, Gam1, GamY) if loop else None) if self.n_restarts else None
        return g

    def _loop_A(self, A, eta):
        """``(A_on, B_y)``: the state matrix with every loop's ``k_z·(y_z − T_z)`` in it and the
        input matrix of the held readings (see :meth:`_loop_discretized`)."""
        inv_f = self._inv_factor(eta)
        By = ca.MX(self.n, self.ny)
        for j, i in zip(self.loop_zones, self.i_loop):
            z = self.meas[j]
            c = ca.exp(eta[i]) * float(self.sym.inv_cz[z])
            if inv_f is not None:
                c = c * inv_f[z]
            By[z, j] = c
        return A - ca.mtimes(By, ca.DM(self.zone_pick)), By

    def _loop_discretized(self, A, B, Sig, eta, squarings: int):
        """``(Phi_on, Gamma_on, Gamma_y, Qd_on)``: the model with the supply on, each loop's
        ``k_z·(y_z − T_z)`` added, discretised over the step with the reading ``y_z`` held.

        The loop term moves ``k_z·inv_cz`` [1/s] into the zone's diagonal of ``A`` (with
        ``internal_mass``, divided by its factor like every term of its equation) and the
        same into an input column for the held reading; ``Gamma_y`` maps the readings of
        every measured zone (zero columns for zones without a loop).
        """
        A_on, By = self._loop_A(A, eta)
        Phi1, GG, Qd1 = kalman.discretize(A_on, ca.horzcat(B, By), Sig, self.data.dt, squarings)
        return Phi1, GG[:, :self.nw], GG[:, self.nw:], Qd1

    def _kstep_of(self, g):
        """The k-step criterion (MX) of graph ``g``, built on first use; None without restarts.

        Lazy because most problems never use it (the selection's fits are on the
        likelihood). Its gradient was about a fifth of a build (profiled on a 38-state
        local problem of the 25-zone corridor); a whole local fit's CPU time did not move
        measurably (6.1–6.7 s before, 6.5–7.0 s after, on a loaded machine).
        """
        if g.kstep_parts is None:
            return None

        def make():
            J = self._build_kstep(*g.kstep_parts)
            return J, BufferedFunction(ca.Function("kstep", [g.eta], [J], ["eta"], ["J"])), \
                BufferedFunction(ca.Function("kstep_grad", [g.eta],
                                             [J, ca.densify(ca.gradient(J, g.eta))],
                                             ["eta"], ["J", "grad"]))
        return self._cached(g, "kstep", make)[0]

    def _build_kstep(self, X, E, Kf, Phi, Gam, C, ThB_full, on=None):
        LM = self.L * self.M
        R = self.n_restarts
        rows = np.array([self.pos[int(t)] for t in self.kstarts])
        Sel = ca.DM(sp.csc_matrix((np.ones(R), (rows, np.arange(R))), shape=(LM, R)))
        if isinstance(Kf, tuple):
            # each restart's filtered state with the gain of its row's regime
            r1 = self.row_regime[self.kstarts].astype(float)
            ES = ca.mtimes(E, Sel)
            Xh = ca.mtimes(X, Sel) + ca.mtimes(Kf[0], ES * ca.DM(np.tile(1.0 - r1, (self.ny, 1)))) \
                + ca.mtimes(Kf[1], ES * ca.DM(np.tile(r1, (self.ny, 1))))
        else:
            Xh = ca.mtimes(X, Sel) + ca.mtimes(Kf, ca.mtimes(E, Sel))
        J = 0
        Sz = np.zeros((self.nw, self.ny))
        Sz[self.meas, np.arange(self.ny)] = 1.0
        Sz = ca.DM(Sz)
        CT = ca.DM(self.zone_pick)
        for i in range(1, self.H + 1):
            idx = self.kstarts + i - 1
            W = ca.DM(self.W0[:, idx]) + _KW * ca.mtimes(ThB_full, ca.DM(self.Bas[:, idx]))
            fb = ca.DM(self.sup_gain[idx].T) * (ca.mtimes(CT, Xh) - ca.DM(self.Tbar[idx].T))
            W = W - ca.mtimes(Sz, fb)
            X0h = dense_mtimes(Phi, Xh) + dense_mtimes(Gam, W)
            if on is not None:
                # supply on: the loops answer the predicted temperature held over the step
                Phi1, Gam1, GamY = on
                X1h = dense_mtimes(Phi1, Xh) + dense_mtimes(Gam1, W) \
                    + dense_mtimes(GamY, ca.mtimes(CT, Xh))
                r1 = ca.DM(np.tile(self.row_regime[idx].astype(float), (self.n, 1)))
                X0h = X0h + (X1h - X0h) * r1
            Xh = X0h
            err = ca.DM(self.Y[self.kstarts + i].T) - ca.mtimes(C, Xh)
            J = J + ca.sumsqr(err)
        return J

    # ------------------------------------------------------------------ numeric API
    @property
    def zone_pick(self) -> np.ndarray:
        """(ny, n) selection of the measured zones' air temperatures among the states (the
        temperatures themselves: without the sensor-error states that ``C`` adds)."""
        P = np.zeros((self.ny, self.n))
        P[np.arange(self.ny), self.meas] = 1.0
        return P

    @property
    def n_kstep(self) -> int:
        """Scalar errors in the k-step criterion."""
        return self.n_restarts * self.H * self.ny

    def release_buffers(self) -> None:
        """Free the evaluation buffers (tens of MB); the next evaluation makes them again."""
        for g in list(self._graphs.values()):
            kstep = g.cache.get("kstep", ())
            for buf in [g.nll_buf, g.nll_grad_buf, *kstep, *g.cache.values()]:
                if isinstance(buf, BufferedFunction):
                    buf.release()

    def nll(self, eta) -> float:
        """Negative log-likelihood [-] (2π term included)."""
        return float(self._graph(eta).nll_buf(eta)[0][0])

    def nll_grad(self, eta):
        f, g = self._graph(eta).nll_grad_buf(eta)
        return float(f[0]), g

    def kstep(self, eta) -> float:
        """k-step criterion: sum of squared errors over horizons 1..H at every restart [K²]."""
        g = self._kstep_graph(eta)
        return float(g.cache["kstep"][1](eta)[0][0])

    def kstep_grad(self, eta):
        f, grad = self._kstep_graph(eta).cache["kstep"][2](eta)
        return float(f[0]), grad

    def _kstep_graph(self, eta):
        g = self._graph(eta)
        if self._kstep_of(g) is None:
            self._need_kstep()
        return g

    def _need_kstep(self):
        if self.n_restarts == 0:
            raise DataError(f"no k-step restart fits in the data: every segment is shorter than "
                            f"burn-in + horizon ({self.options.burn_in / 3600:g} h + "
                            f"{self.options.horizon / 3600:g} h)")

    def _cached(self, g, key, make):
        """``g.cache[key]``, made by ``make()`` on first use (once, whichever thread asks;
        ``make`` must not ask for another entry: the lock is not re-entrant)."""
        f = g.cache.get(key)
        if f is None:
            with self._graphs_lock:
                f = g.cache.get(key)
                if f is None:
                    f = g.cache[key] = make()
        return f

    def hessian(self, eta, criterion: str = "likelihood") -> np.ndarray:
        """Exact Hessian of the criterion in ``eta`` (built on first use)."""
        g = self._graph(eta) if criterion == "likelihood" else self._kstep_graph(eta)
        # the criterion before the cache's lock: the k-step one is made under it
        expr = g.nll if criterion == "likelihood" else self._kstep_of(g)

        def make():
            H, _ = ca.hessian(expr, g.eta)
            return ca.Function(f"hess_{criterion}", [g.eta], [H])
        fn = self._cached(g, f"hess_{criterion}", make)
        H = np.asarray(ca.densify(fn(np.asarray(eta, float))))
        return 0.5 * (H + H.T)

    def block_scores(self, eta, block: float = 86400.0, threads: int = 1) -> np.ndarray:
        """Gradients of the likelihood's contributions of consecutive time blocks.

        Parameters
        ----------
        eta : array_like
        block : float
            Block length [s] (blocks follow the data rows from the first sample).
        threads : int
            Blocks computed side by side.

        Returns
        -------
        ndarray, shape (n_blocks, n_params)
            ``∂ nll_b / ∂ eta`` for every block with observations (they sum to the gradient).
        """
        eta = np.asarray(eta, float)
        g = self._graph(eta)

        def make():
            # one reverse sweep per block (a Jacobian of all blocks at once would make
            # CasADi differentiate the Riccati callback column by column)
            wcol = ca.MX.sym("w", self.L * self.M)
            f = ca.dot(wcol, g.col_terms.T)
            return BufferedFunction(ca.Function(
                "wnll_grad", [g.eta, wcol], [ca.densify(ca.gradient(f, g.eta))]))
        fn = self._cached(g, "weighted", make)
        bid = self._block_ids(block)
        ids = np.unique(bid[bid >= 0])

        def score(b):
            return fn(eta, (bid == b).astype(float))[0]
        return np.array(thread_map(score, ids, threads)).reshape(len(ids), len(self.layout))

    def _block_ids(self, block: float) -> np.ndarray:
        """Block number (data row // rows per block) of every layout column; -1 where the
        column holds no observation that counts."""
        per = max(1, int(round(block / self.data.dt)))
        return np.where((self.tmap >= 0) & (self.mask > 0), self.tmap // per, -1)

    def n_blocks(self, block: float = 86400.0) -> int:
        """How many time blocks of ``block`` seconds hold observations that count (the D of
        the daily-gain test, :meth:`LikelihoodScorer.consistent`) [-]."""
        bid = self._block_ids(block)
        return int(np.unique(bid[bid >= 0]).size)

    def block_nll(self, eta, block: float = 86400.0) -> tuple[np.ndarray, np.ndarray]:
        """The likelihood's contributions of consecutive time blocks (as :meth:`block_scores`).

        Returns
        -------
        ids : ndarray of int
            Block numbers (row // rows per block) that hold observations.
        nll : ndarray
            ``nll_b`` of those blocks [-]; they sum to :meth:`nll`.
        """
        eta = np.asarray(eta, float)
        g = self._graph(eta)
        fn = self._cached(g, "col_terms",
                          lambda: ca.Function("col_terms", [g.eta], [g.col_terms]))
        cols = np.asarray(fn(eta), dtype=float).ravel()
        bid = self._block_ids(block)
        keep = bid >= 0
        ids, inv = np.unique(bid[keep], return_inverse=True)
        return ids, np.bincount(inv, weights=cols[keep], minlength=len(ids))

    def matrices(self, eta) -> dict:
        """Every intermediate matrix at ``eta`` as numpy arrays (continuous, discrete, filter)."""
        eta = np.asarray(eta, float)
        out = self._graph(eta).matrices_fn(eta=eta)
        return {k: np.asarray(ca.densify(v)) for k, v in out.items()}

    def inputs(self, eta) -> np.ndarray:
        """Model inputs ``w`` of every row, shape (N, nz + nb): zone heat [kW], boundary T [°C]."""
        Th = self.matrices(eta)["Theta"]
        W = self.W0.copy()
        W[:self.nz] += _KW * Th @ self.Bas
        return W.T

    def rbar_c(self, eta):
        """``(rbar_v, c_v)`` per convection edge at ``eta`` ([K/(W m)], [J/K])."""
        m = len(self.edges)
        if not m:
            return np.zeros(0), np.zeros(0)
        eta = np.asarray(eta, float)
        rb = np.exp(eta[self.i_rbar])
        return rb, np.exp(eta[self.i_tau]) / rb

    def ua_factors(self, eta) -> dict:
        """Fitted UA factor per wall class at ``eta`` [-] (``wall_factors``; else empty)."""
        eta = np.asarray(eta, float)
        return {c: float(np.exp(eta[i])) for c, i in zip(self.ua_classes, self.i_ua)}

    def fitted_network(self, eta) -> ThermalNetwork:
        """The network with the fitted zone capacitances and wall conductances at ``eta``.

        Without capacity (``internal_mass``) or UA (``wall_factors``) factors, the network
        itself. With them, a shallow copy whose spec gives every measured zone
        ``capacitance = f_z·C_z`` [J/K] explicitly and every wall of a class with factor f
        ``R/f`` (all three resistances; C unchanged), with its conduction edges to match,
        so that :class:`ThermalModel`, its state-space export and ``model.json`` carry
        them.
        """
        if not self.i_cf and not self.i_ua:
            return self.network
        spec = self.network.spec
        net = copy.copy(self.network)       # keeps edges, graph and any subclass state
        if self.i_cf:
            cap = self.zone_capacitances(eta)
            zones = tuple(dataclasses.replace(z, capacitance=float(cap[self.zones.index(z.name)]))
                          if z.name in self.zones and self.zones.index(z.name) in self.meas
                          else z for z in spec.zones)
            spec = dataclasses.replace(spec, zones=zones)
        if self.i_ua:
            fac = self.ua_factors(eta)
            cond = self.network.conduction_edges
            if len(cond) != len(spec.walls):
                raise EstimationError(f"fitted_network: {len(cond)} conduction edges but "
                                      f"{len(spec.walls)} walls in the spec")
            f_edge = {e.name: fac.get(c, 1.0) for e, c in zip(cond, self.wall_classes)}
            # the network's conduction edges are the spec's walls, in order
            walls = tuple(w if f_edge[e.name] == 1.0 else
                          dataclasses.replace(w, R=tuple(float(r) / f_edge[e.name] for r in w.R))
                          for w, e in zip(spec.walls, cond))
            spec = dataclasses.replace(spec, walls=walls)
            edges = [e if e.kind != "conduction" or f_edge[e.name] == 1.0 else
                     dataclasses.replace(e, R=tuple(float(r) / f_edge[e.name] for r in e.R))
                     for e in self.network.edges]
            net.edges = edges
            net.graph = self.network.graph.copy()
            for e in edges:
                if e.kind == "conduction":
                    net.graph.edges[e.a, e.b, e.name]["edge"] = e
        net.spec = spec
        return net

    def thermal_model(self, eta, meta: dict | None = None) -> ThermalModel:
        """The identified :class:`ThermalModel` (network part) at ``eta``.

        With ``internal_mass`` its network's spec holds the fitted zone capacitances, with
        ``wall_factors`` the fitted wall resistances (:meth:`fitted_network`).
        """
        net = self.fitted_network(eta)
        rb, cv = self.rbar_c(eta)
        if not len(rb):
            return ThermalModel(net, meta=meta)
        if self.options.per_edge:
            return ThermalModel(net, rbar_v=rb, c_v=cv, meta=meta)
        return ThermalModel(net, rbar_v=float(rb[0]), c_v=float(cv[0]), meta=meta)

    def describe(self) -> str:
        return (f"{len(self.zones)} zones ({self.ny} measured), {len(self.edges)} convection "
                f"edges, {self.n} states ({self.n_d} gain states), {len(self.layout)} parameters, "
                f"{len(self.segments)} segment(s), {self.n_obs} observations, "
                f"{self.n_restarts} k-step restarts of {self.H} steps, "
                f"at most {self.box_squarings} squarings, chunks {self.L}×{self.M}")


def _lgamma(x):
    """log Γ(x) of a CasADi expression, x ≥ 1 (CasADi has no lgamma): shifted by 6 and
    Stirling's series to x⁻⁵, error below 1e-9 (checked against ``math.lgamma`` from 1 to 500)."""
    z = x + 6.0
    series = (z - 0.5) * ca.log(z) - z + 0.5 * math.log(2 * math.pi) \
        + 1.0 / (12.0 * z) - 1.0 / (360.0 * z ** 3) + 1.0 / (1260.0 * z ** 5)
    return series - ca.log(x * (x + 1) * (x + 2) * (x + 3) * (x + 4) * (x + 5))
