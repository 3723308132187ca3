"""Columns → network inputs: the one place a table becomes the input matrix ``U``."""

from __future__ import annotations

import logging
import warnings

import numpy as np

from ..errors import DataError

__all__ = ["network_inputs", "GAP_POLICIES"]

log = logging.getLogger(__name__)

GAP_POLICIES = ("keep", "raise")


def network_inputs(frame, network, *, gaps: str = "keep") -> np.ndarray:
    """Network inputs from ``T:<node>``, ``Ts:<zone>``, ``ms:<zone>``, ``Q:<zone>`` columns.

    A directed flow of the spec (:class:`thermctl.spec.Flow`: ventilation air passed on
    from ``src`` into ``dst``) joins ``dst``'s supply air: the zone's ``ms`` is the sum of
    its own supply and the flows into it, ``Ts`` their flow-weighted temperature (``T:src``
    for a flow), so the zone gains ``Σ ṁ_k·cp·(T_k − T_z)``.

    A zone without ``ms:`` gets no supply air (``ms = 0``) and a supply temperature that
    can never turn ``0·Ts`` into NaN: its own ``T:`` where measured, else the mean of the
    measured zones at that sample, else 20 °C (the value multiplies ``ms = 0``; it matters
    only to a linearisation about an operating point, which should see the zone's own
    level). A zone without ``Q:`` gets zero gains (the paper's choice). Every boundary
    node needs its ``T:`` column.

    Parameters
    ----------
    frame : pandas.DataFrame
        SI units: ``T`` and ``Ts`` [°C], ``ms`` [kg/s], ``Q`` [W].
    network : ThermalNetwork
    gaps : {"keep", "raise"}
        ``keep``: a missing value of a measured input stays NaN (the estimators leave
        those samples out; simulations must not start inside them); ``raise``: a
        :class:`DataError` names the first column with a gap.

    Returns
    -------
    ndarray, shape (len(frame), network.n_inputs)
        In ``network.input_names`` order: ``ms`` [kg/s], ``Ts`` [°C], boundary ``T``
        [°C], ``Q`` [W].

    Raises
    ------
    DataError
        Naming the missing boundary ``T:`` or supply ``Ts:`` column, or (``gaps="raise"``)
        the column with a gap.
    """
    if gaps not in GAP_POLICIES:
        raise DataError(f"gaps must be one of {GAP_POLICIES}, found {gaps!r}")
    cols = set(frame.columns)
    n = len(frame)
    for b in network.boundary:
        if f"T:{b}" not in cols:
            raise DataError(f"column 'T:{b}' missing: boundary node {b!r} needs its "
                            "measured temperature")
    measured = [frame[f"T:{z}"].to_numpy(float) for z in network.zones if f"T:{z}" in cols]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)       # all-NaN rows inside gaps
        mean_t = np.nanmean(np.vstack(measured), axis=0) if measured else np.full(n, np.nan)
    mean_t = np.where(np.isfinite(mean_t), mean_t, 20.0)
    ms, ts, q = [], [], []
    used = []
    flows = _incoming_flows(frame, network, cols)
    for z in network.zones:
        if f"ms:{z}" in cols and f"Ts:{z}" not in cols:
            raise DataError(f"column 'Ts:{z}' missing: zone {z!r} has a supply flow "
                            f"'ms:{z}' but no supply temperature")
        parts = ([(frame[f"ms:{z}"].to_numpy(float), frame[f"Ts:{z}"].to_numpy(float))]
                 if f"ms:{z}" in cols else []) + flows.get(z, [])
        if f"ms:{z}" in cols:
            used += [f"ms:{z}", f"Ts:{z}"]
        if len(parts) == 1:
            ms.append(parts[0][0])
            ts.append(parts[0][1])
        elif parts:
            # supply air and air passed on from other rooms mix: one flow at the
            # flow-weighted temperature gives the zone the same Σ ṁ_k·cp·(T_k − T_z)
            m = np.sum([p[0] for p in parts], axis=0)
            h = np.sum([p[0] * p[1] for p in parts], axis=0)
            with np.errstate(invalid="ignore", divide="ignore"):
                t_mix = np.where(m > 0, h / np.where(m > 0, m, 1.0), parts[0][1])
            ms.append(m)
            ts.append(t_mix)
        else:
            log.debug("zone %s has no 'ms:%s' column: no supply air", z, z)
            own = frame[f"T:{z}"].to_numpy(float) if f"T:{z}" in cols else mean_t
            ms.append(np.zeros(n))
            ts.append(np.where(np.isfinite(own), own, mean_t))
        if f"Q:{z}" in cols:
            q.append(frame[f"Q:{z}"].to_numpy(float))
            used.append(f"Q:{z}")
        else:
            q.append(np.zeros(n))
    tb = [frame[f"T:{b}"].to_numpy(float) for b in network.boundary]
    used += [f"T:{b}" for b in network.boundary]
    if gaps == "raise":
        for c in used:
            bad = ~np.isfinite(frame[c].to_numpy(float))
            if bad.any():
                raise DataError(f"column {c!r} has {int(bad.sum())} missing value(s), first "
                                f"at {frame.index[int(np.argmax(bad))]}")
    return np.column_stack(ms + ts + tb + q).astype(float)


def _incoming_flows(frame, network, cols) -> dict:
    """Zone → [(rate [kg/s], temperature [°C]), ...] of the spec's directed flows into it."""
    out = {}
    zones = set(network.zones)
    for f in network.spec.flows:
        if f.dst not in zones:
            continue
        where = f"directed flow {f.src} → {f.dst}"
        if f.rate_column not in cols:
            raise DataError(f"column {f.rate_column!r} missing: the {where} takes its rate "
                            f"from it")
        if f"T:{f.src}" not in cols:
            raise DataError(f"column 'T:{f.src}' missing: the {where} needs the temperature "
                            f"of the air it carries (a flow from an unmeasured zone cannot be "
                            "an input)")
        rate = f.fraction * frame[f.rate_column].to_numpy(float)
        out.setdefault(f.dst, []).append((rate, frame[f"T:{f.src}"].to_numpy(float)))
    return out
