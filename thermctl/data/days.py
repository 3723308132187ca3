"""Zone temperatures as day × time of day × zone: one sample per day at every time of day.

Structure identification (:mod:`thermctl.structure`) treats each day as one sample of the
zone temperatures at each time-of-day index. :func:`day_array` does that shaping for any
frame with a regular ``DatetimeIndex``; :meth:`thermctl.data.Measurements.day_time_array`
calls it on the measured zone temperatures.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import pandas as pd

from ..errors import DataError
from ._grid import _DAY_NS

__all__ = ["DayArray", "day_array"]

logger = logging.getLogger(__name__)


@dataclass
class DayArray:
    """Zone temperatures arranged as day × time of day × zone.

    Attributes
    ----------
    values : ndarray, shape (N, K, n)
        Temperatures [°C] of the N complete days at the K times of day, n zones.
    days : list of datetime.date
        The N days used, in order (calendar days in the index's time zone).
    zones : list of str
        The n zones, in column order of ``values``.
    step : float
        Sampling step [s]; ``K = 86400 / step``.
    dropped : list of (datetime.date, str)
        Days left out and why: ``"incomplete (m of K samples)"`` (cut by the data's
        start or end, a missing row, a spring-forward clock change), ``"repeated time
        of day (clock change, m of K samples)"`` (fall-back clock change) or ``"gap in
        <columns>"`` (a NaN temperature).
    """

    values: np.ndarray
    days: list
    zones: list
    step: float
    dropped: list

    @property
    def n_times(self) -> int:
        """K, the number of time-of-day indices."""
        return self.values.shape[1]


def _zone_columns(data: pd.DataFrame, zones: Sequence[str]) -> list[str]:
    cols = []
    for z in zones:
        have = [c for c in (f"T:{z}", z) if c in data.columns]
        if not have:
            raise DataError(f"no temperature column for measured zone {z!r}: expected 'T:{z}' "
                            f"or {z!r}; columns are {list(data.columns)[:20]}")
        if len(have) == 2:
            raise DataError(f"zone {z!r} has two temperature columns, 'T:{z}' and {z!r}; keep one")
        cols.append(have[0])
    return cols


def day_array(data: pd.DataFrame, zones: Sequence[str], *, step: float | None = None) -> DayArray:
    """Arrange zone temperatures as day × time-of-day samples.

    Parameters
    ----------
    data : pandas.DataFrame
        Index: a regular ``DatetimeIndex`` (time-zone aware or naive; days are the
        calendar days of the index's time zone), rows may be missing. Columns:
        ``T:<zone>`` or ``<zone>`` temperatures [°C]; other columns are ignored.
    zones : sequence of str
        Zones to use, in this order.
    step : float, optional
        Sampling step [s]. Default: the smallest spacing of the index (then ``data``
        needs at least 2 rows).

    Returns
    -------
    DayArray
        Complete days only; a day with a missing row, a missing value or a repeated
        time of day (clock change) is left out and listed in ``dropped``.

    Raises
    ------
    DataError
        If the index is not a sorted, duplicate-free DatetimeIndex on a grid whose step
        divides 24 h, or a zone has no column, or a temperature column is not numeric.

    Examples
    --------
    >>> idx = pd.date_range("2024-01-01 12:00", periods=72, freq="1h")
    >>> da = day_array(pd.DataFrame({"T:a": 20.0, "T:b": 21.0}, index=idx), ["a", "b"])
    >>> da.values.shape, [str(d) for d in da.days], da.step
    ((2, 24, 2), ['2024-01-02', '2024-01-03'], 3600.0)
    >>> da.dropped
    [(datetime.date(2024, 1, 1), 'incomplete (12 of 24 samples)'), \
(datetime.date(2024, 1, 4), 'incomplete (12 of 24 samples)')]
    """
    idx = data.index
    if not isinstance(idx, pd.DatetimeIndex):
        raise DataError(f"data index must be a DatetimeIndex, found {type(idx).__name__}")
    if step is None and len(idx) < 2:
        raise DataError(f"data has {len(idx)} row(s): too few to infer the sampling step; "
                        "days of data are needed")
    if not idx.is_monotonic_increasing or idx.has_duplicates:
        raise DataError("data index must be sorted and free of duplicate time stamps")
    cols = _zone_columns(data, zones)
    # wall-clock time: a day is a calendar day where the building is
    local = idx.tz_localize(None) if idx.tz is not None else idx
    idx = idx.as_unit("ns")
    local = local.as_unit("ns")
    ns = np.diff(idx.asi8)
    if step is None:
        step_ns = int(ns.min())
    else:
        step_ns = int(round(float(step) * 1e9))
        if step_ns <= 0:
            raise DataError(f"step must be > 0 s, found {step!r}")
    if np.any(ns % step_ns):
        bad = idx[1:][ns % step_ns != 0][0]
        raise DataError(f"data index is not on a regular grid of {step_ns / 1e9:g} s "
                        f"(first off-grid time stamp {bad}); resample first (thermctl.data)")
    if _DAY_NS % step_ns:
        raise DataError(f"data step {step_ns / 1e9:g} s does not divide 24 h; "
                        "resample to e.g. 5 min")
    K = _DAY_NS // step_ns
    day = local.normalize()
    tod = (local - day).asi8
    if len(tod) and np.any(tod % step_ns != tod[0] % step_ns):
        raise DataError(f"time stamps are not aligned to a daily grid of {step_ns / 1e9:g} s")
    k = tod // step_ns
    codes, days = pd.factorize(day)
    try:
        vals = data[cols].to_numpy(dtype=float)
    except (TypeError, ValueError):
        bad = [c for c in cols if not pd.api.types.is_numeric_dtype(data[c])]
        raise DataError(f"temperature column(s) {bad} are not numeric [°C]") from None
    n_days = len(days)
    count = np.zeros((n_days, K), dtype=int)
    np.add.at(count, (codes, k), 1)
    arr = np.full((n_days, K, len(zones)), np.nan)
    arr[codes, k] = vals

    keep, dropped = [], []
    for d in range(n_days):
        date = days[d].date()
        if (count[d] > 1).any():
            dropped.append((date, f"repeated time of day (clock change, {int(count[d].sum())} "
                                  f"of {K} samples)"))
        elif (count[d] == 0).any():
            dropped.append((date, f"incomplete ({int((count[d] > 0).sum())} of {K} samples)"))
        else:
            nan_cols = [c for c, bad in zip(cols, np.isnan(arr[d]).any(axis=0)) if bad]
            if nan_cols:
                dropped.append((date, "gap in " + ", ".join(nan_cols)))
            else:
                keep.append(d)
    if dropped:
        logger.info("day array: %d of %d day(s) used; left out: %s", len(keep), n_days,
                    "; ".join(f"{d}: {r}" for d, r in dropped))
    if len(keep) < n_days:
        arr = arr[keep]
    return DayArray(arr, [days[d].date() for d in keep], list(zones), step_ns / 1e9, dropped)
