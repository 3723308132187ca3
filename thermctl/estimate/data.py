"""Data checks and conversions shared by :class:`~thermctl.estimate.EstimationData` and
:class:`~thermctl.greybox.GreyboxData` (one time convention, one column layout, so one
implementation: both must accept and reject the same tables).
"""

from __future__ import annotations

import logging
import math

import numpy as np

from ..errors import DataError

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


def inputs_from_frame(frame, network):
    """Network inputs from ``T:<node>``, ``Ts:<zone>``, ``ms:<zone>``, ``Q:<zone>`` columns.

    A zone without ``ms:`` gets no supply air (``ms = 0``), one without ``Q:`` zero gains;
    every boundary node needs its ``T:`` column.

    Parameters
    ----------
    frame : pandas.DataFrame
        SI units: ``T`` and ``Ts`` [°C], ``ms`` [kg/s], ``Q`` [W].
    network : ThermalNetwork

    Returns
    -------
    U : ndarray, shape (len(frame), n_inputs)
        In ``network.input_names`` order.
    gains_known : bool
        Whether any ``Q:`` column was given.

    Raises
    ------
    DataError
        Naming the missing boundary ``T:`` or supply ``Ts:`` column.
    """
    cols = set(frame.columns)
    n = len(frame)
    for b in network.boundary:
        if f"T:{b}" not in cols:
            raise DataError(f"column 'T:{b}' missing: boundary node {b!r} needs its "
                            "measured temperature")
    ms, ts, q = [], [], []
    gains_known = False
    for z in network.zones:
        if f"ms:{z}" in cols:
            if f"Ts:{z}" not in cols:
                raise DataError(f"column 'Ts:{z}' missing: zone {z!r} has a supply flow "
                                f"'ms:{z}' but no supply temperature")
            ms.append(frame[f"ms:{z}"].to_numpy(float))
            ts.append(frame[f"Ts:{z}"].to_numpy(float))
        else:
            log.info("zone %s has no 'ms:%s' column: no supply air", z, z)
            ms.append(np.zeros(n))
            ts.append(np.full(n, 20.0))   # multiplied by ms = 0
        if f"Q:{z}" in cols:
            q.append(frame[f"Q:{z}"].to_numpy(float))
            gains_known = True
        else:
            q.append(np.zeros(n))
    tb = [frame[f"T:{b}"].to_numpy(float) for b in network.boundary]
    return np.column_stack(ms + ts + tb + q), gains_known
