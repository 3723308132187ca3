r"""The testbed's plant: the true thermal model stepped one control interval at a time.

:class:`Plant` is the building; :class:`VAVController` is the baseline BAS controller that
produced the testbed data. Any other controller (an MPC, say) can drive the same plant::

    plant = tb.plant()                      # fresh plant at the data's start state
    meas = plant.measure()
    for k in range(plant.n_steps):
        ms, Ts = my_controller(meas)        # supply flow [kg/s], supply temperature [°C]
        meas = plant.step(ms, Ts)           # advance one control step

or with :func:`run_closed_loop`. The plant integrates with the same L-stable Radau IIA
(Padé 1/2) rational step as :func:`thermctl.model.make_stepper`, but factors it through the
zones: the supply flow changes every control step, and only the zone block of the
state matrix depends on it, so each step solves an ``n_zones × n_zones`` system instead of
refactoring the whole ``n_states × n_states`` one.

The factorisation: :math:`D = I - \tfrac23 hA + \tfrac16 h^2A^2 = (I - hA/s)(I - hA/\bar s)`
with :math:`s = 2 + i\sqrt2`, and by partial fractions
:math:`D^{-1} r = 2\,\mathrm{Re}\,[\alpha (I - hA/s)^{-1} r]`, :math:`\alpha = \tfrac12 +
i/\sqrt2`. In :math:`I - \beta A` (:math:`\beta = h/s`) the zone block is diagonal (zones
touch only edge states) and the edge block is 2 × 2 block-diagonal, so the edge states
are eliminated once; the flow only adds :math:`\beta\,\mathrm{diag}(\dot m c_p / C_z)` to
the zone Schur complement.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.linalg import lapack

from .._blas import single_thread_blas
from ..errors import ModelError
from ..model import ThermalModel, zoh
from .disturbances import Disturbances

__all__ = ["Plant", "Measurement", "VAVController", "HvacSettings", "run_closed_loop",
           "PadeZoneStepper", "single_thread_blas"]

# Dense linear algebra up to this many states; above, sparse (measured: at 290 states the
# sparse path is faster, and it never calls multi-threaded BLAS, which can be 100x slower
# than one thread for small products on a busy machine).
_DENSE_STATES = 150
_DENSE_SCHUR = 400    # zone Schur complement inverted densely up to this many zones
_zgetrf, _zgetrs = lapack.zgetrf, lapack.zgetrs


class PadeZoneStepper:
    r"""Radau IIA (Padé 1/2) ZOH step of :math:`\dot x = (A - P\,\mathrm{diag}(a)P^T)x + b`.

    ``P`` selects the first ``nz`` states (the zones); ``a`` [1/s] changes from step to
    step (supply flow ``ms·cp/C_z``), ``A`` does not. Gives the same result as
    ``make_stepper(A_u, dt, "radau", substeps)`` up to round-off, at a cost per step that
    grows with the number of zones, not states.

    Up to ``dense_limit`` states, :math:`G_0^{-1} = (I - \beta A)^{-1}` is formed once and
    the flow enters through an ``nz × nz`` solve (Woodbury). Above, the edge states are
    eliminated (2 × 2 blocks) and the sparse zone Schur complement is factored at a
    reference flow; other flows are solved by fixed-point iteration on that factor, which
    contracts by at least :math:`|\beta|\,\max|a - a_{ref}|` per iteration (the network is
    self-adjoint in the capacitance-weighted norm), and it is refactored when that bound
    exceeds 0.05.

    Parameters
    ----------
    A : sparse matrix, shape (n, n)
        State matrix without the supply term [1/s] (:meth:`ThermalModel.matrices`).
    nz : int
        Number of zones (the first ``nz`` states).
    dt : float
        Step [s].
    substeps : int
        Sub-steps per step.
    dense_limit : int
        Largest state count handled with dense matrices.

    Raises
    ------
    ModelError
        If zones are coupled directly or edge states across edges (not a thermal network
        in :class:`~thermctl.network.ThermalNetwork` order).
    """

    def __init__(self, A, nz: int, dt: float, substeps: int = 1, dense_limit: int = _DENSE_STATES):
        A = sp.csr_matrix(A, dtype=float)
        n = A.shape[0]
        ne = n - nz
        if ne % 2:
            raise ModelError(f"PadeZoneStepper: {ne} edge states, expected two per edge")
        self.n, self.nz, self.substeps = n, nz, int(substeps)
        self.h = h = dt / substeps
        self.beta = beta = h / (2.0 + 1j * math.sqrt(2.0))
        self.alpha2 = 1.0 + 2j / math.sqrt(2.0)           # 2·alpha
        coo = A.tocoo()
        r, c, nzd = coo.row, coo.col, coo.data != 0
        if ((r < nz) & (c < nz) & (r != c) & nzd).any():
            raise ModelError("PadeZoneStepper: zones are coupled directly; expected couplings "
                             "through edge states only")
        if ((r >= nz) & (c >= nz) & ((r - nz) // 2 != (c - nz) // 2) & nzd).any():
            raise ModelError("PadeZoneStepper: edge states of different edges are coupled")
        self.dense = n <= dense_limit
        if self.dense:
            self.A = A.toarray()
            G0inv = np.linalg.inv(np.eye(n) - beta * self.A)
            self.R0 = (self.alpha2 * G0inv).real             # x+ = R0 r at zero flow
            self.Gz = G0inv[:nz]                             # zone rows of G0^-1
            self.bHz = beta * G0inv[:nz, :nz]
            self.Hc = self.alpha2 * beta * G0inv[:, :nz]
            self._diag = np.diag_indices(nz)
            return
        G = sp.identity(n, dtype=complex, format="csr") - beta * A
        idx = np.arange(nz, n, 2)        # 2x2 blocks of the edge part, inverted in closed form
        g11 = np.asarray(G[idx, idx]).ravel()
        g12 = np.asarray(G[idx, idx + 1]).ravel()
        g21 = np.asarray(G[idx + 1, idx]).ravel()
        g22 = np.asarray(G[idx + 1, idx + 1]).ravel()
        det = g11 * g22 - g12 * g21
        rows = np.concatenate([idx, idx, idx + 1, idx + 1]) - nz
        cols = np.concatenate([idx, idx + 1, idx, idx + 1]) - nz
        vals = np.concatenate([g22, -g12, -g21, g11]) / np.tile(det, 4)
        Gee_inv = sp.csr_matrix((vals, (rows, cols)), shape=(ne, ne))
        K = sp.csr_matrix(G[:nz, nz:] @ Gee_inv)
        Gez = G[nz:, :nz]
        self.A = A
        self.KG = sp.vstack([K, Gee_inv], format="csr")    # [K; Gee^-1] in one product
        self.W = sp.csr_matrix(Gee_inv @ Gez)
        self.S0 = sp.csc_matrix(sp.diags(G.diagonal()[:nz]) - K @ Gez)
        self._zero = self._splu(np.zeros(nz))
        self._ref = (np.zeros(nz), self._zero)
        self.refactorizations = 0

    def _splu(self, a):
        S = self.S0 + sp.diags(self.beta * a, format="csc")
        if self.nz <= _DENSE_SCHUR:
            # one dense product per solve beats SuperLU's per-call overhead at this size
            return np.linalg.inv(S.toarray()).__matmul__
        return spla.splu(sp.csc_matrix(S), permc_spec="MMD_AT_PLUS_A").solve

    def _sparse_solver(self, a):
        if not a.any():
            return self._zero
        a_ref, base = self._ref
        da = a - a_ref
        rho = abs(self.beta) * np.abs(da).max()
        if rho > 0.05:
            base = self._splu(a)
            self._ref = (a.copy(), base)
            self.refactorizations += 1
            return base
        if rho == 0.0:
            return base
        bda = self.beta * da

        def solve(t):
            y = base(t)
            for _ in range(60):
                y_new = base(t - bda * y)
                if np.abs(y_new - y).max() <= 1e-12 * (np.abs(y_new).max() + 1e-300):
                    return y_new
                y = y_new
            return y_new
        return solve

    def step(self, x, a, b):
        """One step of ``dt``.

        Parameters
        ----------
        x : ndarray, shape (n,)
            State at the start [°C].
        a : ndarray, shape (nz,)
            Supply-flow coefficient per zone, ``ms·cp/C_z`` [1/s], >= 0.
        b : ndarray, shape (n,)
            Constant term of the dynamics over the step [K/s].

        Returns
        -------
        ndarray, shape (n,)
        """
        nz, h, A = self.nz, self.h, self.A
        on = bool(a.any())
        hb = h * b
        if self.dense:
            if on:
                M = self.bHz * a
                M[self._diag] += 1.0
                # LAPACK directly: the numpy/scipy wrappers cost more than a 10x10 solve
                lu, piv, _ = _zgetrf(M, overwrite_a=True)
        else:
            solve = self._sparse_solver(a)
        for _ in range(self.substeps):
            # r = N x + c = x + h b + A_u ((h/3) x - (h²/6) b): one product with A per sub-step
            v = (h / 3.0) * x - (h / 6.0) * hb
            r = A @ v
            if on:
                r[:nz] -= a * v[:nz]
            r += x
            r += hb
            if self.dense:
                x = self.R0 @ r
                if on:
                    yz = self.Gz @ r
                    yz = _zgetrs(lu, piv, yz)[0]
                    x -= (self.Hc @ (a * yz)).real
                continue
            re = r[nz:]
            kg = self.KG @ re
            yz = solve(r[:nz] - kg[:nz])
            x = np.empty(self.n)
            x[:nz] = (self.alpha2 * yz).real
            x[nz:] = (self.alpha2 * (kg[nz:] - self.W @ yz)).real
        return x


@dataclass(frozen=True)
class HvacSettings:
    """Schedule, VAV boxes and zone controllers of the baseline BAS.

    Attributes
    ----------
    hours : (float, float)
        Occupied mode (supply on) [h local time], default 06:00–19:00.
    weekdays_only : bool
        Supply off on weekends.
    heat_setpoint, cool_setpoint : float
        Occupied heating and cooling set points [°C] (71 °F and 73 °F: the paper's zones
        sit near 72 °F in the day).
    setpoint_sd : float
        Per-zone set point offset (occupants adjust thermostats) [K].
    flow_per_area : float
        Design maximum supply flow per floor area [kg/(s m²)] (1 CFM/ft² = 0.0061).
    flow_spread : float
        Box sizes vary uniformly by ``± flow_spread`` [-].
    min_fraction : float
        Minimum (ventilation) flow as a fraction of the maximum [-].
    heat_max_fraction : float
        Maximum flow in heating (dual-maximum logic) as a fraction of the maximum [-].
    Ts_max : float
        Highest discharge temperature after reheat [°C].
    T_ahu : float
        Mean cold-deck supply temperature [°C] (55 °F).
    kp : float
        Proportional gain of both zone loops [1/K] (2 K proportional band).
    ti : float
        Integral time [s].
    """

    hours: tuple = (6.0, 19.0)
    weekdays_only: bool = True
    heat_setpoint: float = 21.7
    cool_setpoint: float = 22.8
    setpoint_sd: float = 0.4
    flow_per_area: float = 0.0061
    flow_spread: float = 0.2
    min_fraction: float = 0.3
    heat_max_fraction: float = 0.5
    Ts_max: float = 32.0
    T_ahu: float = 12.8
    kp: float = 0.5
    ti: float = 900.0


class Measurement:
    """What the BAS sees at one time stamp.

    Attributes
    ----------
    k : int
        Control step index.
    time : pandas.Timestamp
        Time of the step (computed on access).
    T : ndarray, shape (n_measured,)
        Zone temperature sensor readings [°C], measured zones in spec order.
    T_boundary : ndarray, shape (n_boundary,)
        Boundary temperature readings [°C].
    occupied : bool
        HVAC occupied mode.
    T_ahu : float
        Cold-deck supply air temperature available to the boxes [°C].
    """

    __slots__ = ("k", "T", "T_boundary", "occupied", "T_ahu", "_t0", "_dt")

    def __init__(self, k, T, T_boundary, occupied, T_ahu, t0, dt):
        self.k, self.T, self.T_boundary = k, T, T_boundary
        self.occupied, self.T_ahu, self._t0, self._dt = occupied, T_ahu, t0, dt

    @property
    def time(self) -> pd.Timestamp:
        return self._t0 + pd.Timedelta(seconds=self._dt * self.k)

    def __repr__(self):
        return (f"Measurement(k={self.k}, time={self.time}, occupied={self.occupied}, "
                f"T={np.round(self.T, 2).tolist()})")


class Plant:
    """The true building: a :class:`~thermctl.model.ThermalModel` driven by disturbances.

    Parameters
    ----------
    model : ThermalModel
        The true model (convection edges included).
    disturbances : Disturbances
        Boundary temperatures and heat gains on the control grid; its ``dt`` is the
        control step.
    x0 : array_like, shape (n_states,), optional
        Initial state [°C]; default: steady state of the first step's inputs with the
        supply off.
    substeps : int, optional
        Integration sub-steps per control step; default ``ceil(dt / 60 s)``.
    sensor_sd : float
        Zone and boundary sensor noise [K] of the returned measurements.
    sensor_bias : array_like, shape (n_sensed,), optional
        Constant offsets of the zone sensors [K].
    seed : int or numpy.random.Generator, optional
        Seed of the sensor noise.
    sensed : list of str, optional
        Zones whose sensors :meth:`measure` reads, in this order; default the measured
        zones. A zone with a thermostat the BAS does not log (a hidden conditioned zone)
        is sensed but not measured.
    method : {"radau", "exact"}
        ``radau``: the L-stable Radau IIA step on ``substeps`` sub-steps (default);
        ``exact``: exact zero-order hold of each control step (matrix exponential).

    Notes
    -----
    A controller that needs forecasts reads the (true) future disturbances from
    ``plant.disturbances`` at indices ``plant.k`` onwards: ``T_boundary``, ``gains``,
    ``occupied``, ``T_ahu``. For speed in a long loop, use :func:`run_closed_loop` or wrap
    the loop in :func:`single_thread_blas`.

    Examples
    --------
    >>> tb = generate(days=2)               # doctest: +SKIP
    >>> plant = tb.plant()                  # doctest: +SKIP
    >>> meas = plant.step(ms=0.05, Ts=14.0) # doctest: +SKIP
    """

    def __init__(self, model: ThermalModel, disturbances: Disturbances, x0=None,
                 substeps: int | None = None, sensor_sd: float = 0.0, sensor_bias=None, seed=None,
                 *, sensed=None, method: str = "radau"):
        net = model.network
        d = disturbances
        if list(d.zones) != net.zones or list(d.boundary) != net.boundary:
            raise ModelError("Plant: disturbances are for zones/boundary "
                             f"{d.zones}/{d.boundary}, the model has {net.zones}/{net.boundary}")
        if method not in ("radau", "exact"):
            raise ModelError(f"Plant: method must be 'radau' or 'exact', found {method!r}")
        self.model = model
        self.network = net
        self.disturbances = d
        self.dt = float(d.dt)
        self.method = method
        self.substeps = substeps or max(1, math.ceil(self.dt / 60.0))
        self._build()
        self._init_sensors(sensed, sensor_sd, sensor_bias, seed)
        if x0 is None:
            u = self.inputs(np.zeros(net.n_zones), np.full(net.n_zones, 20.0), 0)
            x0 = self.steady_state(u)
        self.x0 = np.asarray(x0, dtype=float).copy()
        if self.x0.shape != (self.n_states,):
            raise ModelError(f"Plant: x0 needs shape ({self.n_states},), found {self.x0.shape}")
        self.reset()

    def _build(self):
        """The stepper of the 3R2C model (Radau IIA through the zones, or exact ZOH)."""
        model, net = self.model, self.network
        A, Bt = model.matrices()
        self._Bt = Bt.toarray() if net.n_states <= _DENSE_STATES else sp.csr_matrix(Bt)
        if self.method == "exact":
            self._A = A
            self._zoh_cache = {}
        else:
            self._stepper = PadeZoneStepper(A, net.n_zones, self.dt, self.substeps)
        self._kz = np.asarray(model.sym.kz, dtype=float)
        self._inv_cz = np.asarray(model.sym.inv_cz, dtype=float)
        self.n_states = net.n_states

    def _init_sensors(self, sensed, sensor_sd, sensor_bias, seed):
        net = self.network
        names = net.measured_zones if sensed is None else list(sensed)
        unknown = [z for z in names if z not in net.zones]
        if unknown:
            raise ModelError(f"Plant: sensed zone(s) {unknown} are not zones of the model")
        self._meas_idx = np.array([net.zones.index(z) for z in names], dtype=int)
        self.sensed = list(names)
        self.sensor_sd = float(sensor_sd)
        nm = len(self._meas_idx)
        self.sensor_bias = np.zeros(nm) if sensor_bias is None else np.asarray(sensor_bias, float)
        if self.sensor_bias.shape != (nm,):
            raise ModelError(f"Plant: sensor_bias needs {nm} values (sensed zones), "
                             f"found shape {self.sensor_bias.shape}")
        self._rng = np.random.default_rng(seed)
        self._t0 = self.disturbances.time[0]

    def steady_state(self, u) -> np.ndarray:
        """Steady state [°C] for the constant input vector ``u`` (``network.input_names``)."""
        return self.model.steady_state(u)

    # ---- state --------------------------------------------------------------
    def reset(self, x0=None) -> None:
        """Back to step 0 at ``x0`` (default: the initial state)."""
        self.k = 0
        self.x = (self.x0 if x0 is None else np.asarray(x0, dtype=float)).copy()

    @property
    def n_steps(self) -> int:
        """Number of control steps the disturbances cover."""
        return len(self.disturbances)

    @property
    def time(self) -> pd.Timestamp:
        """Time of the current step."""
        return self._t0 + pd.Timedelta(seconds=self.dt * self.k)

    @property
    def T_zones(self) -> np.ndarray:
        """True zone temperatures [°C], all zones in spec order."""
        return self.x[: self.network.n_zones].copy()

    def inputs(self, ms, Ts, k: int | None = None) -> np.ndarray:
        """The model input vector at step ``k`` for supply ``ms`` [kg/s], ``Ts`` [°C]."""
        k = self.k if k is None else k
        d = self.disturbances
        nz = self.network.n_zones
        return np.concatenate([np.broadcast_to(np.asarray(ms, float), (nz,)),
                               np.broadcast_to(np.asarray(Ts, float), (nz,)),
                               d.T_boundary[k], d.gains[k]])

    # ---- stepping -----------------------------------------------------------
    def measure(self) -> Measurement:
        """Sensor readings at the current step."""
        d = self.disturbances
        k = min(self.k, self.n_steps - 1)
        T = self.x[self._meas_idx] + self.sensor_bias
        Tb = d.T_boundary_logged[k].copy()
        if self.sensor_sd > 0:
            T = T + self._rng.normal(0.0, self.sensor_sd, T.shape)
            Tb = Tb + self._rng.normal(0.0, self.sensor_sd, Tb.shape)
        return Measurement(self.k, T, Tb, bool(d.occupied[k]), float(d.T_ahu[k]), self._t0, self.dt)

    def step(self, ms, Ts) -> Measurement:
        """Hold ``ms`` and ``Ts`` for one control step, advance, and measure.

        Parameters
        ----------
        ms : float or array_like, shape (n_zones,)
            Supply mass flow per zone [kg/s], >= 0 (all zones, spec order).
        Ts : float or array_like, shape (n_zones,)
            Supply air temperature per zone [°C].

        Returns
        -------
        Measurement
            At the new time.
        """
        if self.k >= self.n_steps:
            raise ModelError(f"Plant: the disturbances end after {self.n_steps} steps")
        nz = self.network.n_zones
        ms = _vector(ms, nz, "ms")
        Ts = _vector(Ts, nz, "Ts")
        if not (ms.min() >= 0.0 and np.isfinite(ms.sum() + Ts.sum())):
            bad = [z for z, m in zip(self.network.zones, ms) if not 0.0 <= m < np.inf]
            if bad:
                raise ModelError(f"Plant.step: supply flow must be finite and >= 0 [kg/s]; "
                                 f"zone(s) {bad} have "
                                 f"{[float(m) for m in ms if not 0 <= m < np.inf]}")
            bad = [z for z, t in zip(self.network.zones, Ts) if not -np.inf < t < np.inf]
            raise ModelError(f"Plant.step: supply temperature must be finite [°C]; zone(s) {bad}")
        self.x = self._advance(ms, Ts, self.k)
        self.k += 1
        return self.measure()

    def _advance(self, ms, Ts, k):
        """The state after holding ``ms``, ``Ts`` and step ``k``'s disturbances over ``dt``."""
        nz = self.network.n_zones
        d = self.disturbances
        a = ms * self._kz
        b = self._Bt @ d.T_boundary[k]
        b[:nz] += a * Ts + d.gains[k] * self._inv_cz
        if self.method == "exact":
            key = a.tobytes()
            if key not in self._zoh_cache:
                if len(self._zoh_cache) > 64:
                    self._zoh_cache.clear()
                A_u = sp.lil_matrix(self._A, copy=True)
                A_u.setdiag(A_u.diagonal() - np.concatenate([a, np.zeros(self.n_states - nz)]))
                self._zoh_cache[key] = zoh(A_u, self.dt)
            Phi, Gamma = self._zoh_cache[key]
            return Phi @ self.x + Gamma @ b
        return self._stepper.step(self.x, a, b)


def _vector(v, n, name):
    if type(v) is np.ndarray and v.shape == (n,) and v.dtype == float:
        return v
    try:
        return np.broadcast_to(np.asarray(v, dtype=float), (n,))
    except ValueError:
        raise ModelError(f"Plant.step: {name} needs a scalar or {n} values (one per zone), "
                         f"found shape {np.shape(v)}") from None


class VAVController:
    """Baseline zone control of a VAV box with reheat (dual-maximum logic).

    Occupied mode: a cooling PI loop moves the flow from minimum to maximum at cold-deck
    temperature; a heating PI loop first raises the discharge temperature (reheat) from
    the cold deck to ``Ts_max`` at minimum flow (loop output 0–50 %), then the flow to the
    heating maximum (50–100 %). Between the set points: minimum flow, no reheat. Both loops
    integrate only while unsaturated and reset when the supply goes off. Unoccupied: supply
    off (zones float).

    Parameters
    ----------
    zones : list of str
        All zones, spec order.
    boxes : dict
        Zone → ``(ms_min, ms_max, ms_heat)`` [kg/s]; zones without a box get no supply.
    heat_sp, cool_sp : dict
        Zone → set point [°C] for the zones with a box.
    measured : list of str
        The zones whose readings come in :attr:`Measurement.T` (spec order).
    settings : HvacSettings
    dt : float
        Control step [s].
    """

    def __init__(self, zones, boxes, heat_sp, cool_sp, measured, settings: HvacSettings, dt: float):
        self.zones = list(zones)
        self.settings = settings
        self.dt = float(dt)
        idx = [i for i, z in enumerate(self.zones) if z in boxes]
        pos = {z: j for j, z in enumerate(measured)}
        missing = [self.zones[i] for i in idx if self.zones[i] not in pos]
        if missing:
            raise ModelError(f"VAVController: zone(s) {missing} have a box but no sensor")
        self._box = np.array(idx, dtype=int)
        self._sensor = np.array([pos[self.zones[i]] for i in idx], dtype=int)
        names = [self.zones[i] for i in idx]
        self.ms_min = np.array([boxes[z][0] for z in names])
        self.ms_max = np.array([boxes[z][1] for z in names])
        self.ms_heat = np.array([boxes[z][2] for z in names])
        self.heat_sp = np.array([heat_sp[z] for z in names])
        self.cool_sp = np.array([cool_sp[z] for z in names])
        self.reset()

    def reset(self) -> None:
        """Zero both integrators (as when the supply goes off)."""
        self._integ = np.zeros(2 * len(self._box))

    def __call__(self, meas: Measurement):
        """Supply flow [kg/s] and temperature [°C] for every zone (arrays, spec order)."""
        nz = len(self.zones)
        ms = np.zeros(nz)
        Ts = np.full(nz, meas.T_ahu)
        if not meas.occupied:
            self.reset()
            return ms, Ts
        s = self.settings
        T = meas.T[self._sensor]
        e = np.concatenate((T - self.cool_sp, self.heat_sp - T))   # cooling, heating loops
        u = s.kp * (e + self._integ / s.ti)
        # conditional integration: wind only while the output is inside [0, 1]
        grow = ((u < 1.0) | (e < 0.0)) & ((u > 0.0) | (e > 0.0))
        self._integ = np.minimum(np.maximum(self._integ + grow * (e * self.dt), 0.0), s.ti / s.kp)
        u = np.minimum(np.maximum(s.kp * (e + self._integ / s.ti), 0.0), 1.0)
        nb = len(self._box)
        uc, uh = u[:nb], u[nb:]
        lo = self.ms_min
        flow = np.where(uh > 0.5, lo + (self.ms_heat - lo) * (2.0 * uh - 1.0),
                        lo + (self.ms_max - lo) * np.where(uh > 0.0, 0.0, uc))
        ms[self._box] = flow
        Ts[self._box] = meas.T_ahu + (s.Ts_max - meas.T_ahu) * np.minimum(2.0 * uh, 1.0)
        return ms, Ts


def run_closed_loop(plant: Plant, controller, n_steps: int | None = None, callback=None):
    """Drive ``plant`` with ``controller`` for ``n_steps`` control steps.

    Parameters
    ----------
    plant : Plant
    controller : callable
        ``controller(measurement) -> (ms, Ts)`` for all zones ([kg/s], [°C]).
    n_steps : int, optional
        Default: to the end of the disturbances.
    callback : callable, optional
        ``callback(measurement, ms, Ts, plant)`` before each step (the measurement is the
        one the controller saw, the plant still at its time), e.g. to record data.

    Returns
    -------
    Measurement
        The last measurement.
    """
    n = plant.n_steps - plant.k if n_steps is None else int(n_steps)
    meas = plant.measure()
    with single_thread_blas():
        for _ in range(n):
            ms, Ts = controller(meas)
            if callback is not None:
                callback(meas, ms, Ts, plant)
            meas = plant.step(ms, Ts)
    return meas


