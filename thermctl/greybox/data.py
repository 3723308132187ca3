"""Data as the stochastic grey-box estimator reads it.

Same time convention as :class:`thermctl.estimate.EstimationData`: row ``k`` is the sample
at ``t_k = t_0 + k·dt``; inputs are held over ``[t_k, t_{k+1})`` (zero-order hold), so the
last row's inputs act on nothing. On top of the network inputs the grey-box model reads
measured irradiance (``solar:<name>`` [W/m²]) and the time stamps (for a time-of-day
basis of the unmeasured gains).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ..errors import DataError
from ..estimate._data import check_network, grid_arrays, inputs_from_frame, regular_step
from ..network import ThermalNetwork

__all__ = ["GreyboxData"]

log = logging.getLogger(__name__)


@dataclass
class GreyboxData:
    """Measured data on a regular grid for :class:`~thermctl.greybox.GreyboxEstimator`.

    Attributes
    ----------
    U : ndarray, shape (N, n_inputs)
        Network inputs in :attr:`ThermalNetwork.input_names` order: ``ms`` [kg/s],
        ``Ts`` [°C], boundary ``T`` [°C], ``Q`` (measured heat input) [W]. Row ``k`` acts
        over ``[t_k, t_{k+1})``.
    Y : ndarray, shape (N, n_measured)
        Measured zone temperatures [°C], NaN where missing.
    dt : float
        Step [s].
    zones : list of str
        Zone of each column of ``Y``.
    input_names : list of str
        Names of the columns of ``U``.
    solar : ndarray, shape (N, n_solar)
        Measured irradiance [W/m²] (may have zero columns).
    solar_names : list of str
        Names of the ``solar:`` columns (without the prefix).
    time : pandas.DatetimeIndex or None
        Time stamps (needed only for a time-of-day basis of the gains).
    """

    U: np.ndarray
    Y: np.ndarray
    dt: float
    zones: list
    input_names: list
    solar: np.ndarray = field(default=None)
    solar_names: list = field(default_factory=list)
    time: pd.DatetimeIndex | None = None

    def __post_init__(self):
        self.U, self.Y, self.dt = grid_arrays(self.U, self.Y, self.dt, self.zones)
        N = self.U.shape[0]
        if self.solar is None:
            self.solar = np.zeros((N, 0))
        self.solar = np.asarray(self.solar, dtype=float).reshape(N, -1)
        if self.solar.shape[1] != len(self.solar_names):
            raise DataError(f"solar has {self.solar.shape[1]} columns but "
                            f"{len(self.solar_names)} names ({self.solar_names})")
        if self.time is not None:
            self.time = pd.DatetimeIndex(self.time)
            if len(self.time) != N:
                raise DataError(f"time has {len(self.time)} stamps for {N} rows")

    def __len__(self):
        return self.U.shape[0]

    # ---- constructors ---------------------------------------------------------------
    @classmethod
    def from_arrays(cls, network: ThermalNetwork, U, Y, dt: float, zones=None, solar=None,
                    solar_names=None, time=None) -> "GreyboxData":
        """Data for ``network`` from arrays.

        Parameters
        ----------
        network : ThermalNetwork
        U : array_like, shape (N, n_inputs)
            Inputs in ``network.input_names`` order.
        Y : array_like, shape (N, n_measured)
            Zone temperatures [°C].
        dt : float
            Step [s].
        zones : list of str, optional
            Zones of the columns of ``Y``; default ``network.measured_zones``.
        solar : array_like, shape (N, n_solar), optional
            Irradiance [W/m²].
        solar_names : list of str, optional
            Default ``solar0, solar1, ...``.
        time : array_like of datetime, optional
        """
        zones = list(network.measured_zones if zones is None else zones)
        if solar is not None:
            solar = np.asarray(solar, dtype=float)
            solar = solar.reshape(len(solar), -1)
            if solar_names is None:
                solar_names = [f"solar{i}" for i in range(solar.shape[1])]
        data = cls(U, Y, dt, zones, list(network.input_names), solar,
                   list(solar_names or []), time)
        data.check(network)
        return data

    @classmethod
    def from_measurements(cls, meas, network: ThermalNetwork, zones=None) -> "GreyboxData":
        """Data from :class:`thermctl.data.Measurements` (or a table with the same columns).

        Parameters
        ----------
        meas : thermctl.data.Measurements or pandas.DataFrame
            With ``T:<node>``, ``Ts:<zone>``, ``ms:<zone>``, ``Q:<zone>``, ``solar:<name>``
            columns in SI units and a regular ``DatetimeIndex``.
        network : ThermalNetwork
        zones : list of str, optional
            Measured zones to use (default: the spec's measured zones with a ``T:`` column).
        """
        if hasattr(meas, "frame") and hasattr(meas, "step"):
            frame = meas.frame
            dt = meas.step.total_seconds()
            U = meas.inputs(network)
        else:
            frame = meas
            idx = frame.index
            if not isinstance(idx, pd.DatetimeIndex) or len(idx) < 2:
                raise DataError("from_measurements: the table needs a regular DatetimeIndex")
            dt = regular_step(idx, "from_measurements")
            U, _ = inputs_from_frame(frame, network)
        cols = set(frame.columns)
        if zones is None:
            zones = [z for z in network.measured_zones if f"T:{z}" in cols]
        missing = [z for z in zones if f"T:{z}" not in cols]
        if missing:
            raise DataError(f"zone(s) {missing} have no 'T:' column")
        Y = np.column_stack([frame[f"T:{z}"].to_numpy(float) for z in zones])
        sol_cols = [c for c in frame.columns if c.startswith("solar:")]
        solar = np.column_stack([frame[c].to_numpy(float) for c in sol_cols]) if sol_cols \
            else np.zeros((len(frame), 0))
        if sol_cols and not np.all(np.isfinite(solar)):
            # irradiance is an input: a missing value cannot be skipped like an output
            bad = [c for c, col in zip(sol_cols, solar.T) if not np.all(np.isfinite(col))]
            log.info("solar column(s) %s have gaps; filled with 0 W/m² (night-time value)", bad)
            solar = np.where(np.isfinite(solar), solar, 0.0)
        data = cls(U, Y, dt, list(zones), list(network.input_names), solar,
                   [c[len("solar:"):] for c in sol_cols], frame.index)
        data.check(network)
        return data

    # ---- checks and slicing -----------------------------------------------------------
    def check(self, network: ThermalNetwork) -> None:
        """Raise :class:`DataError` unless these data fit ``network``'s spec."""
        check_network(self, network)

    def window(self, start: int, stop: int | None = None) -> "GreyboxData":
        """Rows ``start:stop`` (sample indices)."""
        sl = slice(start, stop)
        return GreyboxData(self.U[sl], self.Y[sl], self.dt, list(self.zones),
                           list(self.input_names), self.solar[sl], list(self.solar_names),
                           None if self.time is None else self.time[sl])

    def valid(self) -> np.ndarray:
        """Rows where every output and input is finite."""
        return (np.isfinite(self.Y).all(axis=1) & np.isfinite(self.U).all(axis=1)
                & np.isfinite(self.solar).all(axis=1))

    def segments(self, min_length: int = 2) -> list[tuple[int, int]]:
        """Maximal runs ``[a, b)`` of valid rows with at least ``min_length`` rows."""
        ok = np.r_[False, self.valid(), False].astype(np.int8)
        e = np.flatnonzero(np.diff(ok))
        return [(int(a), int(b)) for a, b in zip(e[::2], e[1::2]) if b - a >= min_length]

