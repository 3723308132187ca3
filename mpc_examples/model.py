r"""The controller's side of the loop: its internal model and its state estimator.

The MPC never sees the plant's state: the plant is the testbed's true building (true air
paths, unmeasured heat gains, an unmeasured hallway, noisy sensors), the MPC holds a
:class:`~thermctl.model.ThermalModel` — identified from the testbed's data, or for
comparison the true one or the conduction-only one — and a Kalman filter that estimates
that model's state (zone, wall and air-path temperatures) together with one unknown heat
gain per measured zone.

Gain model (offset-free MPC): :math:`d_{k+1} = d_k + w_k`, a random walk in W entering the
zone balance like the model's ``Q[z]`` input; the forecast holds the current estimate over
the horizon (nothing is measured about occupants, equipment or lighting). The gain
states also absorb the controller model's error, which is what makes an identified model
usable in closed loop.

Before it takes over, the filter replays the BAS log of the last days
(:meth:`GainKalmanFilter.run`), so the wall and air-path states and the gains are
estimated when the first MPC step is computed. A time-of-day gain profile learned from the
log (the median per slot, plus the current deviation fading within an hour) was tried as
the forecast instead and measured: on the 3-day run it changed site energy by 0.01 % and
discomfort not at all, so it is not kept.
"""

from __future__ import annotations

import logging

import numpy as np
import pandas as pd
import scipy.sparse as sp

from thermctl.estimate.likelihood.kalman import filter_predict, filter_update, process_noise_np
from thermctl.export.disturbances import greybox_params
from thermctl.export.kalman import augment_noise, has_noise_model
from thermctl.model import ThermalModel, zoh

__all__ = ["identified_model", "controller_model", "reduced_model", "min_flow_point",
           "GainKalmanFilter", "logged_steps"]

log = logging.getLogger(__name__)

MODEL_KINDS = ("identified", "paper", "true", "conduction-only")


def identified_model(tb, end=None, **options) -> ThermalModel:
    """The model thermctl identifies from the testbed's (closed-loop, baseline) data.

    Runs the package's pipeline with its default method, :func:`thermctl.identify.identify`
    (what ``thermctl identify`` runs), on the data logged before ``end``. The data are read
    through :func:`thermctl.data.read_measurements` like a user's CSV.

    Calibration window: every day before ``end`` except the last whole day, which
    validates. identify's own default split keeps only three quarters of the days for
    calibration, and SIN structure identification needs at least ``n + 2`` days for ``n``
    measured zones (8 for Pugh Hall): with 10 days of data that split fails, while one
    validation day is all an MPC example needs.

    Parameters
    ----------
    tb : thermctl.testbed.TestbedResult
        Uses ``tb.data`` (what the BAS logged) and ``tb.spec`` (no air paths).
    end : pandas.Timestamp, optional
        Use only data logged before this time (the control period must not be seen).
    **options
        Fields of :class:`thermctl.identify.IdentifyOptions` that differ from the
        package's defaults (e.g. ``criterion="simulation", selection="scores"``: the
        paper's pipeline). Always set unless given: the calibration window above, no
        parameter intervals and no reference grid search (neither changes the model;
        they only report on it, and took half the time).

    Returns
    -------
    ThermalModel
    """
    from thermctl.data import read_measurements
    from thermctl.identify import EstimationOptions, IdentifyOptions, SelectionOptions, identify

    data = tb.data if end is None else tb.data.loc[tb.data.index < end]
    meas = read_measurements(data, tb.spec, name="testbed data")
    # the last day the data cover whole: it ends at (last time stamp + one step)
    last_day = (meas.end + meas.step - pd.Timedelta(days=1)).normalize()
    options = dict(options)
    est = {"grid": options.pop("grid", False), "intervals": options.pop("intervals", "none")}
    if "criterion" in options:
        est["criterion"] = options.pop("criterion")
    sel = {"method": options.pop("selection")} if "selection" in options else {}
    opt = IdentifyOptions(estimation=EstimationOptions(**est), selection=SelectionOptions(**sel),
                          validation=(str(last_day.date()), None), **options)
    model = identify(meas, opt).model
    log.info("identified (criterion %s, selection %s): edges %s, rbar_v %s, c_v %s",
             opt.estimation.criterion, opt.selection.method,
             [(e.a, e.b) for e in model.network.convection_edges], model.rbar_v, model.c_v)
    return model


def controller_model(tb, kind: str = "identified", end=None) -> ThermalModel:
    """The MPC's internal model.

    Parameters
    ----------
    tb : thermctl.testbed.TestbedResult
    kind : {"identified", "paper", "true", "conduction-only"}
        ``identified``: thermctl's default identification (:func:`identified_model`);
        ``paper``: the paper's pipeline (SIN scores and rule, open-loop simulation
        criterion); ``true``: the plant's own model (perfect structure and parameters,
        still no knowledge of the gains); ``conduction-only``: walls only, no air paths.
    end : pandas.Timestamp, optional
        For ``identified`` and ``paper``: last time of the data used.
    """
    if kind == "identified":
        return identified_model(tb, end)
    if kind == "paper":
        return identified_model(tb, end, criterion="simulation", selection="scores")
    if kind == "true":
        return tb.model
    if kind == "conduction-only":
        return ThermalModel(tb.model.network.conduction_only())
    raise ValueError(f"model kind must be one of {MODEL_KINDS}, found {kind!r}")


def min_flow_point(tb, model: ThermalModel):
    """The operating point reductions are made at: every box at its minimum flow [kg/s],
    supply at the AHU temperature [°C], boundary nodes at their mean over the data [°C]."""
    boxes = tb.truth.details["vav_boxes"]
    net = model.network
    ms = {z: boxes[z]["ms_min"] for z in net.zones if z in boxes}
    Tb = tb.data[[f"T:{b}" for b in net.boundary]].mean().to_numpy()
    return model.operating_point(ms=ms, Ts=float(tb.controller.settings.T_ahu),
                                 T=dict(zip(net.boundary, Tb)))


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

    op = min_flow_point(tb, model)
    red = structured(model, op, order=int(order), design_ms=[0.0])
    log.info("reduced the model from %d to %d states", model.network.n_states,
             red.network.n_states)
    return red.network


class GainKalmanFilter:
    r"""Kalman filter for the model state and an unknown heat gain per measured zone.

    Augmented state :math:`z = [x;\, d\,(;\, e)]`, exact ZOH over the plant step with the
    applied supply held (the model is linear in :math:`x` once :math:`\dot m` is fixed):

    .. math::

        x_{k+1} = \Phi(\dot m_k) x_k + \Gamma(\dot m_k)\,(b(u_k) + E d_k), \quad
        d_{k+1} = d_k + w_k, \quad y_k = H x_k (+ e_k) + v_k,

    :math:`E` puts gain :math:`d_j` [W] into its zone row divided by the zone capacitance.

    The noise model is the identified one when the model has one (a
    :class:`~thermctl.model.ThermalModel` identified with the likelihood criterion:
    ``model.meta["greybox"]["params"]``, what :func:`thermctl.export.kalman_filter`
    exports), built by the same :func:`thermctl.export.kalman.augment_noise`; otherwise
    (the true, conduction-only and reduced models, or any ``sd_*`` given) the hand-set one
    below. The numerics are those of :mod:`thermctl.estimate.likelihood.kalman`
    (:func:`~thermctl.estimate.likelihood.kalman.process_noise_np`,
    :func:`~thermctl.estimate.likelihood.kalman.filter_predict`,
    :func:`~thermctl.estimate.likelihood.kalman.filter_update`). Only the transition is
    this class's own: the exported filter is linearized at one operating point, while the
    supply flow changes the state matrix at every MPC step, so :math:`\Phi`, :math:`\Gamma`
    and :math:`Q_d` are recomputed whenever the applied flows change.

    Parameters
    ----------
    model : ThermalModel or ReducedNetwork
        The controller model.
    dt : float
        Plant (measurement) step [s].
    measured : list of str
        Zones whose temperatures are measured (they also get a gain state).
    sd_zone : float, optional
        Hand-set process noise of zone temperatures [K/√h]: model error (default 0.3).
    sd_edge : float, optional
        Hand-set process noise of edge (wall, air-path) states [K/√h] (default 0.05).
    sd_gain : float, optional
        Hand-set random-walk intensity of the gains [W/√h]: how fast occupancy can change
        (default 150).
    sd_meas : float, optional
        Hand-set sensor noise [K] (default 0.1).
    """

    HAND_SET = {"sd_zone": 0.3, "sd_edge": 0.05, "sd_gain": 150.0, "sd_meas": 0.1}

    def __init__(self, model: ThermalModel, dt: float, measured, sd_zone: float | None = None,
                 sd_edge: float | None = None, sd_gain: float | None = None,
                 sd_meas: float | None = None):
        net = model.network
        self.model = model
        self.dt = float(dt)
        self.nx, self.nz = net.n_states, net.n_zones
        measured = list(measured)
        self.meas_idx = np.array([net.zones.index(z) for z in measured], dtype=int)
        self._mats = model.matrices()
        cz = np.asarray(model.capacitances(), float)[: self.nz]
        given = {k: v for k, v in dict(sd_zone=sd_zone, sd_edge=sd_edge, sd_gain=sd_gain,
                                       sd_meas=sd_meas).items() if v is not None}
        params = greybox_params(model) if hasattr(model, "meta") and not given else {}
        self.identified = has_noise_model(params)
        if not self.identified:
            params, edge_q = _hand_set_noise(cz, net.zones, measured, **{**self.HAND_SET, **given})
        # the network block of A is replaced at every flow (_transition); only the
        # augmentation (gain and sensor-error states, noise) is taken from here
        self._A, self.H, self.Qc, self.R, extra = augment_noise(
            params, np.zeros((self.nx, self.nx)), cz, net.zones, measured)
        if not self.identified:
            self.Qc[self.nz:self.nx, self.nz:self.nx] += np.eye(self.nx - self.nz) * edge_q
        self.n = self._A.shape[0]
        self.nd = sum(n.startswith("d[") for n in extra)
        self._cache_key = None
        self._trans = None
        self.z = None
        self.P = None

    # ---- state -------------------------------------------------------------
    @property
    def x(self) -> np.ndarray:
        """Estimated model state [°C]."""
        return self.z[: self.nx].copy()

    @property
    def gains(self) -> np.ndarray:
        """Estimated heat gain per measured zone [W] (0 if the noise model has no gains)."""
        if not self.nd:
            return np.zeros(len(self.meas_idx))
        return self.z[self.nx:self.nx + self.nd].copy()

    def gains_all_zones(self) -> np.ndarray:
        """Estimated gains on all zones [W] (0 for unmeasured zones)."""
        g = np.zeros(self.nz)
        g[self.meas_idx] = self.gains
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
        z0 = np.zeros(self.n)
        z0[: self.nx] = x0
        if self.nd and gains is not None:
            z0[self.nx:self.nx + self.nd] = np.asarray(gains, float)
        self.z = z0
        p0 = np.full(self.n, 1.0)
        p0[self.meas_idx] = 0.1
        p0[self.nx:self.nx + self.nd] = 200.0       # [W]: nothing is known of the gains
        e = np.arange(self.nx + self.nd, self.n)    # AR(1) sensor errors: their stationary sd
        p0[e] = np.sqrt(self.Qc[e, e] / (-2.0 * self._A[e, e]))
        self.P = np.diag(p0 ** 2)

    # ---- filter ------------------------------------------------------------
    def _transition(self, u):
        sl = self.model.network.input_slices()
        key = tuple(np.round(u[sl["ms"]], 12))
        if key != self._cache_key:
            A_u, _ = self.model.affine(u, mats=self._mats)
            A = self._A.copy()
            A[: self.nx, : self.nx] = A_u.toarray() if sp.issparse(A_u) else A_u
            Phi, Gam = zoh(A, self.dt)
            Qd = process_noise_np(A, self.Qc, self.dt)
            self._cache_key, self._trans = key, (Phi, Gam[:, : self.nx], Qd)
        return self._trans

    def predict(self, u) -> None:
        """Propagate over one plant step with the applied input vector ``u``.

        Parameters
        ----------
        u : ndarray, shape (n_inputs,)
            Model input (``ms``, ``Ts``, ``T[b]``, ``Q``) held over the step; ``Q`` is what
            the controller knows of the gains (0 here — the gain states carry them).
        """
        Phi, Gam, Qd = self._transition(u)
        _, b = self.model.affine(u, mats=self._mats)
        self.z, self.P = filter_predict(self.z, self.P, Phi, Qd, Gam @ b)

    def update(self, y) -> None:
        """Correct with measured zone temperatures ``y`` [°C] (NaN entries are skipped)."""
        self.z, self.P, _ = filter_update(self.z, self.P, np.asarray(y, dtype=float), self.H,
                                          self.R)

    def run(self, data: pd.DataFrame) -> pd.DataFrame:
        """Replay logged BAS data through the filter, one filter step (``dt``) at a time.

        Starts with :meth:`reset` at the first step's time stamp, then for every step
        ``[t, t + dt)``: predict with the inputs averaged over the step, correct with the
        zone temperatures logged at ``t + dt`` (skipped where there is none: after the last
        step the filter is left *predicted* to the end of the data, ready for the next
        reading, e.g. the plant's first one when a controller takes over).

        Parameters
        ----------
        data : pandas.DataFrame
            ``T:``, ``Ts:``, ``ms:`` columns (SI, °C) on a DatetimeIndex whose step divides
            ``dt``; zones without supply columns get no supply air.

        Returns
        -------
        pandas.DataFrame
            The gain estimate per measured zone [W] over each step, indexed by the step's
            start (the estimate after the correction at its end; NaN for the last step).
        """
        times, U, Y = logged_steps(self.model.network, data, self.dt,
                                   [self.model.network.zones[i] for i in self.meas_idx])
        if len(times) < 2:
            raise ValueError(f"the data cover {len(times)} filter step(s) of {self.dt:g} s; "
                             "need at least 2")
        sl = self.model.network.input_slices()
        y0 = Y[0]
        self.reset(np.where(np.isfinite(y0), y0, np.nanmean(y0)), U[0, sl["T"]])
        G = np.full((len(times), len(self.meas_idx)), np.nan)
        for k in range(len(times)):
            self.predict(U[k])
            if k + 1 < len(times):
                self.update(Y[k + 1])
                G[k] = self.gains   # the gain over step k, seen at its end
        return pd.DataFrame(G, index=times, columns=[f"gain:{z}" for z in
                                                     (self.model.network.zones[i]
                                                      for i in self.meas_idx)])


def _hand_set_noise(cz, zones, measured, sd_zone, sd_edge, sd_gain, sd_meas):
    """The hand-set noise as grey-box parameters, and the edge states' intensity [K²/s].

    Per hour [K/√h, W/√h] → per second: ``σ_q[z] = sd_zone·C_z/60`` [W s^0.5] gives the
    intensity ``sd_zone²/3600`` [K²/s] on ``T[z]``; ``σ_φ = sd_gain/60`` [W/√s].
    """
    params = {f"sigma_q[{z}]": sd_zone * c / 60.0 for z, c in zip(zones, cz)}
    params.update(sigma_phi=sd_gain / 60.0, sigma_v=sd_meas)
    return params, sd_edge ** 2 / 3600.0


def logged_steps(net, data: pd.DataFrame, dt: float, measured):
    """Logged BAS data on a grid of ``dt``: model inputs averaged over each step, zone
    temperatures at each step's start.

    Parameters
    ----------
    net : ThermalNetwork
    data : pandas.DataFrame
        ``T:``, ``Ts:``, ``ms:`` columns on a DatetimeIndex.
    dt : float
        Step [s], a multiple of the data step.
    measured : list of str

    Returns
    -------
    times : DatetimeIndex
        Step starts.
    U : ndarray, shape (n_steps, n_inputs)
        Inputs (``Q`` = 0: the filter's gain states carry the gains).
    Y : ndarray, shape (n_steps, n_measured)
        Zone temperatures logged at each step's start [°C] (NaN where none).
    """
    step = pd.Timedelta(seconds=dt)
    df = data.resample(step, closed="left", label="left", origin="start").mean()
    sl = net.input_slices()
    U = np.zeros((len(df), net.n_inputs))
    for i, z in enumerate(net.zones):
        if f"ms:{z}" in df:
            U[:, sl["ms"].start + i] = df[f"ms:{z}"].fillna(0.0).to_numpy()
            U[:, sl["Ts"].start + i] = df[f"Ts:{z}"].ffill().bfill().to_numpy()
        else:
            U[:, sl["Ts"].start + i] = 20.0   # irrelevant: no flow
    U[:, sl["T"]] = df[[f"T:{b}" for b in net.boundary]].ffill().bfill().to_numpy()
    Y = data[[f"T:{z}" for z in measured]].reindex(df.index).to_numpy()
    return df.index, U, Y
