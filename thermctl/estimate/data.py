"""The data window both criteria read (:class:`EstimationData`) and its checks.

One time convention for every estimator: row ``k`` is the sample at ``t_k = t_0 + k·dt``;
inputs are held over ``[t_k, t_{k+1})`` (zero-order hold), so the last row's inputs act
on nothing. One column layout: ``U`` in :attr:`ThermalNetwork.input_names` order, built
from a table by :func:`thermctl.data.network_inputs`.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ..data import network_inputs
from ..errors import DataError
from ..network import ThermalNetwork

__all__ = ["EstimationData", "as_estimation_data"]

log = logging.getLogger(__name__)


def grid_arrays(U, Y, dt, zones):
    """Inputs, outputs and step checked to describe one regular time grid.

    Parameters
    ----------
    U : array_like, shape (N, n_inputs)
        Inputs (SI units).
    Y : array_like, shape (N, n_measured) or (N,)
        Measured zone temperatures [°C]; a 1-D ``Y`` is one zone.
    dt : float
        Sample step [s]; finite and > 0.
    zones : list of str
        The zone of each column of ``Y``.

    Returns
    -------
    U : ndarray, shape (N, n_inputs)
    Y : ndarray, shape (N, n_measured)
    dt : float
        [s]

    Raises
    ------
    DataError
        If ``dt`` is not a positive step, ``U`` and ``Y`` differ in rows or ``Y`` in
        columns from ``zones``.
    """
    U = np.atleast_2d(np.asarray(U, dtype=float))
    Y = np.asarray(Y, dtype=float)
    if Y.ndim == 1:
        Y = Y[:, None]
    dt = float(dt)
    if not (math.isfinite(dt) and dt > 0):
        raise DataError(f"dt must be a positive step [s], found {dt}")
    if U.shape[0] != Y.shape[0]:
        raise DataError(f"U has {U.shape[0]} rows but Y has {Y.shape[0]}; "
                        "they must share the time grid")
    if Y.shape[1] != len(zones):
        raise DataError(f"Y has {Y.shape[1]} columns but {len(zones)} zones were named ({zones})")
    return U, Y, dt


def check_network(data, network) -> None:
    """Raise :class:`DataError` unless ``data`` (with ``input_names``, ``zones``, ``U``) fit
    ``network``: the same inputs in the same order, and measured zones of the network."""
    if list(data.input_names) != list(network.input_names):
        raise DataError(f"inputs do not match the network: expected {network.input_names}, "
                        f"found {data.input_names}")
    unknown = [z for z in data.zones if z not in network.zones]
    if unknown:
        raise DataError(f"measured zone(s) {unknown} are not zones of the network "
                        f"({network.zones})")
    if data.U.shape[1] != network.n_inputs:
        raise DataError(f"U has {data.U.shape[1]} columns, the network has "
                        f"{network.n_inputs} inputs")


def regular_step(index, where: str) -> float:
    """Step [s] of a time index with at least two stamps, which must be evenly spaced.

    Parameters
    ----------
    index : pandas.DatetimeIndex
    where : str
        Caller named in the error message.

    Raises
    ------
    DataError
        If the spacing varies.
    """
    steps = np.asarray((index[1:] - index[:-1]).total_seconds(), dtype=float)
    if not np.allclose(steps, steps[0]):
        raise DataError(f"{where}: the time index is not regular (steps from {steps.min():g} to "
                        f"{steps.max():g} s); resample with thermctl.data.read_measurements first")
    return float(steps[0])


@dataclass
class EstimationData:
    """A block of measured data on a regular time grid, as every estimator reads it.

    Attributes
    ----------
    U : ndarray, shape (N, n_inputs)
        Network inputs in :attr:`ThermalNetwork.input_names` order: ``ms`` [kg/s], ``Ts``
        [°C], boundary ``T`` [°C], ``Q`` (measured heat input) [W]. Row ``k`` acts over
        ``[t_k, t_{k+1})``.
    Y : ndarray, shape (N, n_measured)
        Measured zone temperatures [°C], NaN where missing (left out of every criterion).
    dt : float
        Sample step [s].
    zones : list of str
        Zone of each column of ``Y``.
    input_names : list of str
        Names of the columns of ``U`` (checked against the network).
    gains_known : bool
        Whether the ``Q`` columns hold measured heat inputs (False: zero, as in the paper,
        which neglects occupants and sun).
    solar : ndarray, shape (N, n_solar)
        Measured irradiance [W/m²] (may have zero columns; the simulation criterion
        ignores it).
    solar_names : list of str
        Names of the ``solar:`` columns (without the prefix).
    time : pandas.DatetimeIndex or None
        Time stamps (needed only for a time-of-day basis of the unmeasured gains).
    """

    U: np.ndarray
    Y: np.ndarray
    dt: float
    zones: list
    input_names: list
    gains_known: bool = False
    solar: np.ndarray = field(default=None)
    solar_names: list = field(default_factory=list)
    time: pd.DatetimeIndex | None = None

    def __post_init__(self):
        self.zones = [str(z) for z in self.zones]
        self.input_names = [str(n) for n in self.input_names]
        self.U, self.Y, self.dt = grid_arrays(self.U, self.Y, self.dt, self.zones)
        if self.U.shape[1] != len(self.input_names):
            raise DataError(f"U has {self.U.shape[1]} columns but {len(self.input_names)} "
                            "input names were given")
        if len(set(self.zones)) != len(self.zones):
            raise DataError(f"zones listed twice in {self.zones}")
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
    def from_arrays(cls, network: ThermalNetwork, U, Y, dt: float, zones=None, Q=None,
                    solar=None, solar_names=None, time=None) -> "EstimationData":
        """Data for ``network`` from arrays.

        Parameters
        ----------
        network : ThermalNetwork
        U : array_like, shape (N, n_inputs)
            Inputs in ``network.input_names`` order (see the class docstring).
        Y : array_like, shape (N, n_measured)
            Measured zone temperatures [°C].
        dt : float
            Sample step [s].
        zones : list of str, optional
            Zones of the columns of ``Y``; default ``network.measured_zones``.
        Q : array_like, shape (N, n_zones), optional
            Known heat gains [W]; written into the ``Q`` columns of ``U`` (otherwise those
            columns are used as given and the gains count as unknown unless non-zero).
        solar : array_like, shape (N, n_solar), optional
            Irradiance [W/m²].
        solar_names : list of str, optional
            Default ``solar0, solar1, ...``.
        time : array_like of datetime, optional
        """
        U = np.array(U, dtype=float, copy=True)
        zones = list(network.measured_zones if zones is None else zones)
        sl = network.input_slices()
        gains_known = False
        if Q is not None:
            Q = np.asarray(Q, dtype=float)
            if Q.shape != (U.shape[0], network.n_zones):
                raise DataError(f"Q: expected shape ({U.shape[0]}, {network.n_zones}) "
                                f"(one column per zone {network.zones}), found {Q.shape}")
            U[:, sl["Q"]] = Q
            gains_known = True
        elif U.ndim == 2 and U.shape[1] == network.n_inputs:
            gains_known = bool(np.any(U[:, sl["Q"]] != 0))
        if solar is not None:
            solar = np.asarray(solar, dtype=float)
            solar = solar.reshape(len(solar), -1)
            if solar_names is None:
                solar_names = [f"solar{i}" for i in range(solar.shape[1])]
        data = cls(U, Y, dt, zones, list(network.input_names), gains_known, solar,
                   list(solar_names or []), time)
        data.check(network)
        return data

    @classmethod
    def from_frame(cls, frame, network: ThermalNetwork, dt: float | None = None,
                   zones=None) -> "EstimationData":
        """Data from a table with ``T:``, ``Ts:``, ``ms:``, ``Q:``, ``solar:`` columns.

        Parameters
        ----------
        frame : pandas.DataFrame or thermctl.data.Measurements
            SI units: ``T`` and ``Ts`` [°C], ``ms`` [kg/s], ``Q`` [W], ``solar`` [W/m²];
            inputs by :func:`thermctl.data.network_inputs` (a zone without ``ms:`` gets no
            supply air, one without ``Q:`` zero gains; every boundary node needs its
            ``T:`` column).
        network : ThermalNetwork
        dt : float, optional
            Sample step [s]; default from a regular ``DatetimeIndex`` (or the
            ``Measurements.step``).
        zones : list of str, optional
            Measured zones to use (default: the network's measured zones with a ``T:``
            column).
        """
        if hasattr(frame, "frame") and hasattr(frame, "step"):   # thermctl.data.Measurements
            dt = frame.step.total_seconds() if dt is None else dt
            frame = frame.frame
        cols = set(frame.columns)
        n = len(frame)
        timed = isinstance(frame.index, pd.DatetimeIndex)
        if dt is None:
            if not timed or n < 2:
                raise DataError("from_frame: give dt [s]; the table has no DatetimeIndex "
                                "to read the step from")
            dt = regular_step(frame.index, "from_frame")
        U = network_inputs(frame, network)
        gains_known = any(f"Q:{z}" in cols for z in network.zones)
        if zones is None:
            zones = [z for z in network.measured_zones if f"T:{z}" in cols]
        missing = [z for z in zones if f"T:{z}" not in cols]
        if missing:
            raise DataError(f"zone(s) {missing} have no 'T:' column in the table")
        Y = np.column_stack([frame[f"T:{z}"].to_numpy(float) for z in zones]) if zones \
            else np.empty((n, 0))
        sol_cols = [c for c in frame.columns if c.startswith("solar:")]
        solar = np.column_stack([frame[c].to_numpy(float) for c in sol_cols]) if sol_cols \
            else np.zeros((n, 0))
        if sol_cols and not np.all(np.isfinite(solar)):
            # irradiance is an input: a missing value cannot be skipped like an output
            bad = [c for c, col in zip(sol_cols, solar.T) if not np.all(np.isfinite(col))]
            log.info("solar column(s) %s have gaps; filled with 0 W/m² (night-time value)", bad)
            solar = np.where(np.isfinite(solar), solar, 0.0)
        data = cls(U, Y, dt, list(zones), list(network.input_names), gains_known, solar,
                   [c[len("solar:"):] for c in sol_cols], frame.index if timed else None)
        data.check(network)
        return data

    # ---- checks and slicing -----------------------------------------------------------
    def check(self, network: ThermalNetwork) -> None:
        """Raise :class:`DataError` unless these data fit ``network``."""
        check_network(self, network)

    def window(self, start: int, stop: int | None = None) -> "EstimationData":
        """Rows ``start:stop`` (sample indices)."""
        sl = slice(start, stop)
        return EstimationData(self.U[sl], self.Y[sl], self.dt, list(self.zones),
                              list(self.input_names), self.gains_known, self.solar[sl],
                              list(self.solar_names),
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


def as_estimation_data(data, network: ThermalNetwork) -> EstimationData:
    """:class:`EstimationData` from itself, :class:`thermctl.data.Measurements` or a
    DataFrame (read for ``network``)."""
    if isinstance(data, EstimationData):
        return data
    return EstimationData.from_frame(data, network)
