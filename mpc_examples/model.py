r"""The controller's side of the loop: its internal model and its state estimator.

The MPC never sees the plant's state: the plant is the testbed's true building (true air
paths, unmeasured heat gains, an unmeasured hallway, noisy sensors), the MPC holds a
:class:`~thermctl.model.ThermalModel` — identified from the testbed's data, or for
comparison the true one or the conduction-only one — and a Kalman filter that estimates
that model's state (zone, wall and air-path temperatures) together with one unknown heat
gain per measured zone.

Gain model (offset-free MPC): :math:`d_{k+1} = d_k + w_k`, a random walk in W entering the
zone balance like the model's ``Q[z]`` input. The forecast holds the last estimate
constant over the horizon; nothing else is known about occupants, equipment or lighting.
The gain states also absorb the controller model's error, which is what makes the
identified model usable in closed loop.
"""

from __future__ import annotations

import logging

import numpy as np

from thermctl.model import ThermalModel, zoh

__all__ = ["identified_model", "controller_model", "reduced_model", "GainKalmanFilter"]

log = logging.getLogger(__name__)

MODEL_KINDS = ("identified", "true", "conduction-only")


def identified_model(tb, end=None, options=None) -> ThermalModel:
    """The model thermctl identifies from the testbed's (closed-loop, baseline) data.

    Runs the package's pipeline, :func:`thermctl.identify.identify` (what ``thermctl
    identify`` runs): structure identification (SIN, paper rule) on the calibration days,
    then the convection parameters by the CasADi multiple-shooting NLP. The data are read
    through :func:`thermctl.data.read_measurements` like a user's CSV.

    Parameters
    ----------
    tb : thermctl.testbed.TestbedResult
        Uses ``tb.data`` (what the BAS logged) and ``tb.spec`` (no air paths).
    end : pandas.Timestamp, optional
        Use only data logged before this time (the control period must not be seen).
    options : thermctl.identify.IdentifyOptions, optional
        Default: the package's defaults without the reference grid search (the NLP alone
        gave the same optimum on the testbed in half the time).

    Returns
    -------
    ThermalModel
    """
    from thermctl.data import read_measurements
    from thermctl.identify import IdentifyOptions, identify

    data = tb.data if end is None else tb.data.loc[tb.data.index < end]
    meas = read_measurements(data, tb.spec, name="testbed data")
    res = identify(meas, options or IdentifyOptions(grid=False))
    model = res.model
    log.info("identified: edges %s, rbar_v %s, c_v %s",
             [(e.a, e.b) for e in model.network.convection_edges], model.rbar_v, model.c_v)
    return model


def controller_model(tb, kind: str = "identified", end=None) -> ThermalModel:
    """The MPC's internal model.

    Parameters
    ----------
    tb : thermctl.testbed.TestbedResult
    kind : {"identified", "true", "conduction-only"}
        ``true``: the plant's own model (perfect structure and parameters, still no
        knowledge of the gains); ``conduction-only``: walls only, no air paths.
    end : pandas.Timestamp, optional
        For ``identified``: last time of the data used.
    """
    if kind == "identified":
        return identified_model(tb, end)
    if kind == "true":
        return tb.model
    if kind == "conduction-only":
        return ThermalModel(tb.model.network.conduction_only())
    raise ValueError(f"model kind must be one of {MODEL_KINDS}, found {kind!r}")


def reduced_model(tb, model: ThermalModel, order: int):
    """``model`` reduced to ``order`` states by :func:`thermctl.reduce.structured`.

    Every zone temperature stays a state and the model stays bilinear in the supply flow;
    the edge (wall, air-path) states become ``order − n_zones`` modes, chosen at the boxes'
    minimum flows (occupied) and at zero flow (night).

    Returns
    -------
    thermctl.reduce.ReducedNetwork
        Stands in for the ThermalModel in both MPCs and the Kalman filter.
    """
    from thermctl.reduce import structured

    boxes = tb.truth.details["vav_boxes"]
    net = model.network
    ms = {z: boxes[z]["ms_min"] for z in net.zones if z in boxes}
    Tb = tb.data[[f"T:{b}" for b in net.boundary]].mean().to_numpy()
    op = model.operating_point(ms=ms, Ts=float(tb.controller.settings.T_ahu),
                               T=dict(zip(net.boundary, Tb)))
    red = structured(model, op, order=int(order), design_ms=[0.0])
    log.info("reduced the model from %d to %d states", net.n_states, red.network.n_states)
    return red.network


class GainKalmanFilter:
    r"""Kalman filter for the model state and an unknown heat gain per measured zone.

    Augmented state :math:`z = [x;\, d]`, exact ZOH over the plant step with the applied
    supply held (the model is linear in :math:`x` once :math:`\dot m` is fixed):

    .. math::

        x_{k+1} = \Phi(\dot m_k) x_k + \Gamma(\dot m_k)\,(b(u_k) + E d_k), \quad
        d_{k+1} = d_k + w_k, \quad y_k = H x_k + v_k,

    :math:`E` puts gain :math:`d_j` [W] into its zone row divided by the zone capacitance.

    Parameters
    ----------
    model : ThermalModel
        The controller model.
    dt : float
        Plant (measurement) step [s].
    measured : list of str
        Zones whose temperatures are measured (they also get a gain state).
    sd_zone : float
        Process noise of zone temperatures per hour [K/√h]: model error.
    sd_edge : float
        Process noise of edge (wall, air-path) states per hour [K/√h].
    sd_gain : float
        Random-walk intensity of the gains [W/√h]: how fast occupancy can change.
    sd_meas : float
        Sensor noise [K].
    """

    def __init__(self, model: ThermalModel, dt: float, measured, sd_zone: float = 0.3,
                 sd_edge: float = 0.05, sd_gain: float = 150.0, sd_meas: float = 0.1):
        net = model.network
        self.model = model
        self.dt = float(dt)
        self.nx, self.nz = net.n_states, net.n_zones
        self.meas_idx = np.array([net.zones.index(z) for z in measured], dtype=int)
        nm = len(self.meas_idx)
        self.n = self.nx + nm
        self._mats = model.matrices()
        cap = model.capacitances()
        self._E = np.zeros((self.nx, nm))
        self._E[self.meas_idx, np.arange(nm)] = 1.0 / cap[self.meas_idx]
        h = self.dt / 3600.0
        q = np.full(self.nx, sd_edge ** 2 * h)
        q[: self.nz] = sd_zone ** 2 * h
        self.Qn = np.diag(np.concatenate([q, np.full(nm, sd_gain ** 2 * h)]))
        self.R = np.eye(nm) * sd_meas ** 2
        self.H = np.zeros((nm, self.n))
        self.H[np.arange(nm), self.meas_idx] = 1.0
        self._cache_key = None
        self._PhiGam = None
        self.z = None
        self.P = None

    # ---- state -------------------------------------------------------------
    @property
    def x(self) -> np.ndarray:
        """Estimated model state [°C]."""
        return self.z[: self.nx].copy()

    @property
    def gains(self) -> np.ndarray:
        """Estimated heat gain per measured zone [W]."""
        return self.z[self.nx:].copy()

    def gains_all_zones(self) -> np.ndarray:
        """Estimated gains on all zones [W] (0 for unmeasured zones)."""
        g = np.zeros(self.nz)
        g[self.meas_idx] = self.z[self.nx:]
        return g

    def reset(self, T_meas, T_boundary, gains=None) -> None:
        """Start from the paper's initial state (edges at the mean of their ends).

        Parameters
        ----------
        T_meas : array_like, shape (n_measured,)
            Measured zone temperatures [°C].
        T_boundary : array_like, shape (n_boundary,)
            [°C]
        gains : array_like, shape (n_measured,), optional
            Initial gain estimate [W] (default 0).
        """
        Tz = np.full(self.nz, np.nan)
        Tz[self.meas_idx] = T_meas
        x0 = self.model.initial_state(Tz, T_boundary)
        nm = len(self.meas_idx)
        d0 = np.zeros(nm) if gains is None else np.asarray(gains, float)
        self.z = np.concatenate([x0, d0])
        p0 = np.full(self.nx, 1.0)
        p0[self.meas_idx] = 0.1
        self.P = np.diag(np.concatenate([p0 ** 2, np.full(nm, 200.0 ** 2)]))

    # ---- filter ------------------------------------------------------------
    def _transition(self, u):
        sl = self.model.network.input_slices()
        key = tuple(np.round(u[sl["ms"]], 12))
        if key != self._cache_key:
            A_u, _ = self.model.affine(u, mats=self._mats)
            Phi, Gam = zoh(A_u, self.dt)
            F = np.zeros((self.n, self.n))
            F[: self.nx, : self.nx] = Phi
            F[: self.nx, self.nx:] = Gam @ self._E
            F[self.nx:, self.nx:] = np.eye(self.n - self.nx)
            self._cache_key, self._PhiGam = key, (F, Gam)
        return self._PhiGam

    def predict(self, u) -> None:
        """Propagate over one plant step with the applied input vector ``u``.

        Parameters
        ----------
        u : ndarray, shape (n_inputs,)
            Model input (``ms``, ``Ts``, ``T[b]``, ``Q``) held over the step; ``Q`` is what
            the controller knows of the gains (0 here — the gain states carry them).
        """
        F, Gam = self._transition(u)
        _, b = self.model.affine(u, mats=self._mats)
        z = F @ self.z
        z[: self.nx] += Gam @ b
        self.z = z
        self.P = F @ self.P @ F.T + self.Qn

    def update(self, y) -> None:
        """Correct with measured zone temperatures ``y`` [°C] (NaN entries are skipped)."""
        y = np.asarray(y, dtype=float)
        ok = np.isfinite(y)
        if not ok.any():
            return
        H, R = self.H[ok], self.R[np.ix_(ok, ok)]
        S = H @ self.P @ H.T + R
        K = np.linalg.solve(S, H @ self.P).T
        self.z = self.z + K @ (y[ok] - H @ self.z)
        I_KH = np.eye(self.n) - K @ H
        self.P = I_KH @ self.P @ I_KH.T + K @ R @ K.T  # Joseph form: stays symmetric PSD
